"""Tensor operations of the detection family: box formats, IoU/GIoU, the box coder, the
anchor generator, NMS, RoI pooling and mask pasting (:mod:`.boxes`)."""
