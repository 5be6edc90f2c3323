"""Semantic and instance segmentation: FCN, U-Net and their losses and training
(:mod:`.networks`), data with ground truth (:mod:`.data`) and scores (:mod:`.metrics`,
NumPy only)."""
