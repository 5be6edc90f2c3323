"""Image classification: the small VGG/Inception/ResNet family (:mod:`.models`) and the
run folder of ``robopercept nn train|eval|predict`` (:mod:`.run`, on one process or
several with DistributedDataParallel)."""
