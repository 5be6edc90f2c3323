"""Frame sources: RGB-D frames from folders (TUM layout) and, later, synthetic scenes and
RealSense cameras."""

from robopercept.sources.frames import RGBDFrame
from robopercept.sources.tum import TUMFolderSource, read_camera_json, write_tum_folder

__all__ = ["RGBDFrame", "TUMFolderSource", "read_camera_json", "write_tum_folder"]
