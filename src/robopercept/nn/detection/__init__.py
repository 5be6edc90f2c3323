"""Object detection, one concept per module as torchvision lays it out: the detector
contract and input checks (:mod:`.base`), anchor and region targets (:mod:`.targets`),
the two-stage region heads (:mod:`.roi_heads`), one module per detector
(:mod:`.localizer`, :mod:`.rcnn`, :mod:`.fast_rcnn`, :mod:`.faster_rcnn`,
:mod:`.mask_rcnn`, :mod:`.keypoint_rcnn`, :mod:`.fcos`), test-time augmentation
(:mod:`.tta`), training and COCO evaluation (:mod:`.train`), the detectors by name
(:mod:`.zoo`), and detection
data with exact ground truth: the record (:mod:`.data`), the synthetic sets
(:mod:`.synthetic`), the DeepForest tiles (:mod:`.deepforest`) and the augmentations
(:mod:`.augment`)."""
