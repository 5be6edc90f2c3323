"""Point-cloud networks: PointNet (:mod:`.pointnet`), DGCNN (:mod:`.dgcnn`), their data
(:mod:`.data`) and training, evaluation and files (:mod:`.run`)."""
