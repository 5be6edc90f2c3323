"""Object detection: the detectors from the single-object localizer to Faster/Mask/
Keypoint R-CNN and FCOS, their training and evaluation (:mod:`.models`), and detection
data with exact ground truth (:mod:`.data`)."""
