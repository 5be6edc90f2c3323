"""COCO and Pascal-VOC data and evaluation: JSON and XML formats, results files, COCO
bbox/segm/keypoint evaluation and VOC AP (:mod:`.formats`), run-length encoded masks
(:mod:`.rle`, NumPy only)."""
