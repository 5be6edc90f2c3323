"""2-D features: corners (Harris, Shi-Tomasi), HOG, SIFT, descriptor matching, and
two-image matching and stitching."""

from robopercept.features.harris import (
    harris_corners,
    harris_response,
    min_eigenvalue,
    refine_corners,
    structure_tensor,
)
from robopercept.features.hog import cell_histograms, hog, hog_windows
from robopercept.features.keypoints import KeyPoint, Keypoints
from robopercept.features.matching import Matches, knn_match, match_descriptors
from robopercept.features.selective_search import (
    SIMILARITIES,
    hierarchical_grouping,
    selective_search,
)
from robopercept.features.sift import Features, sift
from robopercept.features.stitching import ImageMatch, Panorama, match_images, stitch

__all__ = [
    "SIMILARITIES",
    "Features",
    "ImageMatch",
    "KeyPoint",
    "Keypoints",
    "Matches",
    "Panorama",
    "cell_histograms",
    "harris_corners",
    "harris_response",
    "hierarchical_grouping",
    "hog",
    "hog_windows",
    "knn_match",
    "match_descriptors",
    "match_images",
    "min_eigenvalue",
    "refine_corners",
    "selective_search",
    "sift",
    "stitch",
    "structure_tensor",
]
