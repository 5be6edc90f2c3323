"""COCO and Pascal-VOC data and evaluation, NumPy only (no torch): the COCO ground truth
and its JSON file (:mod:`.dataset`), COCO results files (:mod:`.results`), the COCO
bbox/segm/keypoint evaluation and its PR curves (:mod:`.evaluate`), Pascal-VOC XML files
and the VOC AP (:mod:`.voc`), run-length encoded masks (:mod:`.rle`)."""
