"""``robopercept info``: versions and which optional extras work here."""

from __future__ import annotations

import argparse
import importlib
import platform
import sys

from robopercept import __version__

__all__ = ["register", "report"]

# (module, pip name, extra that brings it, what it is for)
_OPTIONAL = (
    ("torch", "torch", "deep", "CNNs, PointNet, DGCNN"),
    ("pyrealsense2", "pyrealsense2", "realsense", "RealSense cameras and .bag recordings"),
    ("cv2", "opencv-contrib-python-headless", "dev", "reference for tests and benchmarks"),
    ("skimage", "scikit-image", "dev", "reference for tests"),
    ("sklearn", "scikit-learn", "dev", "reference for tests"),
    ("open3d", "open3d", "dev", "reference for tests and benchmarks"),
    ("filterpy", "filterpy", "dev", "reference for tests"),
)
_CORE = ("numpy", "scipy", "numba", "imageio", "imageio_ffmpeg", "PIL", "tqdm")


def _version(module: str) -> str | None:
    try:
        mod = importlib.import_module(module)
    except Exception:  # any import failure means "not usable here"
        return None
    return str(getattr(mod, "__version__", getattr(mod, "VERSION", "installed")))


def report() -> list[tuple[str, str, str]]:
    """Rows ``(name, version or 'missing', note)`` for the core and optional packages."""
    rows = [("robopercept", __version__, ""), ("python", platform.python_version(), sys.platform)]
    for mod in _CORE:
        rows.append((mod, _version(mod) or "MISSING", "required"))
    for mod, pip_name, extra, purpose in _OPTIONAL:
        v = _version(mod)
        note = purpose if v else f"{purpose}; pip install 'robopercept[{extra}]'"
        rows.append((pip_name, v or "missing", note))
    return rows


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser("info", help="versions and which optional extras work")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``robopercept info`` with the parsed ``args``; returns the exit status."""
    for name, version, note in report():
        print(f"{name:<24} {version:<14} {note}")
    return 0
