"""Frame sources: synthetic RGB-D scenes, folders in the TUM layout, RealSense cameras and
recordings, and videos or image folders (:class:`VideoSource`).

Every source has the same contract: iterating yields the frames in order, ``len()`` is
the number it will yield (where known), and a source reading files or a device skips a
frame it cannot decode and records it in ``skipped`` as ``(index, reason)``."""

from robopercept.sources.frames import RGBDFrame
from robopercept.sources.synthetic import SyntheticRGBDScene
from robopercept.sources.tum import TUMFolderSource, read_camera_json, write_tum_folder
from robopercept.sources.video import IMAGE_EXTENSIONS, VideoSource

__all__ = [
    "IMAGE_EXTENSIONS",
    "RGBDFrame",
    "SyntheticRGBDScene",
    "TUMFolderSource",
    "VideoSource",
    "read_camera_json",
    "write_tum_folder",
]
