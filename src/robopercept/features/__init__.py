"""2-D features: corners (Harris, Shi-Tomasi), HOG, SIFT, descriptor matching."""

from robopercept.features.harris import (
    harris_corners,
    harris_response,
    min_eigenvalue,
    refine_corners,
    structure_tensor,
)
from robopercept.features.keypoints import Keypoints

__all__ = [
    "Keypoints",
    "harris_corners",
    "harris_response",
    "min_eigenvalue",
    "refine_corners",
    "structure_tensor",
]
