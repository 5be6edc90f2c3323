"""End-to-end applications built from the library's methods."""

from robopercept.pipelines.cloud import CloudProcessing, process_cloud
from robopercept.pipelines.mot import MotFrame, run_mot, track_objects
from robopercept.pipelines.plane_eval import (
    ErrorStats,
    PlaneErrorStats,
    PlaneTrackSummary,
    plane_errors,
    summarize,
)
from robopercept.pipelines.plane_measure import (
    PlaneHueModel,
    PlaneMeasurement,
    PlaneMeasurer,
    PlaneMeasurerConfig,
)
from robopercept.pipelines.plane_tracking import (
    PlaneTracker,
    PlaneTrackerConfig,
    PlaneTrackResult,
)

__all__ = [
    "CloudProcessing",
    "ErrorStats",
    "MotFrame",
    "PlaneErrorStats",
    "PlaneHueModel",
    "PlaneMeasurement",
    "PlaneMeasurer",
    "PlaneMeasurerConfig",
    "PlaneTrackResult",
    "PlaneTrackSummary",
    "PlaneTracker",
    "PlaneTrackerConfig",
    "plane_errors",
    "process_cloud",
    "run_mot",
    "summarize",
    "track_objects",
]
