"""Frame sources: synthetic RGB-D scenes, folders in the TUM layout, RealSense cameras and
recordings, and videos or image folders (:class:`VideoSource`).

Every source has the same contract: iterating yields the frames in order, ``len()`` is
the number it will yield (where known), and a source reading files or a device skips a
frame it cannot decode and records it in ``skipped`` as ``(index, reason)``.

:func:`import_rgbd_folder` (``robopercept rgbd-import``) turns other RGB-D folder layouts
(TUM lists, colour/depth subfolders, image pairs) into the folder layout that
:class:`TUMFolderSource` reads, with its ``camera.json``."""

from robopercept.sources.frames import RGBDFrame
from robopercept.sources.rgbd_import import (
    CAMERA_PRESETS,
    RGBDImportResult,
    camera_preset,
    import_rgbd_folder,
)
from robopercept.sources.synthetic import DISTRACTORS, MOTIONS, SyntheticRGBDScene
from robopercept.sources.tum import TUMFolderSource, read_camera_json, write_tum_folder
from robopercept.sources.video import IMAGE_EXTENSIONS, VideoSource

__all__ = [
    "CAMERA_PRESETS",
    "DISTRACTORS",
    "IMAGE_EXTENSIONS",
    "MOTIONS",
    "RGBDFrame",
    "RGBDImportResult",
    "SyntheticRGBDScene",
    "TUMFolderSource",
    "VideoSource",
    "camera_preset",
    "import_rgbd_folder",
    "read_camera_json",
    "write_tum_folder",
]
