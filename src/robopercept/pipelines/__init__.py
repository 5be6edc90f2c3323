"""End-to-end applications built from the library's methods."""

from robopercept.pipelines.plane_tracking import (
    PlaneHueModel,
    PlaneTracker,
    PlaneTrackerConfig,
    PlaneTrackResult,
    plane_errors,
    summarize,
)

__all__ = [
    "PlaneHueModel",
    "PlaneTrackResult",
    "PlaneTracker",
    "PlaneTrackerConfig",
    "plane_errors",
    "summarize",
]
