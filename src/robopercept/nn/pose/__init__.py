"""Pose estimation: heatmap and regression networks (:mod:`.networks`), pictorial
structures (:mod:`.pictorial`), 3-D by matching and lifting (:mod:`.lifting`), data
(:mod:`.data`), annotation files (:mod:`.io`) and PCK (:mod:`.metrics`)."""
