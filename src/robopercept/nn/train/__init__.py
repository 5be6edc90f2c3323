"""Training: the loop, its configuration, checkpoints and history (:mod:`.loop`), and
DistributedDataParallel training (:mod:`.distributed`)."""
