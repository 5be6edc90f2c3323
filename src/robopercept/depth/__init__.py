"""Depth: RGB-D geometry (depth to points, texture coordinates, alignment, colour
selection of points) and stereo matching (block matching, semi-global matching,
disparity to depth), active sensor models (time of flight, active stereo)."""

from robopercept.depth.color_select import (
    ColoredPoints,
    ColorRangeSelector,
    points_in_color_range,
)
from robopercept.depth.rgbd import (
    align_color_to_depth,
    align_depth_to_color,
    depth_to_points,
    pixel_rays,
    sample_colors,
    texture_coordinates,
)
from robopercept.depth.sensors import (
    D435,
    ActiveStereoSensor,
    focal_from_fov,
    tof_ambiguity_range,
    tof_phase,
    tof_phase_distance,
    tof_pulse_distance,
    tof_pulse_time,
    tof_unwrap,
)
from robopercept.depth.stereo import (
    bad_pixel_rate,
    block_matching,
    census_transform,
    depth_resolution,
    disparity_to_depth,
    disparity_to_points,
    reprojection_matrix,
    semi_global_matching,
)

__all__ = [
    "D435",
    "ActiveStereoSensor",
    "ColorRangeSelector",
    "ColoredPoints",
    "align_color_to_depth",
    "align_depth_to_color",
    "bad_pixel_rate",
    "block_matching",
    "census_transform",
    "depth_resolution",
    "depth_to_points",
    "disparity_to_depth",
    "disparity_to_points",
    "focal_from_fov",
    "pixel_rays",
    "points_in_color_range",
    "reprojection_matrix",
    "sample_colors",
    "semi_global_matching",
    "texture_coordinates",
    "tof_ambiguity_range",
    "tof_phase",
    "tof_phase_distance",
    "tof_pulse_distance",
    "tof_pulse_time",
    "tof_unwrap",
]
