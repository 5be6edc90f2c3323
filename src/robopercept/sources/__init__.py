"""Frame sources: synthetic RGB-D scenes, folders in the TUM layout, RealSense cameras and
recordings."""

from robopercept.sources.frames import RGBDFrame
from robopercept.sources.synthetic import SyntheticRGBDScene
from robopercept.sources.tum import TUMFolderSource, read_camera_json, write_tum_folder

__all__ = [
    "RGBDFrame",
    "SyntheticRGBDScene",
    "TUMFolderSource",
    "read_camera_json",
    "write_tum_folder",
]
