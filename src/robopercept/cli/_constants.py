"""The library's names and limits that the parser needs before any command runs
(``choices`` and help texts), copied here so that building the parser imports no
library package: ``robopercept --help`` and ``--version`` stay fast (the sources and
pipeline packages import SciPy, numba and scikit-learn).

Each value equals its library original, which stays the one the library checks
(``tests/cli/test_startup.py`` compares them): change both together.
"""

from __future__ import annotations

__all__ = ["BATCH_JOBS", "BATCH_MAX_WORKERS", "SCENE_DISTRACTORS", "SCENE_MOTIONS"]

#: :data:`robopercept.pipelines.batch.JOBS`: the jobs of ``robopercept batch``
BATCH_JOBS = (
    "cloud",
    "edges",
    "features",
    "stereo",
    "plane-track",
    "nn-predict",
    "nn-detect",
    "nn-segment",
    "nn-pose",
    "nn-cloud",
)
#: :data:`robopercept.pipelines.batch.MAX_WORKERS`: the most local workers of a batch
BATCH_MAX_WORKERS = 256
#: :data:`robopercept.sources.MOTIONS`: the synthetic board's motion profiles
SCENE_MOTIONS = ("smooth", "fast", "jerky", "stop-go", "handheld")
#: :data:`robopercept.sources.DISTRACTORS`: the synthetic scene's green distractors
SCENE_DISTRACTORS = ("none", "box", "wall", "both")
