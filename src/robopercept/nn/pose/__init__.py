"""Pose estimation: heatmap and regression networks, saved and loaded (:mod:`.networks`),
run on images (:mod:`.inference`), trained (:mod:`.train`) and evaluated
(:mod:`.evaluate`); pictorial structures (:mod:`.pictorial`, learned by
:mod:`.pictorial_learn`); 3-D poses seen from cameras (:mod:`.views`), lifted by
matching (:mod:`.library`) or by a network (:mod:`.lifting`, with MPJPE); data
(:mod:`.data`; a COCO keypoint file's persons as top-down crops, :mod:`.crops`),
annotation files (:mod:`.io`) and PCK (:mod:`.metrics`). The heatmap codec is
:mod:`robopercept.nn.ops.heatmaps`."""
