"""Point-cloud networks: PointNet (:mod:`.pointnet`), DGCNN (:mod:`.dgcnn`), their data
(:mod:`.data`: data sets, folders, augmentations), procedural shapes with parts
(:mod:`.synthetic`) and training, evaluation and files (:mod:`.run`)."""
