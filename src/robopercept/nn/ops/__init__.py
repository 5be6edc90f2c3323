"""Tensor operations of the detection family: box formats, IoU/GIoU and the box check
(:mod:`.boxes`), the box coder and the anchor generator (:mod:`.anchors`), NMS
(:mod:`.nms`), RoI pooling, RoI Align and mask pasting (:mod:`.roi`); the keypoint
heatmap codec shared by pose networks and Keypoint R-CNN (:mod:`.heatmaps`); the sigmoid
focal loss (:mod:`.losses`)."""
