"""Drawing on images and colour maps for scalar fields."""

from robopercept.viz.cloud import render_points
from robopercept.viz.cloud_dl import (
    cloud_picture,
    clouds_grid,
    critical_points_picture,
    feature_neighbours_picture,
)
from robopercept.viz.colormap import (
    colorize_depth,
    colorize_signed,
    label_colors,
    voc_palette,
)
from robopercept.viz.draw import (
    draw_boxes,
    draw_chessboard,
    draw_label,
    draw_lines,
    draw_mask,
    draw_points,
    draw_text,
    enlarge_picture,
    label_font,
    label_size_for,
)
from robopercept.viz.features import (
    MatchPicture,
    draw_matches,
    hog_picture,
    matches_picture,
    project_outline,
    select_matches,
)
from robopercept.viz.flow import (
    dense_flow_picture,
    draw_flow,
    draw_trails,
    flow_to_color,
    flow_wheel,
)
from robopercept.viz.learning import (
    confusion_picture,
    curves_picture,
    scatter_picture,
    tiles_picture,
)
from robopercept.viz.pose import draw_skeleton, heatmap_grid, skeleton_3d_picture
from robopercept.viz.segmentation import class_overlay, instance_overlay, panels_picture

__all__ = [
    "MatchPicture",
    "class_overlay",
    "cloud_picture",
    "clouds_grid",
    "colorize_depth",
    "colorize_signed",
    "confusion_picture",
    "critical_points_picture",
    "curves_picture",
    "dense_flow_picture",
    "draw_boxes",
    "draw_chessboard",
    "draw_flow",
    "draw_label",
    "draw_lines",
    "draw_mask",
    "draw_matches",
    "draw_points",
    "draw_skeleton",
    "draw_text",
    "draw_trails",
    "enlarge_picture",
    "feature_neighbours_picture",
    "flow_to_color",
    "flow_wheel",
    "heatmap_grid",
    "hog_picture",
    "instance_overlay",
    "label_colors",
    "label_font",
    "label_size_for",
    "matches_picture",
    "panels_picture",
    "project_outline",
    "render_points",
    "scatter_picture",
    "select_matches",
    "skeleton_3d_picture",
    "tiles_picture",
    "voc_palette",
]
