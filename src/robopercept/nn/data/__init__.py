"""Datasets, splits and statistics (:mod:`.datasets`), augmentations and normalization
(:mod:`.augment`), font-rendered digits for sim-to-real pretraining (:mod:`.fonts`),
and the photo backgrounds and textures of the procedural sets (:mod:`.textures`)."""
