"""Training: its configuration, history, device and determinism (:mod:`.config`), THE
loop (:mod:`.loop`), checkpoints (:mod:`.checkpoint`), and DistributedDataParallel
training on several processes (:mod:`.distributed`)."""
