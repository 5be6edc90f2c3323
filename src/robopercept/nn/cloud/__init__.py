"""Point-cloud networks: PointNet (:mod:`.pointnet`), DGCNN (:mod:`.dgcnn`), their data
(:mod:`.data`: data sets, folders, augmentations), procedural shapes with parts
(:mod:`.synthetic`), building, training, scoring and files (:mod:`.train`), and the run
of ``robopercept nn cloud`` (:mod:`.run`: data splits, the run folder, evaluation,
one file's prediction)."""
