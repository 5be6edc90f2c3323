"""Robust estimation: least squares, the RANSAC engine and its models, homographies
from matches."""

from robopercept.estimation.homography import HomographyFit, find_homography
from robopercept.estimation.least_squares import (
    DepthPlaneFit,
    Line,
    LineFit,
    Plane,
    PlaneFit,
    fit_line,
    fit_plane,
    fit_plane_inverse_depth,
)
from robopercept.estimation.models import (
    AffineModel,
    HomographyModel,
    LineModel,
    Model,
    PlaneModel,
)
from robopercept.estimation.ransac import RansacResult, ransac, required_iterations

__all__ = [
    "AffineModel",
    "DepthPlaneFit",
    "HomographyFit",
    "HomographyModel",
    "Line",
    "LineFit",
    "LineModel",
    "Model",
    "Plane",
    "PlaneFit",
    "PlaneModel",
    "RansacResult",
    "find_homography",
    "fit_line",
    "fit_plane",
    "fit_plane_inverse_depth",
    "ransac",
    "required_iterations",
]
