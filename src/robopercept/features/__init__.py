"""2-D features: corners (Harris, Shi-Tomasi), descriptor matching (HOG, SIFT to come)."""

from robopercept.features.harris import (
    harris_corners,
    harris_response,
    min_eigenvalue,
    refine_corners,
    structure_tensor,
)
from robopercept.features.keypoints import Keypoints
from robopercept.features.matching import Matches, knn_match, match_descriptors

__all__ = [
    "Keypoints",
    "Matches",
    "harris_corners",
    "harris_response",
    "knn_match",
    "match_descriptors",
    "min_eigenvalue",
    "refine_corners",
    "structure_tensor",
]
