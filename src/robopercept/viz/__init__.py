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
from robopercept.viz.detection import detections_grid, draw_detections
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
from robopercept.viz.figure import readable_dpi
from robopercept.viz.flow import (
    arrow_scale,
    dense_flow_picture,
    draw_flow,
    draw_trails,
    flow_to_color,
    flow_wheel,
)
from robopercept.viz.learning import (
    confusion_figure,
    confusion_picture,
    curves_figure,
    curves_picture,
    precision_recall_picture,
    scatter_figure,
    scatter_picture,
    tiles_picture,
)
from robopercept.viz.plot import (
    Panel,
    Series,
    disparity_picture,
    plot_series,
    scalar_map_figure,
    scalar_map_picture,
    series_figure,
)
from robopercept.viz.pose import draw_skeleton, heatmap_grid, skeleton_3d_picture
from robopercept.viz.segmentation import class_overlay, instance_overlay, panels_picture

__all__ = [
    "MatchPicture",
    "Panel",
    "Series",
    "arrow_scale",
    "class_overlay",
    "cloud_picture",
    "clouds_grid",
    "colorize_depth",
    "colorize_signed",
    "confusion_figure",
    "confusion_picture",
    "critical_points_picture",
    "curves_figure",
    "curves_picture",
    "dense_flow_picture",
    "detections_grid",
    "disparity_picture",
    "draw_boxes",
    "draw_chessboard",
    "draw_detections",
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
    "plot_series",
    "precision_recall_picture",
    "project_outline",
    "readable_dpi",
    "render_points",
    "scalar_map_figure",
    "scalar_map_picture",
    "scatter_figure",
    "scatter_picture",
    "select_matches",
    "series_figure",
    "skeleton_3d_picture",
    "tiles_picture",
    "voc_palette",
]
