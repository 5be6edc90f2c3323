"""``robopercept info``: versions and which optional extras work here."""

from __future__ import annotations

import argparse
import importlib
import json
import platform
import sys
from typing import Any

from robopercept import __version__

__all__ = ["packages", "register", "report", "report_dict"]

# (module, pip name, extra that brings it, what it is for)
_OPTIONAL = (
    ("torch", "torch", "deep", "CNNs, PointNet, DGCNN"),
    ("distributed", "dask[distributed]", "scale", "robopercept batch on a Dask cluster"),
    ("pyrealsense2", "pyrealsense2", "realsense", "RealSense live camera (recordings need not)"),
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


def packages() -> list[dict[str, Any]]:
    """One dictionary per core and optional package: ``name`` (the pip name),
    ``module`` (what is imported), ``version`` (None when it does not import),
    ``required`` (a core dependency), ``extra`` (the robopercept extra that brings an
    optional one, else None), ``purpose`` and ``install`` (the pip command when it is
    missing, else None).

    Examples
    --------
    >>> rows = packages()
    >>> rows[0]["name"], rows[0]["required"], rows[0]["version"] is not None
    ('numpy', True, True)
    """
    rows: list[dict[str, Any]] = []
    for mod in _CORE:
        v = _version(mod)
        rows.append(
            {
                "name": mod,
                "module": mod,
                "version": v,
                "required": True,
                "extra": None,
                "purpose": "required",
                "install": None if v else "pip install robopercept",
            }
        )
    for mod, pip_name, extra, purpose in _OPTIONAL:
        v = _version(mod)
        rows.append(
            {
                "name": pip_name,
                "module": mod,
                "version": v,
                "required": False,
                "extra": extra,
                "purpose": purpose,
                "install": None if v else f"pip install 'robopercept[{extra}]'",
            }
        )
    return rows


def report() -> list[tuple[str, str, str]]:
    """Rows ``(name, version or 'missing', note)`` for the core and optional packages.

    Examples
    --------
    >>> report()[0][0], report()[1][0]
    ('robopercept', 'python')
    """
    rows = [("robopercept", __version__, ""), ("python", platform.python_version(), sys.platform)]
    for p in packages():
        if p["required"]:
            rows.append((p["name"], p["version"] or "MISSING", "required"))
        else:
            note = p["purpose"] if p["version"] else f"{p['purpose']}; {p['install']}"
            rows.append((p["name"], p["version"] or "missing", note))
    return rows


def report_dict() -> dict[str, Any]:
    """What ``robopercept info --json`` prints: ``robopercept`` (version), ``python``
    (version), ``platform`` (``sys.platform``), ``packages`` (:func:`packages`) and
    ``missing_required`` (the pip names of core packages that do not import).

    Examples
    --------
    >>> info = report_dict()
    >>> info["robopercept"] == __version__, info["missing_required"]
    (True, [])
    """
    pkgs = packages()
    return {
        "robopercept": __version__,
        "python": platform.python_version(),
        "platform": sys.platform,
        "packages": pkgs,
        "missing_required": [p["name"] for p in pkgs if p["required"] and not p["version"]],
    }


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "info",
        help="versions and which optional extras work",
        description="Print the versions of robopercept, Python and the core and optional "
        "packages, and the pip command for each optional one that is missing.",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``robopercept info`` with the parsed ``args``; returns the exit status."""
    if getattr(args, "json", False):
        print(json.dumps(report_dict(), indent=2))
        return 0
    width = max(len(name) for name, _, _ in report()) + 1
    for name, version, note in report():
        print(f"{name:<{width}} {version:<14} {note}".rstrip())
    return 0
