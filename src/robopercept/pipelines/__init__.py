"""End-to-end applications built from the library's methods."""

from robopercept.pipelines.cloud import CloudProcessing, process_cloud
from robopercept.pipelines.mot import MotFrame, run_mot, track_objects
from robopercept.pipelines.plane_tracking import (
    PlaneHueModel,
    PlaneTracker,
    PlaneTrackerConfig,
    PlaneTrackResult,
    plane_errors,
    summarize,
)

__all__ = [
    "CloudProcessing",
    "MotFrame",
    "PlaneHueModel",
    "PlaneTrackResult",
    "PlaneTracker",
    "PlaneTrackerConfig",
    "plane_errors",
    "process_cloud",
    "run_mot",
    "summarize",
    "track_objects",
]
