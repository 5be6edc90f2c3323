"""2-D image processing: filters, edges, colour, morphology, blobs, pyramids, I/O."""

from robopercept.imaging.blobs import BlobFeatures, blob_features, label_components, otsu_threshold
from robopercept.imaging.color import (
    gray_255,
    hsv_range_mask,
    hsv_to_rgb,
    rgb_to_gray,
    rgb_to_hsv,
)
from robopercept.imaging.edges import canny, log_zero_crossings
from robopercept.imaging.filters import (
    box_filter,
    convolve,
    convolve_separable,
    correlate,
    correlate_separable,
    derivative_kernel,
    gaussian_blur,
    gaussian_kernel,
    gaussian_ksize,
    gradient,
    laplacian,
    laplacian_of_gaussian,
    median_filter,
    sobel,
)
from robopercept.imaging.io import (
    SnapshotVideoWriter,
    VideoReader,
    VideoWriter,
    check_image_path,
    check_video_path,
    read_image,
    sample_image_path,
    write_image,
)
from robopercept.imaging.morphology import closing, dilate, erode, opening, structuring_element
from robopercept.imaging.pyramids import gaussian_pyramid, pyr_down
from robopercept.imaging.segmentation import felzenszwalb, grid_edges
from robopercept.imaging.warp import remap, transform_points, warp_perspective

__all__ = [
    "BlobFeatures",
    "SnapshotVideoWriter",
    "VideoReader",
    "VideoWriter",
    "blob_features",
    "box_filter",
    "canny",
    "check_image_path",
    "check_video_path",
    "closing",
    "convolve",
    "convolve_separable",
    "correlate",
    "correlate_separable",
    "derivative_kernel",
    "dilate",
    "erode",
    "felzenszwalb",
    "gaussian_blur",
    "gaussian_kernel",
    "gaussian_ksize",
    "gaussian_pyramid",
    "gradient",
    "gray_255",
    "grid_edges",
    "hsv_range_mask",
    "hsv_to_rgb",
    "label_components",
    "laplacian",
    "laplacian_of_gaussian",
    "log_zero_crossings",
    "median_filter",
    "opening",
    "otsu_threshold",
    "pyr_down",
    "read_image",
    "remap",
    "rgb_to_gray",
    "rgb_to_hsv",
    "sample_image_path",
    "sobel",
    "structuring_element",
    "transform_points",
    "warp_perspective",
    "write_image",
]
