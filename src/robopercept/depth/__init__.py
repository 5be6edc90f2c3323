"""Depth: RGB-D geometry (depth to points, texture coordinates, alignment)."""

from robopercept.depth.rgbd import (
    align_color_to_depth,
    align_depth_to_color,
    depth_to_points,
    pixel_rays,
    sample_colors,
    texture_coordinates,
)

__all__ = [
    "align_color_to_depth",
    "align_depth_to_color",
    "depth_to_points",
    "pixel_rays",
    "sample_colors",
    "texture_coordinates",
]
