"""Drawing on images and colour maps for scalar fields."""

from robopercept.viz.cloud import render_points
from robopercept.viz.colormap import colorize_depth, colorize_signed, label_colors
from robopercept.viz.draw import draw_boxes, draw_lines, draw_mask, draw_points, draw_text

__all__ = [
    "colorize_depth",
    "colorize_signed",
    "draw_boxes",
    "draw_lines",
    "draw_mask",
    "draw_points",
    "draw_text",
    "label_colors",
    "render_points",
]
