"""Datasets and augmentations (:mod:`.datasets`) and font-rendered digits for sim-to-real
pretraining (:mod:`.fonts`)."""
