"""Shared network parts: the VGG/Inception/ResNet blocks (:mod:`.blocks`), the detection
backbone and FPN shared by detection and segmentation (:mod:`.backbones`), per-layer
summaries (:mod:`.summary`), fine-tuning helpers (:mod:`.transfer`) and ONNX export
(:mod:`.export`). Used by every task wing; imports no wing."""
