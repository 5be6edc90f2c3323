"""2-D features: corners (Harris, Shi-Tomasi), HOG, descriptor matching (SIFT to come)."""

from robopercept.features.harris import (
    harris_corners,
    harris_response,
    min_eigenvalue,
    refine_corners,
    structure_tensor,
)
from robopercept.features.hog import cell_histograms, hog, hog_windows
from robopercept.features.keypoints import Keypoints
from robopercept.features.matching import Matches, knn_match, match_descriptors

__all__ = [
    "Keypoints",
    "Matches",
    "cell_histograms",
    "harris_corners",
    "harris_response",
    "hog",
    "hog_windows",
    "knn_match",
    "match_descriptors",
    "min_eigenvalue",
    "refine_corners",
    "structure_tensor",
]
