"""The API fuzzer: hostile arguments for every public callable of every package.

For each package of robopercept (``imaging``, ``geometry``, ... ``nn``) the names of its
``__all__`` are walked (for ``nn``, the ``__all__`` of each of its modules): functions,
class constructors, and the working methods of stateful classes (``fit``, ``predict``,
``transform`` of the estimators with hostile ``X`` and ``y``, ``update`` of the
filters and trackers, ``apply`` of the background models, ...). Each becomes a
:class:`Plan`: the callable and one *valid* value for every parameter -- the function's
default, else a value chosen by the parameter's name (``image`` gets a small textured
image, ``points`` a cloud of 60 points, ``path`` a file written on first use), else the
table :data:`VALID` of arguments per callable where the name says too little.

A fuzz input replaces ONE parameter by a hostile value (so an error is attributable to
it) drawn from the strategy of the parameter's *role*, which is read off the valid
value: an image-sized array gets :func:`~tests.fuzz.strategies.hostile_images`, an
``(N, 2|3)`` array :func:`~tests.fuzz.strategies.hostile_points`, a number
:func:`~tests.fuzz.strategies.hostile_scalars`, a string choice, a flag, a path, a
point cloud, a small matrix, a sequence, an object each their own (:func:`role_of`).

Each input runs in the :class:`~tests.fuzz.sandbox.Sandbox` worker, through
:func:`invoke`, and is classified there: ``ok``, ``typed`` (a ``RoboperceptError``),
``untyped`` (any other exception: a broken contract), ``crash`` (the worker died),
``hang`` (over the time limit) or ``memory`` (over the allocation limit).

What needs a live device, a GUI, a network, or minutes of training is skipped, with
its reason, in :data:`SKIP`; result records (frozen dataclasses without a validating
constructor, built by the library and not by users), enumerations and protocols are
skipped by rule (:func:`skip_reason`). :func:`build_plans` returns both lists.
"""

from __future__ import annotations

import atexit
import dataclasses
import enum
import functools
import importlib
import inspect
import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

from tests.fuzz import strategies as hs
from tests.fuzz.report import Tally
from tests.fuzz.strategies import Build, Layout, Recipe, describe, materialize, resolve

__all__ = [
    "PACKAGES",
    "PINNED",
    "SKIP",
    "VALID",
    "Fixture",
    "Plan",
    "build_plans",
    "draw_examples",
    "invoke",
    "make_fixtures",
    "plan_seed",
    "preload",
    "role_of",
    "run_api_campaign",
    "run_plan",
    "skip_reason",
]

#: the packages whose ``__all__`` is fuzzed, in floor order
PACKAGES: tuple[str, ...] = (
    "imaging",
    "geometry",
    "estimation",
    "features",
    "learning",
    "motion",
    "depth",
    "calibration",
    "pointcloud",
    "tracking",
    "viz",
    "sources",
    "pipelines",
    "nn",
)

#: the scratch folder of the campaign: inputs (``in/``: empty and garbage files of
#: every extension, lazily written fixtures) and outputs (``out/``)
WORKDIR = Path(
    os.environ.get("ROBOPERCEPT_FUZZ_DIR") or tempfile.mkdtemp(prefix="robopercept-fuzz-")
)
if not os.environ.get("ROBOPERCEPT_FUZZ_DIR"):
    _owner = os.getpid()  # the sandbox's forked workers must not remove it on exit
    atexit.register(lambda: os.getpid() == _owner and shutil.rmtree(WORKDIR, ignore_errors=True))
IN_DIR = WORKDIR / "in"
OUT_DIR = WORKDIR / "out"


# =========================================================================== valid data
# Small, deterministic, and built in the parent: they pickle into every call.


def _texture(h: int = 48, w: int = 64) -> np.ndarray:
    """A (h, w) uint8 image with corners, edges and blobs: 8-px checkerboard squares, a
    diagonal ramp and mild noise (every detector finds something in it)."""
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:h, 0:w]
    board = ((yy // 8 + xx // 8) % 2) * 150.0
    ramp = (xx + yy) * (80.0 / (h + w))
    img = board + ramp + rng.normal(0, 4, (h, w)) + 10
    return np.clip(img, 0, 255).astype(np.uint8)


IMG = _texture()
IMG2 = np.roll(IMG, 2, axis=1)  # the same scene shifted 2 px right (stereo, flow)
IMG_RGB = np.stack([IMG, IMG2, 255 - IMG], axis=-1)
IMG_F = IMG.astype(np.float64) / 255.0
MASK = np.zeros((48, 64), bool)
MASK[10:30, 12:40] = True
LABELS = MASK.astype(np.int32)
LABELS[35:45, 45:60] = 2

_rng = np.random.default_rng(3)
PTS3 = _rng.normal(size=(60, 3))
PTS3[:, 2] += 5.0
PTS2 = _rng.uniform(2, 60, (40, 2))

K = np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])
_ang = 0.05
R_SMALL = np.array([[np.cos(_ang), 0, np.sin(_ang)], [0, 1, 0], [-np.sin(_ang), 0, np.cos(_ang)]])
T_VEC = np.array([-0.5, 0.0, 0.0])
T4 = np.eye(4)
T4[:3, :3] = R_SMALL
T4[:3, 3] = [0.1, -0.2, 0.3]
P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
P2 = K @ np.hstack([R_SMALL, T_VEC[:, None]])
_X3 = np.column_stack([_rng.uniform(-1, 1, 30), _rng.uniform(-1, 1, 30), _rng.uniform(4, 6, 30)])


def _proj(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    h = np.column_stack([X, np.ones(len(X))]) @ P.T
    return h[:, :2] / h[:, 2:]


X1 = _proj(P1, _X3)  # (30, 2) pixels in view 1
X2 = _proj(P2, _X3)  # (30, 2) pixels in view 2
H3 = np.array([[1.05, 0.02, 3.0], [-0.01, 0.98, -2.0], [1e-4, 2e-4, 1.0]])
SRC = np.array([[x, y] for x in range(5, 60, 12) for y in range(5, 45, 10)], float)
_dst_h = np.column_stack([SRC, np.ones(len(SRC))]) @ H3.T
DST = _dst_h[:, :2] / _dst_h[:, 2:]
_skew_t = np.array([[0, -T_VEC[2], T_VEC[1]], [T_VEC[2], 0, -T_VEC[0]], [-T_VEC[1], T_VEC[0], 0]])
E_MAT = _skew_t @ R_SMALL
F_MAT = np.linalg.inv(K).T @ E_MAT @ np.linalg.inv(K)

# three Gaussian blobs in 4-D, 20 samples each: classifiers, clusterers, PCA, LDA
XB = np.concatenate([_rng.normal(c, 0.5, (20, 4)) for c in (0.0, 3.0, 6.0)])
YB = np.repeat(np.arange(3), 20)
YR = XB[:, 0] * 2.0 + _rng.normal(0, 0.1, 60)
Y2 = (np.arange(40) % 2).astype(np.int64)
S2 = np.linspace(0.05, 0.95, 40) + 0.3 * (Y2 - 0.5)

BOXES = np.array([[5.0, 5.0, 20.0, 20.0], [30.0, 10.0, 50.0, 40.0]])
DEPTH_U16 = (1000 + 10 * (np.arange(48)[:, None] + np.arange(64)[None, :])).astype(np.uint16)
DEPTH_M = DEPTH_U16.astype(np.float64) / 1000.0
DISP = np.full((48, 64), 8.0) + np.linspace(0, 4, 64)[None, :]
FLOW = np.dstack([np.full((48, 64), 1.5), np.full((48, 64), -0.5)])

# calibration: a 4x3 board of 1-unit squares seen in 3 poses through K
BOARD = np.array([[x, y, 0.0] for y in range(3) for x in range(4)])


def _view(rx: float, ry: float, tz: float) -> np.ndarray:
    c, s = np.cos(rx), np.sin(rx)
    rot_x = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    c, s = np.cos(ry), np.sin(ry)
    rot_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    cam = BOARD @ (rot_y @ rot_x).T + [-1.5, -1.0, tz]
    return _proj(K @ np.hstack([np.eye(3), np.zeros((3, 1))]), cam)


VIEWS = [
    _view(0.2, 0.1, 8.0),
    _view(-0.25, 0.3, 9.0),
    _view(0.1, -0.35, 7.5),
    _view(0.3, 0.25, 8.5),
]
RVECS = np.zeros((1, 3))
TVECS = np.array([[-1.5, -1.0, 8.0]])
HAND_A = np.stack([np.eye(4)] * 4)
for _i, (_a, _t) in enumerate([(0.3, 0.1), (-0.4, 0.2), (0.5, -0.3), (0.2, 0.4)]):
    _c, _s = np.cos(_a), np.sin(_a)
    HAND_A[_i, :3, :3] = np.array([[_c, -_s, 0], [_s, _c, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, np.cos(_t), -np.sin(_t)], [0, np.sin(_t), np.cos(_t)]]
    )
    HAND_A[_i, :3, 3] = [0.1 * _i, 0.05, 0.2 - 0.03 * _i]
_Xhe = T4
HAND_B = np.stack([np.linalg.inv(_Xhe) @ np.linalg.inv(a) @ np.eye(4) for a in HAND_A])


def _b(target: str, *args: Any, **kwargs: Any) -> Build:
    """Shorthand for a :class:`Build` recipe."""
    return Build(target, tuple(args), tuple(kwargs.items()))


CAM = _b("robopercept.geometry:CameraIntrinsics", 64, 48, 50.0, 50.0, 32.0, 24.0)
CLOUD = _b("robopercept.pointcloud:PointCloud", PTS3)
KF = _b("robopercept.tracking:constant_velocity", 2, 1.0, 1.0, 1.0)
SCENE = _b(
    "robopercept.sources:SyntheticRGBDScene",
    n_frames=3,
    depth_size=(64, 48),
    color_size=(64, 48),
)
FRAME = _b("tests.fuzz.api:scene_frame", 0)
PLANE = _b("robopercept.estimation:Plane", np.array([0.0, 0.0, 1.0]), -5.0)
TORCH_IMG = _b("tests.fuzz.api:torch_image", 1, 16, 16)
TINY_NET = _b(
    "robopercept.nn.classification.models:vgg_small", 1, 3, widths=(4,), convs_per_stage=1
)
ARRAY_DATA = _b(
    "robopercept.nn.data.datasets:ArrayDataset",
    np.random.default_rng(5).uniform(0, 1, (12, 8, 8)).astype(np.float32),
    np.arange(12) % 3,
    ("a", "b", "c"),
)
TBOXES = _b("tests.fuzz.api:torch_tensor", [[0, 0, 4, 4], [1, 1, 5, 6], [2, 0, 7, 3]])
TSCORES = _b("tests.fuzz.api:torch_tensor", [0.9, 0.8, 0.3])
TROIS = _b("tests.fuzz.api:torch_tensor", [[0, 0, 0, 4, 4], [0, 1, 2, 7, 6]])
TRAIN_CFG = _b("robopercept.nn.train.config:TrainConfig", epochs=1, batch_size=4, device="cpu")


@dataclass(frozen=True)
class Fixture(Recipe):
    """A file or folder made on first use in the worker (``IN_DIR/name``), by the
    function :data:`FIXTURES` names; its path (a ``str``) is the valid value.

    Parameters
    ----------
    name : str
        File name, with the extension that readers dispatch on (``cloud.pcd``).
    root : str
        The folder it lives in (the parent's :data:`IN_DIR`, passed along so that a
        worker started in any way finds it).
    """

    name: str
    root: str = str(IN_DIR)

    def make(self) -> str:
        """Create the fixture if it is missing and return its path."""
        path = Path(self.root) / self.name
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            FIXTURES[self.name](path)
        return str(path)

    def __repr__(self) -> str:
        return f"<{self.name}>"


def scene_frame(index: int) -> Any:
    """Frame ``index`` of a 3-frame, 64x48 synthetic RGB-D scene (valid frames)."""
    return materialize(SCENE).frame(index)


def torch_image(*shape: int) -> Any:
    """A float32 tensor of ``shape`` of uniform noise, seeded (valid transform input)."""
    import torch

    g = torch.Generator().manual_seed(0)
    return torch.rand(shape, generator=g)


def torch_tensor(values: Any, dtype: str = "float32") -> Any:
    """``torch.tensor(values)`` of ``dtype`` (boxes, scores, class ids)."""
    import torch

    return torch.tensor(values, dtype=getattr(torch, dtype))


def _write_image(path: Path) -> None:
    from robopercept.imaging import write_image

    write_image(path, IMG_RGB)


def _write_cloud(path: Path) -> None:
    from robopercept.pointcloud import PointCloud, write_point_cloud

    write_point_cloud(path, PointCloud(PTS3))


def _write_video(path: Path) -> None:
    from robopercept.imaging import VideoWriter

    w = VideoWriter(path, fps=10.0)
    for i in range(4):
        w.write(np.roll(IMG_RGB, 3 * i, axis=1))
    w.close()


def _write_mot(path: Path) -> None:
    from robopercept.tracking import write_mot

    write_mot(path, [(1, 1, (5.0, 5.0, 10.0, 10.0), 1.0), (2, 1, (6.0, 5.0, 10.0, 10.0), 0.9)])


def _write_calibration(path: Path) -> None:
    from robopercept.calibration import CalibrationResult, save_calibration

    save_calibration(
        path,
        CalibrationResult(K, np.zeros(5), RVECS, TVECS, 0.1, np.array([0.1]), (64, 48)),
    )


def _write_tum(path: Path) -> None:
    from robopercept.sources import write_tum_folder

    write_tum_folder(path, list(materialize(SCENE)))


def _write_checkpoint(path: Path) -> None:
    from robopercept.nn.train.checkpoint import save_checkpoint

    save_checkpoint(path, {"epoch": 1, "model": materialize(TINY_NET).state_dict()})


def _write_detector(path: Path) -> None:
    from robopercept.nn.detection.zoo import build_detector, save_detector

    save_detector(path, build_detector("fcos", 2, width=4), "fcos", {"width": 4}, ["a", "b"])


def _write_run(path: Path) -> None:
    from robopercept.nn.classification.run import train_run
    from robopercept.nn.train.config import TrainConfig

    train_run(
        "digits",
        "vgg_small",
        path,
        config=TrainConfig(epochs=1, batch_size=64, device="cpu"),
        model_kwargs={"widths": [4], "convs_per_stage": 1},
    )


def _write_image_folder(path: Path) -> None:
    from robopercept.imaging import write_image

    for k, cls in enumerate(("a", "b")):
        (path / cls).mkdir(parents=True, exist_ok=True)
        for i in range(4):
            write_image(path / cls / f"{i}.png", np.roll(IMG_RGB, 5 * i + 20 * k, axis=1))


def _write_rgbd_pairs(path: Path) -> None:
    from robopercept.imaging import write_image

    path.mkdir(parents=True, exist_ok=True)
    for i in range(2):
        write_image(path / f"{i:04d}_rgb.png", IMG_RGB)
        write_image(path / f"{i:04d}_depth.png", DEPTH_U16)


FIXTURES: dict[str, Callable[[Path], None]] = {
    "image.png": _write_image,
    "cloud.pcd": _write_cloud,
    "cloud.ply": _write_cloud,
    "video.mp4": _write_video,
    "mot.txt": _write_mot,
    "calibration.yaml": _write_calibration,
    "calibration.json": _write_calibration,
    "tum": _write_tum,
    "tum/camera.json": lambda p: _write_tum(p.parent),
    "pose.txt": lambda p: p.write_text("10 20 30 0.1 0.2 0.3\n"),
    "table.csv": lambda p: p.write_text(
        "a,b,label\n"
        + "".join(f"{x:.3f},{y:.3f},{'xy'[i % 2]}\n" for i, (x, y) in enumerate(PTS2[:20]))
    ),
    "checkpoint.pt": _write_checkpoint,
    "detector.pt": _write_detector,
    "run": _write_run,
    "run/checkpoint.pt": lambda p: _write_run(p.parent),
    "images": _write_image_folder,
    "rgbd_pairs": _write_rgbd_pairs,
}


def _out(name: str) -> str:
    return str(OUT_DIR / name)


# =========================================================================== the table
# Valid arguments where the parameter's name and default say too little. Keys are plan
# names: "package.name" for functions and constructors, "package.Class.method" for
# methods; "*" holds the positional arguments (varargs, positional-only).

_IMG_ONLY = {"image": IMG}

VALID: dict[str, dict[str, Any]] = {
    # ------------------------------------------------------------------ imaging
    "imaging.SnapshotVideoWriter": {"path": _out("snap.mp4"), "fps": 10.0},
    "imaging.SnapshotVideoWriter.add": {"index": 0, "picture": IMG_RGB},
    "imaging.VideoReader": {"path": Fixture("video.mp4")},
    "imaging.VideoReader.__iter__": {},
    "imaging.VideoWriter": {"path": _out("video.mp4")},
    "imaging.VideoWriter.write": {"frame": IMG_RGB},
    "imaging.blob_features": {"labels": LABELS},
    "imaging.box_filter": {"image": IMG, "ksize": 3},
    "imaging.canny": {"image": IMG, "low": 20.0, "high": 60.0},
    "imaging.check_image_path": {"path": Fixture("image.png")},
    "imaging.check_video_path": {"path": Fixture("video.mp4")},
    "imaging.convolve": {"image": IMG, "kernel": np.ones((3, 3)) / 9},
    "imaging.convolve_separable": {
        "image": IMG,
        "kernel_x": np.ones(3) / 3,
        "kernel_y": np.ones(3) / 3,
    },
    "imaging.correlate": {"image": IMG, "kernel": np.ones((3, 3)) / 9},
    "imaging.correlate_separable": {
        "image": IMG,
        "kernel_x": np.ones(3) / 3,
        "kernel_y": np.ones(3) / 3,
    },
    "imaging.derivative_kernel": {"order": 1, "ksize": 3},
    "imaging.gaussian_blur": {"image": IMG, "sigma": 1.5},
    "imaging.gaussian_kernel": {"sigma": 1.5},
    "imaging.gaussian_ksize": {"sigma": 1.5},
    "imaging.gaussian_pyramid": {"image": IMG, "levels": 2},
    "imaging.hsv_range_mask": {
        "hsv": IMG_RGB,
        "low": (10.0, 20.0, 20.0),
        "high": (90.0, 255.0, 255.0),
    },
    "imaging.hsv_to_rgb": {"hsv": (IMG_RGB // 2).astype(np.uint8)},
    "imaging.label_components": {"mask": MASK},
    "imaging.laplacian_of_gaussian": {"image": IMG, "sigma": 1.5},
    "imaging.log_zero_crossings": {"log": IMG_F - 0.5},
    "imaging.read_image": {"path": Fixture("image.png")},
    "imaging.remap": {
        "image": IMG,
        "map_x": np.tile(np.arange(64, dtype=np.float32), (48, 1)) + 0.5,
        "map_y": np.tile(np.arange(48, dtype=np.float32)[:, None], (1, 64)),
    },
    "imaging.rgb_to_gray": {"image": IMG_RGB},
    "imaging.rgb_to_hsv": {"image": IMG_RGB},
    "imaging.sobel": {"image": IMG, "dx": 1, "dy": 0},
    "imaging.structuring_element": {"shape": "ellipse", "size": 5},
    "imaging.transform_points": {"h": H3, "xy": PTS2},
    "imaging.warp_perspective": {"image": IMG, "h": H3, "dsize": (64, 48)},
    "imaging.write_image": {"path": _out("image.png"), "image": IMG_RGB},
    # ------------------------------------------------------------------ geometry
    "geometry.CameraIntrinsics": {
        "width": 64,
        "height": 48,
        "fx": 50.0,
        "fy": 50.0,
        "cx": 32.0,
        "cy": 24.0,
    },
    "geometry.CameraIntrinsics.scaled": {"width": 32, "height": 24},
    "geometry.apply": {"T": T4, "points": PTS3},
    "geometry.box_convert": {"boxes": BOXES, "in_fmt": "xywh", "out_fmt": "cxcywh"},
    "geometry.box_iou_matrix": {"a": BOXES, "b": BOXES[::-1].copy()},
    "geometry.greedy_nms": {"boxes": BOXES, "scores": np.array([0.9, 0.8]), "iou_threshold": 0.5},
    "geometry.compose": {"*": [T4, np.linalg.inv(T4)]},
    "geometry.decompose_essential": {"E": E_MAT, "x1": X1, "x2": X2, "K": K},
    "geometry.deproject": {"pixels": PTS2, "depth": np.full(40, 2.0), "intrinsics": CAM},
    "geometry.distort": {
        "x": PTS2[:, 0] / 100,
        "y": PTS2[:, 1] / 100,
        "coeffs": (0.1, -0.05, 0.001, 0.001, 0.0),
    },
    "geometry.eight_point": {"x1": X1, "x2": X2},
    "geometry.epipolar_lines": {"F": F_MAT, "points": X1},
    "geometry.epipoles": {"F": F_MAT},
    "geometry.essential_from_pose": {"R": R_SMALL, "t": T_VEC},
    "geometry.find_essential": {"x1": X1, "x2": X2, "K": K, "rng": 0},
    "geometry.find_fundamental": {"x1": X1, "x2": X2, "rng": 0},
    "geometry.fundamental_from_essential": {"E": E_MAT, "K1": K, "K2": K},
    "geometry.invert": {"T": T4},
    "geometry.nearest_rotation": {"M": R_SMALL + 0.01},
    "geometry.project": {"points": PTS3, "intrinsics": CAM},
    "geometry.rectify_stereo": {
        "K1": K,
        "D1": np.zeros(5),
        "K2": K,
        "D2": np.zeros(5),
        "R": R_SMALL,
        "T": T_VEC,
        "size": (64, 48),
    },
    "geometry.rectify_uncalibrated": {"F": F_MAT, "x1": X1, "x2": X2, "size": (64, 48)},
    "geometry.rotation_from_rotvec": {"rotvec": np.array([0.1, 0.2, 0.3])},
    "geometry.rotvec_from_rotation": {"R": R_SMALL},
    "geometry.sampson_distance": {"F": F_MAT, "x1": X1, "x2": X2},
    "geometry.se3": {"rotation": R_SMALL, "translation": T_VEC},
    "geometry.skew": {"v": np.array([1.0, 2.0, 3.0])},
    "geometry.triangulate": {"P1": P1, "P2": P2, "x1": X1, "x2": X2},
    "geometry.undistort": {
        "xd": PTS2[:, 0] / 100,
        "yd": PTS2[:, 1] / 100,
        "coeffs": (0.1, -0.05, 0.001, 0.001, 0.0),
    },
    "geometry.undistort_points": {
        "pixels": PTS2,
        "K": K,
        "dist": np.array([0.1, -0.05, 0.0, 0.0, 0.0]),
    },
    "geometry.undistort_rectify_map": {
        "K": K,
        "D": np.zeros(5),
        "R": np.eye(3),
        "P": K,
        "size": (64, 48),
    },
    # ------------------------------------------------------------------ estimation
    "estimation.find_homography": {"src": SRC, "dst": DST, "rng": 0},
    "estimation.fit_line": {"points": PTS2},
    "estimation.fit_plane": {"points": PTS3},
    "estimation.fit_plane_inverse_depth": {"points": PTS3},
    "estimation.ransac": {
        "data": PTS3,
        "model": _b("robopercept.estimation:PlaneModel"),
        "threshold": 0.5,
        "rng": 0,
    },
    "estimation.required_iterations": {"inlier_ratio": 0.5, "sample_size": 4, "probability": 0.99},
    "estimation.Plane": {"normal": np.array([0.0, 0.0, 1.0]), "offset": -5.0},
    "estimation.Plane.distance": {"points": PTS3},
    "estimation.Plane.project": {"points": PTS3},
    "estimation.Line": {"coefficients": np.array([1.0, -1.0, 0.5])},
    "estimation.Line.distance": {"points": PTS2},
    "estimation.LineModel.fit": {"data": PTS2},
    "estimation.PlaneModel.fit": {"data": PTS3},
    "estimation.HomographyModel.fit": {"data": np.hstack([SRC, DST])},
    "estimation.AffineModel.fit": {"data": np.hstack([SRC, DST])},
    # ------------------------------------------------------------------ features
    "features.Keypoints": {
        "xy": PTS2[:5],
        "scale": np.ones(5),
        "orientation": np.zeros(5),
        "response": np.ones(5),
        "octave": np.zeros(5, np.int64),
    },
    "features.cell_histograms": _IMG_ONLY,
    "features.harris_corners": _IMG_ONLY,
    "features.harris_response": _IMG_ONLY,
    "features.hog": {"image": IMG},
    "features.hog_windows": {"image": IMG, "window": (32, 32), "stride": 16},
    "features.knn_match": {"query": PTS3[:20] * 10, "train": PTS3[10:50] * 10},
    "features.match_descriptors": {"query": PTS3[:20] * 10, "train": PTS3[10:50] * 10},
    "features.match_images": {"image_a": IMG, "image_b": IMG2},
    "features.min_eigenvalue": _IMG_ONLY,
    "features.refine_corners": {"image": IMG, "corners": np.array([[16.0, 16.0], [24.0, 32.0]])},
    "features.sift": _IMG_ONLY,
    "features.stitch": {"image_a": IMG, "image_b": IMG2},
    "features.structure_tensor": _IMG_ONLY,
    # ------------------------------------------------------------------ learning
    "learning.GridSearch": {
        "estimator": _b("robopercept.learning:KMeans", 2, n_init=1),
        "param_grid": {"n_clusters": [2, 3]},
        "cv": 2,
    },
    "learning.GridSearch.fit": {"X": XB, "y": YB},
    "learning.RandomForestClassifier": {"n_estimators": 3},
    "learning.RandomForestRegressor": {"n_estimators": 3},
    "learning.KMeans": {"n_clusters": 3, "n_init": 1},
    "learning.accuracy_score": {"y_true": YB, "y_pred": np.roll(YB, 1)},
    "learning.adjusted_rand_score": {"labels_true": YB, "labels_pred": np.roll(YB, 1)},
    "learning.auc": {"x": np.linspace(0, 1, 10), "y": np.linspace(0, 1, 10) ** 2},
    "learning.average_precision_score": {"y_true": Y2, "y_score": S2},
    "learning.class_scores": {"model": "fitted:SVC", "X": XB, "n_classes": 3},
    "learning.classification_report": {"y_true": YB, "y_pred": np.roll(YB, 1)},
    "learning.clone": {"estimator": _b("robopercept.learning:KMeans", 3)},
    "learning.confusion_matrix": {"y_true": YB, "y_pred": np.roll(YB, 1)},
    "learning.confusion_table": {"confusion": np.array([[5, 1], [2, 7]]), "names": ["a", "b"]},
    "learning.cross_val_score": {
        "estimator": _b("robopercept.learning:DecisionTreeClassifier", max_depth=3),
        "X": XB,
        "y": YB,
        "cv": 3,
    },
    "learning.estimate_bandwidth": {"X": XB, "rng": 0},
    "learning.evaluate_classifier": {
        "model": "fitted:SVC",
        "X": XB,
        "codes": YB,
        "classes": np.array(["a", "b", "c"]),
    },
    "learning.f1_score": {"y_true": Y2, "y_pred": np.roll(Y2, 1)},
    "learning.kmeans_plusplus": {"X": XB, "n_clusters": 3, "rng": 0},
    "learning.label_codes": {"y": np.array(["b", "a", "b", "c"])},
    "learning.precision_recall_curve": {"y_true": Y2, "y_score": S2},
    "learning.precision_score": {"y_true": Y2, "y_pred": np.roll(Y2, 1)},
    "learning.read_table": {"path": Fixture("table.csv"), "label": "label"},
    "learning.recall_score": {"y_true": Y2, "y_pred": np.roll(Y2, 1)},
    "learning.roc_auc_score": {"y_true": Y2, "y_score": S2},
    "learning.roc_curve": {"y_true": Y2, "y_score": S2},
    "learning.standardize": {"*": [XB, XB[:10] + 1.0]},
    "learning.train_test_split": {"*": [XB, YB], "random_state": 0},
    "learning.KFold.split": {"X": XB},
    "learning.PCA.inverse_transform": {"Z": XB},
    "learning.StratifiedKFold.split": {"X": XB, "y": YB},
    # ------------------------------------------------------------------ motion
    "motion.StaticBackground": {"reference": IMG},
    "motion.classify_motion": {"points": PTS2, "flow": np.tile([1.5, -0.5], (40, 1))},
    "motion.clean_mask": {"mask": MASK},
    "motion.dense_flow": {"prev": IMG, "next": IMG2},
    "motion.detections_from_mask": {"mask": MASK, "min_area": 10},
    "motion.good_features_to_track": {"image": IMG},
    "motion.lucas_kanade": {
        "prev": IMG,
        "next": IMG2,
        "points": np.array([[16.0, 16.0], [32.0, 24.0]]),
    },
    "motion.moving_blobs": {"n_frames": 3, "size": (64, 48), "radius": (4.0, 8.0)},
    "motion.KLTTracker": {"max_corners": 50},
    # ------------------------------------------------------------------ depth
    "depth.ActiveStereoSensor": {"baseline": 0.05, "width": 64, "hfov_deg": 87.0},
    "depth.ActiveStereoSensor.disparity": {"depth": DEPTH_M},
    "depth.ActiveStereoSensor.depth_rms_error": {"depth": DEPTH_M},
    "depth.ColorRangeSelector": {"hsv_low": (0.0, 0.0, 0.0), "hsv_high": (180.0, 255.0, 255.0)},
    "depth.ColorRangeSelector.__call__": {
        "depth": DEPTH_U16,
        "color": IMG_RGB,
        "depth_intrinsics": CAM,
        "color_intrinsics": CAM,
        "T_color_depth": np.eye(4),
        "depth_scale": 0.001,
    },
    "depth.depth_scale_warning": {"depth": DEPTH_U16, "depth_scale": 0.001},
    "depth.plausible_depth": {"median_m": 1.5},
    "depth.align_color_to_depth": {
        "color_image": IMG_RGB,
        "depth": DEPTH_U16,
        "depth_intrinsics": CAM,
        "color_intrinsics": CAM,
        "T_color_depth": np.eye(4),
    },
    "depth.align_depth_to_color": {
        "depth": DEPTH_U16,
        "depth_intrinsics": CAM,
        "color_intrinsics": CAM,
        "T_color_depth": np.eye(4),
    },
    "depth.bad_pixel_rate": {"disparity": DISP, "truth": DISP + 0.5},
    "depth.block_matching": {"left": IMG, "right": IMG2, "max_disparity": 8, "window": 5},
    "depth.census_transform": {"image": IMG, "window": 5},
    "depth.depth_resolution": {"depth": np.array([0.5, 1.0, 2.0]), "focal": 50.0, "baseline": 0.05},
    "depth.depth_to_points": {"depth": DEPTH_U16, "intrinsics": CAM},
    "depth.disparity_to_depth": {"disparity": DISP, "focal": 50.0, "baseline": 0.05},
    "depth.disparity_to_points": {
        "disparity": DISP,
        "Q": np.array([[1, 0, 0, -32.0], [0, 1, 0, -24.0], [0, 0, 0, 50.0], [0, 0, 20.0, 0]]),
    },
    "depth.focal_from_fov": {"width": 64, "hfov_deg": 87.0},
    "depth.pixel_rays": {"intrinsics": CAM},
    "depth.points_in_color_range": {
        "depth": DEPTH_U16,
        "color": IMG_RGB,
        "depth_intrinsics": CAM,
        "color_intrinsics": CAM,
        "T_color_depth": np.eye(4),
        "depth_scale": 0.001,
        "hsv_low": (0.0, 0.0, 0.0),
        "hsv_high": (180.0, 255.0, 255.0),
    },
    "depth.reprojection_matrix": {"focal": 50.0, "baseline": 0.05, "size": (64, 48)},
    "depth.sample_colors": {"color_image": IMG_RGB, "uv": PTS2 / np.array([64.0, 64.0])},
    "depth.semi_global_matching": {"left": IMG, "right": IMG2, "max_disparity": 8, "paths": 4},
    "depth.texture_coordinates": {
        "points": PTS3,
        "T_color_depth": np.eye(4),
        "color_intrinsics": CAM,
    },
    "depth.tof_ambiguity_range": {"modulation_frequency": 20e6},
    "depth.tof_phase": {"distance": np.array([0.5, 1.0, 2.0]), "modulation_frequency": 20e6},
    "depth.tof_phase_distance": {"phase": np.array([0.1, 1.0, 3.0]), "modulation_frequency": 20e6},
    "depth.tof_pulse_distance": {"round_trip_time": np.array([1e-9, 1e-8])},
    "depth.tof_pulse_time": {"distance": np.array([0.5, 1.0, 2.0])},
    "depth.tof_unwrap": {
        "phase1": np.array([1.0, 2.0]),
        "f1": 20e6,
        "phase2": np.array([0.5, 1.5]),
        "f2": 15e6,
        "max_distance": 20.0,
    },
    # ------------------------------------------------------------------ calibration
    "calibration.board_pose": {"object_points": BOARD, "image_points": VIEWS[0], "K": K},
    "calibration.calibrate_camera": {
        "object_points": [BOARD] * 4,
        "image_points": VIEWS,
        "image_size": (64, 48),
    },
    "calibration.calibrate_hand_eye": {"T_base_gripper": HAND_A, "T_camera_target": HAND_B},
    "calibration.chessboard_points": {"pattern_size": (4, 3)},
    "calibration.circles_grid_points": {"pattern_size": (4, 3)},
    "calibration.find_chessboard_corners": {"image": IMG, "pattern_size": (5, 3)},
    "calibration.find_circles_grid": {"image": IMG, "pattern_size": (4, 3)},
    "calibration.hand_eye_residuals": {
        "X": T4,
        "T_base_gripper": HAND_A,
        "T_camera_target": HAND_B,
    },
    "calibration.load_calibration": {"path": Fixture("calibration.json")},
    "calibration.pose_from_xyz_rpy": {
        "xyz": np.array([1.0, 2.0, 3.0]),
        "rpy": np.array([10.0, 20.0, 30.0]),
    },
    "calibration.read_opencv_storage": {"path": Fixture("calibration.yaml")},
    "calibration.read_xyz_rpy": {"path": Fixture("pose.txt")},
    "calibration.rectify_pair": {"left": IMG, "right": IMG2, "calibration": "stereo_calibration"},
    "calibration.reprojection_errors": {
        "object_points": [BOARD] * 3,
        "image_points": VIEWS[:3],
        "K": K,
        "dist": np.zeros(5),
        "rvecs": np.zeros((3, 3)),
        "tvecs": np.tile(TVECS, (3, 1)),
    },
    "calibration.save_calibration": {
        "path": _out("calibration.json"),
        "result": _b(
            "robopercept.calibration:CalibrationResult",
            K,
            np.zeros(5),
            RVECS,
            TVECS,
            0.1,
            np.array([0.1]),
            (64, 48),
        ),
    },
    "calibration.stereo_calibrate": {
        "object_points": [BOARD] * 4,
        "image_points1": VIEWS,
        "image_points2": [v + np.array([3.0, 0.0]) for v in VIEWS],
        "image_size": (64, 48),
        "K1": K,
        "dist1": np.zeros(5),
        "K2": K,
        "dist2": np.zeros(5),
    },
    "calibration.undistort": {"image": IMG, "K": K, "dist": np.array([0.1, -0.05, 0.0, 0.0, 0.0])},
    "calibration.xyz_rpy_from_pose": {"T": T4},
    # ------------------------------------------------------------------ pointcloud
    "pointcloud.PointCloud": {"points": PTS3},
    "pointcloud.PointCloud.select": {"selection": np.arange(10)},
    "pointcloud.PointCloud.with_colors": {"colors": np.full((60, 3), 0.5)},
    "pointcloud.check_cloud_path": {"path": Fixture("cloud.ply")},
    "pointcloud.estimate_normals": {"cloud": CLOUD, "k": 10},
    "pointcloud.euclidean_clusters": {"cloud": CLOUD, "tolerance": 0.5},
    "pointcloud.pass_through": {"cloud": CLOUD, "axis": "z", "min_value": 4.0, "max_value": 6.0},
    "pointcloud.radius_outlier_removal": {"cloud": CLOUD, "radius": 1.0, "min_neighbors": 2},
    "pointcloud.read_pcd": {"path": Fixture("cloud.pcd")},
    "pointcloud.read_point_cloud": {"path": Fixture("cloud.ply")},
    "pointcloud.segment_plane": {"cloud": CLOUD, "threshold": 0.5, "rng": 0},
    "pointcloud.segment_planes": {"cloud": CLOUD, "threshold": 0.5, "min_inliers": 10, "rng": 0},
    "pointcloud.statistical_outlier_removal": {"cloud": CLOUD, "k": 8},
    "pointcloud.voxel_downsample": {"cloud": CLOUD, "voxel_size": 0.5},
    "pointcloud.write_point_cloud": {"path": _out("cloud.ply"), "cloud": CLOUD},
    # ------------------------------------------------------------------ tracking
    "tracking.ExtendedKalmanFilter": {
        "dim_x": 2,
        "dim_z": 1,
        "h": "ekf_h",
        "H_jacobian": "ekf_H",
    },
    "tracking.ExtendedKalmanFilter.update": {"z": np.array([1.0])},
    "tracking.IMMEstimator": {
        "filters": [KF, KF],
        "mu": np.array([0.5, 0.5]),
        "M": np.array([[0.9, 0.1], [0.1, 0.9]]),
    },
    "tracking.IMMEstimator.update": {"z": np.array([1.0, 2.0])},
    "tracking.KalmanFilter": {"dim_x": 4, "dim_z": 2},
    "tracking.KalmanFilter.update": {"z": np.array([1.0, 2.0])},
    "tracking.KalmanFilter.predict": {},
    "tracking.GatedTrack.step": {"z": np.array([0.0, 0.0, 1.0, 2.0]), "R": np.eye(4) * 0.01},
    "tracking.MeanShiftTracker": {"frame": IMG_RGB, "box": (12.0, 10.0, 20.0, 16.0)},
    "tracking.MeanShiftTracker.update": {"frame": np.roll(IMG_RGB, 2, axis=1)},
    "tracking.MultiObjectTracker.update": {"detections": BOXES, "scores": np.array([0.9, 0.8])},
    "tracking.constant_acceleration": {"dim": 2, "dt": 1.0, "q": 1.0, "r": 1.0},
    "tracking.constant_position": {"dim": 2, "dt": 1.0, "q": 1.0, "r": 1.0},
    "tracking.constant_velocity": {"dim": 2, "dt": 1.0, "q": 1.0, "r": 1.0},
    "tracking.kf_predict": {
        "x": np.array([0.0, 1.0]),
        "P": np.eye(2),
        "A": np.array([[1.0, 1.0], [0.0, 1.0]]),
        "Q": np.eye(2) * 0.1,
    },
    "tracking.kf_update": {
        "x": np.array([0.0, 1.0]),
        "P": np.eye(2),
        "z": np.array([0.5]),
        "H": np.array([[1.0, 0.0]]),
        "R": np.eye(1),
    },
    "tracking.lagged_model": {
        "A": np.array([[1.0, 1.0], [0.0, 1.0]]),
        "Q": np.eye(2) * 0.1,
        "k": 1,
        "lag": 2,
    },
    "tracking.read_mot": {"path": Fixture("mot.txt")},
    "tracking.rts_smooth": {
        "xs": np.array([[0.0, 1.0], [1.0, 1.0], [2.1, 1.0]]),
        "Ps": np.stack([np.eye(2) * 0.1] * 3),
        "As": np.stack([np.array([[1.0, 1.0], [0.0, 1.0]])] * 3),
        "Qs": np.stack([np.eye(2) * 0.01] * 3),
    },
    "tracking.write_mot": {
        "path": _out("mot.txt"),
        "rows": [(1, 1, (5.0, 5.0, 10.0, 10.0), 1.0), (2, 1, (6.0, 5.0, 10.0, 10.0), 0.9)],
    },
    # ------------------------------------------------------------------ viz
    "viz.class_overlay": {
        "image": IMG_RGB,
        "labels": (IMG // 100).astype(np.int64),
        "classes": ["a", "b"],
    },
    "viz.instance_overlay": {
        "image": IMG_RGB,
        "masks": np.stack([IMG > 100, IMG > 200]),
        "labels": [1, 2],
        "classes": ["a", "b"],
        "scores": [0.9, 0.5],
    },
    "viz.panels_picture": {"pictures": [IMG_RGB, IMG], "titles": ["a", "b"]},
    "viz.colorize_depth": {"depth": DEPTH_M},
    "viz.colorize_signed": {"field": IMG_F - 0.5},
    "viz.confusion_picture": {"matrix": np.array([[5, 1], [2, 7]]), "names": ["a", "b"]},
    "viz.curves_picture": {
        "curves": [(np.linspace(0, 1, 5), np.linspace(0, 1, 5) ** 2, "a")],
        "title": "t",
        "xlabel": "x",
        "ylabel": "y",
        "width": 200,
        "height": 160,
    },
    "viz.precision_recall_picture": {
        "recall": np.linspace(0, 1, 11),
        "precision": np.stack([1 - np.linspace(0, 1, 11) ** 2, -np.ones(11)]),
        "labels": ["a", "b"],
        "iou_threshold": 0.5,
        "width": 200,
        "height": 160,
    },
    "viz.dense_flow_picture": {"field": FLOW[::8, ::8].copy(), "step": 8, "shape": (48, 64)},
    "viz.draw_boxes": {"image": IMG_RGB, "boxes": BOXES},
    "viz.draw_chessboard": {"image": IMG_RGB, "corners": VIEWS[0], "pattern_size": (4, 3)},
    "viz.draw_flow": {"image": IMG_RGB, "start": PTS2, "end": PTS2 + 2.0},
    "viz.draw_lines": {"image": IMG_RGB, "segments": np.hstack([PTS2[:5], PTS2[5:10]])},
    "viz.draw_mask": {"image": IMG_RGB, "mask": MASK},
    "viz.draw_matches": {
        "image_a": IMG_RGB,
        "xy_a": PTS2[:5],
        "image_b": IMG_RGB,
        "xy_b": PTS2[5:10],
    },
    "viz.draw_points": {"image": IMG_RGB, "points": PTS2},
    "viz.draw_text": {"image": IMG_RGB, "text": "fuzz"},
    "viz.draw_trails": {"image": IMG_RGB, "trails": [PTS2[:5], PTS2[5:9]]},
    "viz.flow_to_color": {"flow": FLOW},
    "viz.flow_wheel": {"size": 21},
    "viz.hog_picture": {"histograms": np.random.default_rng(0).uniform(0, 1, (4, 6, 9))},
    "viz.label_colors": {"labels": LABELS},
    "viz.render_points": {"points": PTS3, "size": (64, 48)},
    "viz.scatter_picture": {"points": PTS2, "labels": Y2, "width": 200, "height": 160},
    "viz.tiles_picture": {
        "tiles": np.random.default_rng(0).uniform(0, 1, (4, 8, 8)),
        "tile_px": 16,
    },
    "viz.enlarge_picture": {"img": IMG_RGB, "min_side": 200},
    # viz.pose (issue 28): a 4-joint pose, its heatmaps, a 3-D pose
    "viz.draw_skeleton": {
        "image": IMG_RGB,
        "keypoints": np.array([[10.0, 10.0, 2.0], [30.0, 20.0, 2.0], [50.0, 30.0, 1.0]]),
        "links": [(0, 1), (1, 2)],
        "confidence": np.array([0.9, 0.5, 0.2]),
        "labels": ["a", "b", "c"],
        "flip_pairs": [(0, 2)],
    },
    "viz.heatmap_grid": {
        "image": IMG_RGB,
        "heatmaps": np.random.default_rng(0).uniform(0, 1, (3, 6, 8)),
        "names": ["a", "b", "c"],
        "tile_px": 32,
    },
    "viz.skeleton_3d_picture": {
        "joints3d": PTS3[:4] - np.array([0.0, 0.0, 5.0]),
        "links": [(0, 1), (1, 2), (2, 3)],
        "reference": PTS3[4:8] - np.array([0.0, 0.0, 5.0]),
        "size": (300, 160),
    },
    # ------------------------------------------------------------------ sources
    "sources.RGBDFrame": {
        "index": 0,
        "timestamp": 0.0,
        "depth": DEPTH_U16,
        "color": IMG_RGB,
        "depth_intrinsics": CAM,
        "color_intrinsics": CAM,
        "T_color_depth": np.eye(4),
        "depth_scale": 0.001,
    },
    "sources.SyntheticRGBDScene": {"n_frames": 2, "depth_size": (64, 48), "color_size": (64, 48)},
    "sources.SyntheticRGBDScene.frame": {"index": 1},
    "sources.SyntheticRGBDScene.__iter__": {},
    "sources.TUMFolderSource": {"path": Fixture("tum")},
    "sources.TUMFolderSource.__iter__": {},
    "sources.VideoSource": {"path": Fixture("video.mp4"), "max_frames": 3},
    "sources.VideoSource.__iter__": {},
    "sources.camera_preset": {"name": "fr1"},
    "sources.import_rgbd_folder": {
        "src": Fixture("rgbd_pairs"),
        "out": _out("imported"),
        "intrinsics": (50.0, 50.0, 32.0, 24.0),
    },
    "sources.read_camera_json": {"path": Fixture("tum/camera.json")},
    "sources.write_tum_folder": {"path": _out("tum"), "frames": [FRAME]},
    # ------------------------------------------------------------------ pipelines
    "pipelines.PlaneHueModel": {"hue_tolerance": 10.0},
    "pipelines.PlaneMeasurer.measure": {"frame": FRAME},
    "pipelines.PlaneTracker.process": {"frame": FRAME},
    "pipelines.plane_errors": {
        "normal": np.array([0.0, 0.0, 1.0]),
        "d": 1.0,
        "true_normal": np.array([0.0, 0.1, 0.995]),
        "true_d": 1.1,
    },
    "pipelines.process_cloud": {"cloud": CLOUD, "voxel": 0.2, "sor": (5, 2.0)},
    "pipelines.run_mot": {
        "frames": [(1, IMG_RGB), (2, np.roll(IMG_RGB, 2, axis=1))],
        "min_area": 10,
    },
    "pipelines.summarize": {"results": "plane_results"},
    "pipelines.track_objects": {
        "frames": [(1, IMG_RGB), (2, np.roll(IMG_RGB, 2, axis=1))],
        "min_area": 10,
    },
    # ------------------------------------------------------------------ nn
    "nn.functional.avg_pool2d": {"x": IMG_F[None, None], "kernel_size": 2},
    "nn.functional.conv2d": {"x": IMG_F[None, None], "w": np.ones((2, 1, 3, 3)) / 9},
    "nn.functional.conv_output_size": {"size": 32, "kernel": 3},
    "nn.functional.conv_transpose2d": {
        "x": IMG_F[None, None, :8, :8],
        "w": np.ones((1, 2, 3, 3)) / 9,
    },
    "nn.functional.im2col": {"x": IMG_F[None, None, :16, :16], "kernel_size": 3},
    "nn.functional.max_pool2d": {"x": IMG_F[None, None], "kernel_size": 2},
    "nn.functional.sum_pool2d": {"x": IMG_F[None, None], "kernel_size": 2},
    "nn.functional.ConvSpec": {"in_channels": 3, "out_channels": 8, "kernel_size": 3},
    "nn.functional.parameter_count": {"spec": _b("robopercept.nn.functional:ConvSpec", 3, 8, 3)},
    "nn.functional.receptive_field": {"layers": [(3, 1, 1), (2, 2, 0), (3, 1, 1)]},
    "nn.core.blocks.Bottleneck": {"in_channels": 8, "width": 4},
    "nn.core.blocks.ConvBNAct": {"in_channels": 3, "out_channels": 4},
    "nn.core.blocks.InceptionBlock": {
        "in_channels": 4,
        "ch1x1": 2,
        "ch3x3red": 2,
        "ch3x3": 2,
        "ch5x5red": 2,
        "ch5x5": 2,
        "pool_proj": 2,
    },
    "nn.core.blocks.ResidualBlock": {"in_channels": 4, "out_channels": 4},
    "nn.core.blocks.VGGStage": {"in_channels": 3, "out_channels": 4},
    "nn.core.blocks.check_input": {
        "x": _b("tests.fuzz.api:torch_image", 1, 1, 8, 8),
        "in_channels": 1,
    },
    "nn.core.blocks.make_activation": {"act": "relu"},
    "nn.classification.models.Classifier": {
        "features": _b("robopercept.nn.core.blocks:ConvBNAct", 1, 4),
        "num_features": 4,
        "num_classes": 3,
        "in_channels": 1,
    },
    "nn.classification.models.build_model": {
        "name": "vgg_small",
        "widths": (4,),
        "convs_per_stage": 1,
    },
    "nn.classification.models.inception_small": {"stem_width": 8, "blocks": ((4, 4, 4, 2, 2, 2),)},
    "nn.classification.models.resnet_small": {"widths": (4, 8)},
    "nn.classification.models.vgg_small": {"widths": (4, 8)},
    "nn.core.summary.summary": {"model": TINY_NET, "input_shape": (1, 1, 16, 16)},
    "nn.data.datasets.ArrayDataset": {
        "images": np.random.default_rng(5).uniform(0, 1, (6, 8, 8)).astype(np.float32),
        "labels": np.arange(6) % 2,
        "classes": ("a", "b"),
    },
    "nn.data.augment.Compose": {
        "transforms": [_b("robopercept.nn.data.augment:RandomFlip", generator=0)]
    },
    "nn.data.datasets.ImageFolder": {"root": Fixture("images"), "size": (16, 16)},
    "nn.data.augment.Normalize": {"mean": [0.5], "std": [0.25]},
    "nn.data.augment.RandomCrop": {"size": 12, "padding": 2, "generator": 0},
    "nn.data.augment.RandomFlip": {"generator": 0},
    "nn.data.augment.RandomAffine": {"degrees": 10.0, "generator": 0},
    "nn.data.augment.ColorJitter": {"brightness": 0.2, "generator": 0},
    "nn.data.augment.GaussianNoise": {"generator": 0},
    "nn.data.datasets.normalization_stats": {
        "data": np.random.default_rng(5).uniform(0, 1, (6, 1, 8, 8))
    },
    "nn.data.datasets.shapes_dataset": {"n": 6, "size": 16, "rng": 0},
    "nn.data.datasets.stratified_split": {"labels": np.arange(30) % 3},
    "nn.data.datasets.to_unit_float": {"image": IMG},
    "nn.data.fonts.render_digits": {"n": 4},
    "nn.train.config.TrainConfig": {"epochs": 1, "batch_size": 4},
    "nn.train.fit.evaluate": {"model": TINY_NET, "data": ARRAY_DATA, "device": "cpu"},
    "nn.train.fit.fit": {"model": TINY_NET, "train": ARRAY_DATA, "config": TRAIN_CFG},
    "nn.train.checkpoint.load_checkpoint": {"path": Fixture("checkpoint.pt"), "model": TINY_NET},
    "nn.train.checkpoint.save_checkpoint": {
        "path": _out("checkpoint.pt"),
        "state": {"epoch": 1, "w": [1.0, 2.0]},
    },
    "nn.core.transfer.freeze": {"model": TINY_NET},
    "nn.core.transfer.keep_frozen_batchnorm_in_eval": {"model": TINY_NET},
    "nn.core.transfer.replace_head": {"model": TINY_NET, "num_classes": 5},
    "nn.core.transfer.trainable_parameter_names": {"model": TINY_NET},
    "nn.core.transfer.unfreeze": {"model": TINY_NET},
    "nn.core.export.export_onnx": {
        "model": TINY_NET,
        "path": _out("net.onnx"),
        "input_shape": (1, 16, 16),
    },
    "nn.ops.boxes.box_area": {"boxes": TBOXES},
    "nn.ops.boxes.check_boxes": {"boxes": TBOXES, "name": "boxes"},
    "nn.ops.boxes.box_convert": {"boxes": TBOXES, "in_fmt": "xyxy", "out_fmt": "cxcywh"},
    "nn.ops.boxes.box_iou": {"boxes1": TBOXES, "boxes2": TBOXES},
    "nn.ops.boxes.generalized_box_iou": {"boxes1": TBOXES, "boxes2": TBOXES},
    "nn.ops.boxes.dihedral_boxes": {
        "boxes": TBOXES,
        "size": (16, 24),
        "hflip": True,
        "quarter_turns": 1,
        "inverse": True,
    },
    "nn.ops.nms.nms": {"boxes": TBOXES, "scores": TSCORES, "iou_threshold": 0.5},
    "nn.ops.nms.batched_nms": {
        "boxes": TBOXES,
        "scores": TSCORES,
        "idxs": _b("tests.fuzz.api:torch_tensor", [0, 1, 0], "int64"),
        "iou_threshold": 0.5,
    },
    "nn.ops.nms.non_max_suppression": {"boxes": TBOXES, "scores": TSCORES, "top_k": 2},
    "nn.ops.roi.roi_align": {
        "input": _b("tests.fuzz.api:torch_image", 1, 2, 8, 8),
        "boxes": TROIS,
        "output_size": 2,
    },
    "nn.ops.roi.roi_pool": {
        "input": _b("tests.fuzz.api:torch_image", 1, 2, 8, 8),
        "boxes": TROIS,
        "output_size": 2,
    },
    "nn.ops.roi.RoIAlign": {"output_size": 2},
    "nn.ops.roi.RoIPool": {"output_size": 2},
    "nn.ops.anchors.BoxCoder.encode": {"reference_boxes": TBOXES, "proposals": TBOXES},
    "nn.ops.anchors.BoxCoder.decode": {"deltas": TBOXES, "boxes": TBOXES},
    "nn.ops.roi.RoIAlign.forward": {
        "input": _b("tests.fuzz.api:torch_image", 1, 2, 8, 8),
        "boxes": TROIS,
    },
    "nn.ops.roi.RoIPool.forward": {
        "input": _b("tests.fuzz.api:torch_image", 1, 2, 8, 8),
        "boxes": TROIS,
    },
    "nn.ops.anchors.AnchorGenerator.__call__": {
        "image_shape": (32, 32),
        "feature_shapes": [(4, 4)],
    },
    "nn.classification.run.evaluate_run": {
        "checkpoint": Fixture("run/checkpoint.pt"),
        "data": "digits",
        "device": "cpu",
    },
    "nn.classification.run.load_data": {"data": Fixture("images"), "size": (16, 16)},
    "nn.classification.saved.load_run": {
        "checkpoint": Fixture("run/checkpoint.pt"),
        "device": "cpu",
    },
    "nn.classification.run.predict": {
        "checkpoint": Fixture("run/checkpoint.pt"),
        "image_paths": [Fixture("image.png")],
        "device": "cpu",
    },
}

# Valid values that need the worker (callables, fitted estimators, results of a run):
# the table names them by a string that _SPECIAL turns into a Build.
_SPECIAL: dict[str, Any] = {
    "fitted:SVC": _b("tests.fuzz.api:fitted", "robopercept.learning:SVC"),
    "ekf_h": _b("tests.fuzz.api:picklable", "ekf_h"),
    "ekf_H": _b("tests.fuzz.api:picklable", "ekf_H"),
    "stereo_calibration": _b("tests.fuzz.api:stereo_calibration"),
    "plane_results": _b("tests.fuzz.api:plane_results"),
}


def fitted(target: str) -> Any:
    """An estimator of class ``target`` fitted on the three-blob data (valid model)."""
    return resolve(target)().fit(XB, YB)


def _ekf_h(x: np.ndarray) -> np.ndarray:
    return np.array([x[0] ** 2 / 10.0])


def _ekf_jac(x: np.ndarray) -> np.ndarray:
    return np.array([[x[0] / 5.0, 0.0]])


def picklable(name: str) -> Callable[..., Any]:
    """A module-level function by name (the EKF's measurement model and Jacobian)."""
    return {"ekf_h": _ekf_h, "ekf_H": _ekf_jac}[name]


def stereo_calibration() -> dict[str, Any]:
    """The dict :func:`robopercept.calibration.load_calibration` returns for a stereo
    rig of two K cameras 0.5 apart (the valid ``calibration`` of ``rectify_pair``)."""
    from robopercept.calibration import StereoCalibration, load_calibration, save_calibration

    path = IN_DIR / "stereo.json"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        result = StereoCalibration(
            K,
            np.zeros(5),
            K,
            np.zeros(5),
            np.eye(3),
            np.array([-0.5, 0.0, 0.0]),
            E_MAT,
            F_MAT,
            0.1,
            np.array([0.1]),
            (64, 48),
        )
        save_calibration(path, result)
    return load_calibration(path)


def plane_results() -> list[Any]:
    """Plane-tracking results of the 3 frames of the synthetic scene (``summarize``)."""
    from robopercept.pipelines import PlaneTracker

    tracker = PlaneTracker()
    return [tracker.process(frame) for frame in materialize(SCENE)]


#: methods fuzzed beyond constructors: class plan name -> methods; estimators (classes
#: with ``fit``) get theirs from :func:`_estimator_methods`
METHODS: dict[str, tuple[str, ...]] = {
    "imaging.VideoWriter": ("write",),
    "imaging.SnapshotVideoWriter": ("add",),
    "imaging.VideoReader": ("__iter__",),
    "geometry.CameraIntrinsics": ("scaled",),
    "nn.ops.anchors.BoxCoder": ("encode", "decode"),
    "nn.ops.anchors.AnchorGenerator": ("__call__", "base_anchors"),
    "nn.ops.roi.RoIAlign": ("forward",),
    "nn.ops.roi.RoIPool": ("forward",),
    "estimation.Plane": ("distance", "project"),
    "estimation.Line": ("distance",),
    "estimation.LineModel": ("fit",),
    "estimation.PlaneModel": ("fit",),
    "estimation.HomographyModel": ("fit",),
    "estimation.AffineModel": ("fit",),
    "learning.KFold": ("split",),
    "learning.StratifiedKFold": ("split",),
    "motion.AveragedBackground": ("apply",),
    "motion.FrameDifference": ("apply",),
    "motion.GaussianBackground": ("apply",),
    "motion.StaticBackground": ("apply",),
    "motion.ThreeFrameDifference": ("apply",),
    "motion.KLTTracker": ("update",),
    "depth.ActiveStereoSensor": ("disparity", "depth_rms_error"),
    "depth.ColorRangeSelector": ("__call__",),
    "pointcloud.PointCloud": ("select", "with_colors"),
    "tracking.KalmanFilter": ("update", "predict"),
    "tracking.ExtendedKalmanFilter": ("update",),
    "tracking.IMMEstimator": ("update",),
    "tracking.GatedTrack": ("step",),
    "tracking.MeanShiftTracker": ("update",),
    "tracking.MultiObjectTracker": ("update",),
    "sources.SyntheticRGBDScene": ("frame", "__iter__"),
    "sources.TUMFolderSource": ("__iter__",),
    "sources.VideoSource": ("__iter__",),
    "pipelines.PlaneMeasurer": ("measure",),
    "pipelines.PlaneTracker": ("process",),
    "nn.data.augment.RandomFlip": ("__call__",),
    "nn.data.augment.RandomCrop": ("__call__",),
    "nn.data.augment.RandomAffine": ("__call__",),
    "nn.data.augment.ColorJitter": ("__call__",),
    "nn.data.augment.GaussianNoise": ("__call__",),
    "nn.data.augment.Normalize": ("__call__",),
}

#: the constructor arguments of a method's instance, where the constructor's own
#: valid values are not what the method needs
INIT: dict[str, dict[str, Any]] = {
    "tracking.KalmanFilter": {"dim_x": 2, "dim_z": 2, "x": np.zeros(2), "P": np.eye(2)},
    "tracking.GatedTrack": {"dim": 4},
    "learning.SVC": {"probability": True, "random_state": 0},  # predict_proba fuzzed too
}

#: calls made on the instance before the fuzzed method (valid warm-up)
PRE: dict[str, tuple[tuple[str, tuple[Any, ...]], ...]] = {
    "motion.FrameDifference.apply": (("apply", (IMG,)),),
    "motion.ThreeFrameDifference.apply": (("apply", (IMG,)), ("apply", (IMG2,))),
    "motion.KLTTracker.update": (("update", (IMG,)),),
    "tracking.MultiObjectTracker.update": (("update", (BOXES,)),),
    "tracking.IMMEstimator.update": (("predict", ()),),
    "tracking.ExtendedKalmanFilter.update": (("predict", ()),),
}

#: roles that the valid value does not reveal (a tensor where an image goes)
ROLES: dict[str, dict[str, str]] = {
    "nn.data.augment.RandomFlip.__call__": {"x": "image"},
    "nn.data.augment.RandomCrop.__call__": {"x": "image"},
    "nn.data.augment.RandomAffine.__call__": {"x": "image"},
    "nn.data.augment.ColorJitter.__call__": {"x": "image"},
    "nn.data.augment.GaussianNoise.__call__": {"x": "image"},
    "nn.data.augment.Normalize.__call__": {"x": "image"},
    "nn.core.blocks.check_input": {"x": "image"},
    "pipelines.PlaneMeasurer.measure": {"frame": "frame"},
    "pipelines.PlaneTracker.process": {"frame": "frame"},
    "sources.write_tum_folder": {"frames": "frames"},
}

#: work-size parameters: how many images, shapes or figures a data generator makes.
#: A count in the thousands is a valid request that takes minutes (the work asked for,
#: not a hang), so their hostile values keep every invalid kind but bring valid counts
#: down to :data:`~tests.fuzz.strategies.WORK_CAP` (role ``"work"``)
WORK_SIZES: dict[str, tuple[str, ...]] = {
    "nn.segmentation.data.segmentation_sets": ("n_images",),
    "nn.pose.data.procedural_pose_set": ("n_images",),
    "nn.pose.data.procedural_pose_scenes": ("n_images",),
    "nn.pose.data.pose_sets": ("images", "val_images", "test_images"),
    "nn.cloud.synthetic.procedural_shapes": ("n_per_class",),
    "nn.cloud.run.cloud_sets": ("shapes",),
    "nn.cloud.run.evaluate_run": ("shapes",),
    "nn.detection.synthetic.procedural_detection_set": ("n_images",),
    "nn.detection.synthetic.digits_detection_set": ("n_images",),
    "nn.detection.synthetic.single_digit_set": ("n_images",),
    "nn.detection.run.load_detection_data": ("images",),
    "nn.detection.run.evaluate_run": ("images",),
    "nn.segmentation.run.load_segmentation_data": ("images",),
    "nn.segmentation.run.evaluate_run": ("images",),
    "nn.pose.run.load_pose_data": ("images",),
    "nn.pose.run.evaluate_run": ("images",),
    # passes over the data: samples drawn per epoch, epochs of a small network
    "nn.segmentation.networks.train_segmenter": ("samples_per_epoch",),
    "nn.pose.lifting.train_lifter": ("epochs",),
}
for _name, _params in WORK_SIZES.items():
    ROLES.setdefault(_name, {}).update(dict.fromkeys(_params, "work"))

for _cls in (
    "RandomFlip",
    "RandomCrop",
    "RandomAffine",
    "ColorJitter",
    "GaussianNoise",
    "Normalize",
):
    VALID.setdefault(f"nn.data.augment.{_cls}.__call__", {"x": TORCH_IMG})
VALID["nn.data.augment.Normalize"] = {"mean": [0.5], "std": [0.25]}


# nn.coco (issue 26): a one-image COCO set, its results, a VOC file, an evaluation
_COCO_GT = {
    "images": [{"id": 1, "file_name": "a.png", "width": 64, "height": 48}],
    "categories": [{"id": 1, "name": "a"}, {"id": 2, "name": "b"}],
    "annotations": [
        {"id": 1, "image_id": 1, "category_id": 1, "bbox": [2.0, 3.0, 20.0, 10.0]},
        {"id": 2, "image_id": 1, "category_id": 2, "bbox": [30.0, 5.0, 8.0, 8.0], "iscrowd": 0},
    ],
}
_COCO_RES = [
    {"image_id": 1, "category_id": 1, "bbox": [2.0, 4.0, 20.0, 10.0], "score": 0.9},
    {"image_id": 1, "category_id": 2, "bbox": [0.0, 0.0, 5.0, 5.0], "score": 0.4},
]
_VOC_XML = (
    "<annotation><filename>a.png</filename><size><width>64</width><height>48</height>"
    "<depth>3</depth></size><object><name>tree</name><difficult>0</difficult><bndbox>"
    "<xmin>2</xmin><ymin>3</ymin><xmax>22</xmax><ymax>13</ymax></bndbox></object>"
    "</annotation>"
)


def coco_value(kind: str) -> Any:
    """A valid nn.coco value: ``gt`` (CocoDataset), ``results`` (CocoResults),
    ``evaluation`` (CocoEvaluation) or ``voc`` (a list of one VocAnnotation)."""
    from robopercept.nn.coco import dataset, evaluate, results, voc

    gt = dataset.coco_from_dict(_COCO_GT)
    res = results.results_from_list(_COCO_RES)
    if kind == "voc":
        obj = voc.VocObject("tree", (2.0, 3.0, 22.0, 13.0))
        return [voc.VocAnnotation("a.png", 64, 48, 3, (obj,))]
    return {"gt": gt, "results": res, "evaluation": evaluate.evaluate_detections(gt, res)}[kind]


FIXTURES.update(
    {
        "coco.json": lambda p: p.write_text(json.dumps(_COCO_GT)),
        "coco_results.json": lambda p: p.write_text(json.dumps(_COCO_RES)),
        "voc.xml": lambda p: p.write_text(_VOC_XML),
    }
)
_CGT = _b("tests.fuzz.api:coco_value", "gt")
_CRES = _b("tests.fuzz.api:coco_value", "results")
_CEV = _b("tests.fuzz.api:coco_value", "evaluation")
VALID.update(
    {
        "nn.coco.dataset.coco_from_dict": {"data": _COCO_GT},
        "nn.coco.dataset.read_coco_json": {"path": Fixture("coco.json")},
        "nn.coco.dataset.coco_to_dict": {"dataset": _CGT},
        "nn.coco.dataset.write_coco_json": {"dataset": _CGT, "path": _out("gt.json")},
        "nn.coco.dataset.as_coco_dataset": {"gt": _COCO_GT},
        "nn.coco.results.results_from_list": {"results": _COCO_RES},
        "nn.coco.results.read_coco_results": {"path": Fixture("coco_results.json")},
        "nn.coco.results.results_to_list": {"results": _CRES},
        "nn.coco.results.write_coco_results": {"results": _CRES, "path": _out("results.json")},
        "nn.coco.results.results_from_ground_truth": {"dataset": _CGT},
        "nn.coco.results.as_coco_results": {"results": _COCO_RES, "gt": _CGT},
        "nn.coco.voc.read_voc_xml": {"path": Fixture("voc.xml")},
        "nn.coco.voc.voc_to_coco": {"annotations": _b("tests.fuzz.api:coco_value", "voc")},
        "nn.coco.evaluate.evaluate_detections": {
            "gt": _CGT,
            "results": _COCO_RES,
            "max_dets": (1, 10, 100),
        },
        "nn.coco.voc.evaluate_voc": {"gt": _CGT, "results": _CRES},
        "nn.coco.voc.voc_average_precision": {
            "recall": np.array([0.5, 0.5, 1.0]),
            "precision": np.array([1.0, 0.5, 2 / 3]),
        },
        "nn.coco.evaluate.pr_curves_picture": {"evaluation": _CEV, "width": 200, "height": 150},
        "nn.coco.evaluate.write_pr_curves": {"evaluation": _CEV, "path": _out("pr.png")},
    }
)

# nn.coco keypoints and nn.pose.metrics (issue 28): two persons of 3 keypoints, a detection
_KP_GT = np.array([[[10.0, 10.0, 2.0], [20.0, 12.0, 2.0], [15.0, 30.0, 1.0]], np.zeros((3, 3))])
_KP_DT = np.array([[[11.0, 10.0], [19.0, 13.0], [15.0, 28.0]]])
_I2 = np.array([1, 2], dtype=np.int64)
VALID.update(
    {
        "nn.coco.evaluate.keypoint_oks": {
            "dt_keypoints": _KP_DT,
            "gt_keypoints": _KP_GT,
            "gt_area": np.array([200.0, 50.0]),
            "gt_box": np.array([[8.0, 8.0, 14.0, 24.0], [40.0, 5.0, 5.0, 10.0]]),
            "sigmas": np.array([0.05, 0.07, 0.09]),
        },
        "nn.coco.dataset.CocoDataset": {
            "images": (),
            "categories": (),
            "ann_ids": _I2,
            "image_ids": _I2,
            "category_ids": _I2,
            "boxes": np.array([[8.0, 8.0, 14.0, 24.0], [40.0, 5.0, 5.0, 10.0]]),
            "areas": np.array([200.0, 50.0]),
            "iscrowd": np.zeros(2, dtype=bool),
            "keypoints": _KP_GT,
            "num_keypoints": np.array([3, 0]),
        },
        "nn.coco.results.CocoResults": {
            "image_ids": _I2[:1],
            "category_ids": _I2[:1],
            "boxes": np.array([[11.0, 10.0, 8.0, 18.0]]),
            "scores": np.array([0.9]),
            "keypoints": np.concatenate([_KP_DT, np.ones((1, 3, 1))], axis=2),
        },
        "nn.pose.metrics.pck": {
            "pred": _KP_GT[:, :, :2] + 1.0,
            "truth": _KP_GT,
            "visible": None,
            "threshold": 0.2,
            "normalizer": np.array([28.0, 11.0]),
        },
        "nn.pose.metrics.pckh": {
            "pred": _KP_GT[:, :, :2] + 1.0,
            "truth": _KP_GT,
            "visible": np.ones((2, 3), dtype=bool),
            "head_sizes": np.array([6.0, 4.0]),
        },
        "nn.pose.metrics.bbox_diagonal": {"boxes": np.array([[8.0, 8.0, 14.0, 24.0]])},
        "nn.pose.metrics.mpii_head_sizes": {"head_boxes": np.array([[8.0, 8.0, 22.0, 32.0]])},
    }
)


# nn.coco.rle (issue 27): the compressed RLE of a 4 x 3 mask
_RLE = {"size": [4, 3], "counts": "12114"}  # runs 1, 2, 1, 3, 5
VALID.update(
    {
        "nn.coco.rle.rle_encode": {"mask": np.eye(4, 3, dtype=np.uint8)},
        "nn.coco.rle.rle_decode": {"rle": _RLE},
        "nn.coco.rle.rle_counts": {"rle": _RLE},
        "nn.coco.rle.rle_from_counts": {"counts": [1, 2, 1, 3, 5], "size": (4, 3)},
        "nn.coco.rle.rle_area": {"rle": _RLE},
        "nn.coco.rle.rle_to_bbox": {"rle": _RLE},
        "nn.coco.rle.rle_iou": {"dt": [_RLE], "gt": [_RLE, _RLE], "iscrowd": [0, 1]},
        "nn.coco.rle.rle_merge": {"rles": [_RLE, _RLE]},
        "nn.coco.rle.polygon_to_rle": {
            "polygon": [0.5, 0.5, 2.5, 0.5, 1.5, 3.5],
            "height": 4,
            "width": 3,
        },
        "nn.coco.rle.annotation_to_rle": {
            "segmentation": [[0.5, 0.5, 2.5, 0.5, 1.5, 3.5]],
            "height": 4,
            "width": 3,
        },
    }
)


# nn.segmentation.metrics (issue 27): two 3 x 4 label maps of 3 classes
_SEG_T = np.array([[0, 0, 1, 1], [0, 2, 2, 1], [0, 2, 2, 1]])
_SEG_P = np.array([[0, 1, 1, 1], [0, 2, 2, 2], [0, 0, 2, 1]])
VALID.update(
    {
        "nn.segmentation.metrics.segmentation_confusion": {
            "y_true": _SEG_T,
            "y_pred": _SEG_P,
            "num_classes": 3,
        },
        "nn.segmentation.metrics.segmentation_scores": {"confusion": [[3, 1], [0, 4]]},
        "nn.segmentation.metrics.boundary_f_score": {
            "y_true": _SEG_T,
            "y_pred": _SEG_P,
            "num_classes": 3,
        },
        "nn.segmentation.metrics.match_instances": {
            "true_labels": _SEG_T,
            "pred_labels": _SEG_P,
            "iou_threshold": 0.5,
        },
    }
)


# nn.segmentation.networks (issue 27): tiny networks, logits and labels of two 8 x 8 images
_SLOGITS = _b("tests.fuzz.api:torch_image", 2, 3, 8, 8)
_SLABELS = _b("tests.fuzz.api:torch_tensor", np.tile([[0, 1, 2, 1]], (2, 8, 2)), "int64")
VALID.update(
    {
        "nn.segmentation.networks.NaiveFCN": {"num_classes": 3, "width": 4, "depth": 2},
        "nn.segmentation.networks.FCN": {"num_classes": 3, "width": 4},
        "nn.segmentation.networks.UNet": {"num_classes": 3, "width": 4, "depth": 2},
        "nn.segmentation.networks.NaiveFCN.forward": {
            "x": _b("tests.fuzz.api:torch_image", 1, 3, 8, 8)
        },
        "nn.segmentation.networks.FCN.forward": {"x": _b("tests.fuzz.api:torch_image", 2, 3, 8, 8)},
        "nn.segmentation.networks.UNet.forward": {
            "x": _b("tests.fuzz.api:torch_image", 1, 3, 8, 8)
        },
        "nn.segmentation.networks.bilinear_kernel": {"channels": 2, "factor": 2},
        "nn.segmentation.networks.build_segmenter": {"name": "unet", "num_classes": 2, "width": 4},
        "nn.segmentation.networks.segmentation_cross_entropy": {
            "logits": _SLOGITS,
            "target": _SLABELS,
        },
        "nn.segmentation.networks.dice_loss": {"logits": _SLOGITS, "target": _SLABELS},
    }
)
for _cls in ("NaiveFCN", "FCN", "UNet"):
    METHODS[f"nn.segmentation.networks.{_cls}"] = ("forward",)
_SEG_X = np.tile(np.linspace(0, 1, 8, dtype=np.float32)[None, :, None, None], (2, 1, 8, 1))
_SEG_Y = (_SEG_X[..., 0] > 0.5).astype(np.int64)
_SEG_NET = _b("robopercept.nn.segmentation.networks:UNet", 2, 1, 4, 2)
VALID.update(
    {
        "nn.segmentation.networks.train_segmenter": {
            "model": _SEG_NET,
            "images": _SEG_X,
            "masks": _SEG_Y,
            "config": TRAIN_CFG,
            "progress": False,
        },
        "nn.segmentation.networks.predict_segmentation": {"model": _SEG_NET, "images": _SEG_X},
        "nn.train.loop.optimizer_step": {
            "loss": _b("tests.fuzz.api:step_value", "loss"),
            "opt": _b("tests.fuzz.api:step_value", "opt"),
            "sched": _b("tests.fuzz.api:step_value", "sched"),
            "params": _b("tests.fuzz.api:step_value", "params"),
            "cfg": TRAIN_CFG,
            "where": "epoch 1",
        },
        "nn.train.loop.step_optimizer": {
            "params": _b("tests.fuzz.api:parameters_of", TINY_NET),
            "cfg": TRAIN_CFG,
            "steps_per_epoch": 2,
        },
    }
)


def parameters_of(model: Any) -> list[Any]:
    """The parameters of a built model, as a list (step_optimizer's input)."""
    return list(model.parameters())


def step_value(kind: str) -> Any:
    """A valid nn.train.loop.optimizer_step argument: ``loss`` (a scalar with a graph),
    ``params`` (one parameter), ``opt`` and ``sched`` (SGD on it, a constant schedule)."""
    import torch

    w = torch.nn.Parameter(torch.ones(2))
    opt = torch.optim.SGD([w], lr=0.1)
    values = {
        "loss": (w * w).sum(),
        "params": [w],
        "opt": opt,
        "sched": torch.optim.lr_scheduler.LambdaLR(opt, lambda _: 1.0),
    }
    return values[kind]


# nn.segmentation.data (issue 27): a nuclei folder of two 16 x 16 TIFFs
def _write_nuclei(path: Path) -> None:
    """img2d.tif (a ramp) and mask2d.tif (four labelled squares), 16 x 16 uint16."""
    from robopercept.imaging import write_image

    path.mkdir(parents=True, exist_ok=True)
    write_image(path / "img2d.tif", np.arange(256, dtype=np.uint16).reshape(16, 16))
    labels = np.zeros((16, 16), np.uint16)
    for k, (y, x) in enumerate(((2, 2), (2, 10), (10, 2), (10, 10)), 1):
        labels[y : y + 4, x : x + 4] = k
    write_image(path / "mask2d.tif", labels)


FIXTURES["nuclei"] = _write_nuclei
VALID.update(
    {
        "nn.segmentation.data.nuclei_quadrants": {"folder": Fixture("nuclei")},
        "nn.segmentation.data.percentile_normalize": {"image": IMG_F},
    }
)


# nn.detection.data, .synthetic, .deepforest (issue 26): a small detection set, a batch
# of it, a DeepForest folder
def detection_value(kind: str) -> Any:
    """A valid nn.detection.data value: ``dataset`` (DetectionDataset) or ``batch``
    (two items of it)."""
    from robopercept.nn.detection.data import DetectionDataset

    ds = DetectionDataset(
        [np.full((16, 16, 3), 0.5, np.float32)] * 2,
        [[[1.0, 2.0, 9.0, 12.0]], np.zeros((0, 4))],
        [[1], []],
        ["a"],
    )
    if kind == "one_box":
        return ds.subset([0])
    if kind == "target":
        return {"boxes": torch_tensor([[1.0, 2.0, 9.0, 12.0]])}
    if kind == "masks":
        first = np.zeros((1, 16, 16), bool)
        first[0, 2:12, 1:9] = True
        return [first, np.ones((1, 16, 16), bool)]
    return {"dataset": ds, "batch": [ds[0], ds[1]]}[kind]


def _write_deepforest(path: Path) -> None:
    """The four DeepForest file pairs as 80 x 72 images with one box each."""
    from robopercept.imaging import write_image
    from robopercept.nn.detection.deepforest import DEEPFOREST_IMAGES

    path.mkdir(parents=True, exist_ok=True)
    for stem in DEEPFOREST_IMAGES:
        write_image(path / f"{stem}.png", np.full((72, 80, 3), 90, np.uint8))
        (path / f"{stem}.xml").write_text(
            _VOC_XML.replace(
                "<width>64</width><height>48</height>", "<width>80</width><height>72</height>"
            )
        )


FIXTURES["deepforest"] = _write_deepforest


def _write_coco_folder(path: Path) -> None:
    """A COCO file (:data:`_COCO_GT`, classes ``a`` and ``b``) with its image beside it."""
    from robopercept.imaging import write_image

    path.parent.mkdir(parents=True, exist_ok=True)
    write_image(path.parent / "a.png", np.full((48, 64, 3), 90, np.uint8))
    path.write_text(json.dumps(_COCO_GT))


FIXTURES["coco_images/gt.json"] = _write_coco_folder
_DDS = _b("tests.fuzz.api:detection_value", "dataset")
VALID.update(
    {
        "nn.data.datasets.shape_masks": {
            "kinds": [0, 1, 2, 3],
            "cx": [8.0] * 4,
            "cy": [8.0] * 4,
            "r": [5.0] * 4,
            "phi": [0.3] * 4,
            "size": (16, 16),
        },
        "nn.detection.data.mask_to_box": {"mask": np.eye(5, dtype=bool)},
        "nn.detection.data.DetectionDataset": {
            "images": [np.full((16, 16, 3), 0.5, np.float32)] * 2,
            "boxes": [[[1.0, 2.0, 9.0, 12.0]], [[0.0, 0.0, 16.0, 16.0]]],
            "labels": [[1], [1]],
            "classes": ["a"],
            "masks": _b("tests.fuzz.api:detection_value", "masks"),
        },
        "nn.detection.data.DetectionDataset.from_instance_labels": {
            "images": [np.full((6, 8), 0.5)],
            "instances": [np.repeat([[0, 0, 3, 3, 0, 7, 7, 0]], 6, axis=0)],
            "class_name": "cell",
        },
        "nn.detection.data.DetectionDataset.subset": {"indices": [1, 0]},
        "nn.detection.data.DetectionDataset.split": {"fractions": (0.5, 0.5), "rng": 0},
        "nn.detection.data.DetectionDataset.areas": {"index": 0},
        "nn.detection.data.DetectionDataset.class_map": {"index": 0},
        "nn.detection.data.DetectionDataset.__getitem__": {"index": 0},
        "nn.detection.data.collate_detection": {
            "batch": _b("tests.fuzz.api:detection_value", "batch")
        },
        "nn.detection.synthetic.procedural_detection_set": {
            "n_images": 2,
            "size": (32, 32),
            "rng": 0,
        },
        "nn.detection.synthetic.digits_detection_set": {
            "n_images": 2,
            "size": (32, 32),
            "rng": 0,
            "scale": (8, 16),
        },
        "nn.detection.synthetic.single_digit_set": {
            "n_images": 2,
            "size": (32, 32),
            "rng": 0,
            "scale": (8, 16),
        },
        "nn.detection.deepforest.deepforest_tiles": {"folder": Fixture("deepforest"), "tile": 64},
        "viz.draw_detections": {
            "image": IMG_RGB,
            "boxes": [[1.0, 2.0, 9.0, 12.0]],
            "labels": [1],
            "classes": ["a"],
        },
        "nn.detection.data.samples_picture": {"dataset": _DDS},
        "nn.detection.data.check_classes": {"classes": ["a", "b"]},
        "viz.detections_grid": {
            "images": [IMG_RGB, IMG],
            "boxes": [[[1.0, 2.0, 9.0, 12.0]], np.zeros((0, 4))],
            "labels": [[1], []],
            "classes": ["a"],
        },
        "nn.detection.deepforest.DeepForestTiles": {"train": _DDS, "test": _DDS},
        "nn.detection.data.DetectionDataset.from_coco": {"path": Fixture("coco_images/gt.json")},
        "nn.detection.run.load_detection_data": {"data": "shapes", "images": 4, "size": (32, 32)},
        "nn.detection.run.evaluate_run": {
            "model": Fixture("detector.pt"),
            "data": Fixture("coco_images/gt.json"),
            "device": "cpu",
        },
    }
)
METHODS["nn.detection.data.DetectionDataset"] = (
    "subset",
    "split",
    "areas",
    "to_coco",
    "__getitem__",
    "class_maps",
    "class_map",
    "from_instance_labels",
    "from_coco",
)

#: callables not fuzzed, with the reason
SKIP: dict[str, str] = {
    "imaging.sample_image_path": "takes no argument (returns the path of a bundled image)",
    "learning.DataConversionWarning": "a warning category, not a callable of the API",
    "estimation.Model": "a typing Protocol (its implementations are fuzzed)",
    "geometry.EssentialModel": "takes no argument; fitted through find_essential",
    "geometry.FundamentalModel": "takes no argument; fitted through find_fundamental",
    "nn.classification.run.train_run": "trains a network (tens of seconds per call); its parts "
    "are fuzzed: load_data, TrainConfig, fit, evaluate",
    "nn.cloud.run.train_run": "trains a network and writes a run folder (seconds per call); its "
    "parts are fuzzed: cloud_sets, build_cloud_model, train_cloud_model, evaluate_cloud_model, "
    "save_cloud_model",
    "nn.detection.run.train_run": "trains a detector (seconds per call); its parts are "
    "fuzzed: load_detection_data, build_detector, train_detector, evaluate_run",
    "nn.data.datasets.load_digits": "takes only a transform; loads a bundled data set "
    "(the datasets are fuzzed through shapes_dataset and ArrayDataset)",
    "nn.data.datasets.load_lfw_subset": "downloads (network) on first use",
    "pipelines.PlaneTracker.run": "iterates process() over a source: fuzzed as process",
}

#: name -> valid value for required parameters missing from :data:`VALID`
BY_NAME: dict[str, Any] = {
    "image": IMG,
    "img": IMG,
    "gray": IMG,
    "frame": IMG,
    "mask": MASK,
    "points": PTS3,
    "cloud": CLOUD,
    "X": XB,
    "y": YB,
    "intrinsics": CAM,
}


def skip_reason(obj: Any) -> str | None:
    """Why a public name is not fuzzed by rule, or None.

    Parameters
    ----------
    obj : object
        A name of a package's ``__all__``.

    Returns
    -------
    str or None
        Not callable (a constant, a module); an enumeration; an exception class; a
        result record (a frozen dataclass without ``__post_init__``: the library builds
        it, its constructor checks nothing by design).
    """
    if not callable(obj):
        return "not callable (a constant)"
    if inspect.isclass(obj):
        if issubclass(obj, enum.Enum):
            return "an enumeration"
        if issubclass(obj, BaseException):
            return "an exception class"
        if dataclasses.is_dataclass(obj) and not hasattr(obj, "__post_init__"):
            return (
                "result record (a dataclass without a validating constructor, built by the library)"
            )
    return None


# =========================================================================== plans


@dataclass(frozen=True)
class Plan:
    """How to call one public callable validly, and which parameters to attack.

    Parameters
    ----------
    name : str
        ``"imaging.gaussian_blur"``, ``"learning.KMeans"`` (the constructor) or
        ``"learning.KMeans.fit"`` (a method).
    package : str
        The package (``"nn"`` for every ``nn`` module).
    target : str
        ``"module:qualname"`` of the function or class.
    method : str
        The method's name, ``""`` for a function or a constructor.
    init : tuple of (str, value)
        Constructor arguments of the instance (methods only).
    pre : tuple of (method, args)
        Valid calls on the instance before the fuzzed one.
    args : tuple
        Positional arguments (varargs, positional-only).
    kwargs : tuple of (str, value)
        Keyword arguments.
    roles : tuple of (str, str)
        The fuzzed parameters (``"*0"`` for the first positional one) and their roles.
    """

    name: str
    package: str
    target: str
    method: str = ""
    init: tuple[tuple[str, Any], ...] = ()
    pre: tuple[tuple[str, tuple[Any, ...]], ...] = ()
    args: tuple[Any, ...] = ()
    kwargs: tuple[tuple[str, Any], ...] = ()
    roles: tuple[tuple[str, str], ...] = ()

    def value(self, param: str) -> Any:
        """The valid value of ``param`` (``"*0"`` for positional argument 0)."""
        if param.startswith("*"):
            return self.args[int(param[1:])]
        return dict(self.kwargs)[param]


def _ann_text(annotation: Any) -> str:
    return (
        annotation
        if isinstance(annotation, str)
        else getattr(annotation, "__name__", str(annotation))
    )


def role_of(name: str, value: Any, annotation: Any = None) -> str:
    """The role of a parameter: which hostile strategy attacks it.

    Parameters
    ----------
    name : str
        The parameter's name.
    value : object
        Its valid value.
    annotation : object, optional
        Its annotation (consulted when the valid value is None).

    Returns
    -------
    str
        ``"image"`` (2-D or 3-D arrays at least 8x8), ``"points"`` (``(N, 2..4)``
        arrays, N >= 5), ``"array"`` (other arrays: matrices, vectors), ``"scalar"``,
        ``"work"`` (a work-size count, set by :data:`WORK_SIZES`), ``"flag"``,
        ``"choice"`` (a string), ``"tuple"`` (up to 4 numbers), ``"sequence"``,
        ``"path"``, ``"cloud"``, ``"tensor"`` (a torch tensor), ``"tensors"`` (a list of
        them), ``"mesh"``, ``"object"``, or ``"fixed"`` (callables: not attacked).
    """
    if isinstance(value, Fixture):
        return "path"
    if isinstance(value, Build):
        if value.target in _TENSOR_TARGETS:
            return "tensor"
        if value.target == "tests.fuzz.api:detector_value" and value.args == ("images",):
            return "tensors"
        if value.target.endswith(":TriangleMesh"):
            return "mesh"
        return "cloud" if value.target.endswith(":PointCloud") else "object"
    if (
        isinstance(value, list)
        and value
        and all(isinstance(v, Build) and v.target in _TENSOR_TARGETS for v in value)
    ):
        return "tensors"
    if isinstance(value, str) and (
        value.startswith(str(WORKDIR)) or name in ("path", "out", "out_dir")
    ):
        return "path"
    if isinstance(value, Layout):
        value = value.array
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufc":
            return "array"
        if value.ndim == 2 and 2 <= value.shape[1] <= 4 and value.shape[0] >= 5:
            return "points"
        if value.ndim in (2, 3) and value.shape[0] >= 8 and value.shape[1] >= 8:
            return "image"
        return "array"
    if isinstance(value, (bool, np.bool_)):
        return "flag"
    if isinstance(value, (int, float, np.integer, np.floating)):
        return "scalar"
    if isinstance(value, str):
        return "choice"
    if isinstance(value, (tuple, list)):
        if 0 < len(value) <= 4 and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            for v in value
        ):
            return "tuple"
        return "sequence"
    if value is None:
        text = _ann_text(annotation)
        if "Callable" in text:
            return "fixed"
        if "ndarray" in text or "ArrayLike" in text:
            return "array"
        if "tuple" in text:
            return "tuple"
        if "float" in text or "int" in text or "Generator" in text:
            return "scalar"
        if "str" in text:
            return "choice"
        return "object"
    if callable(value):
        return "fixed"
    return "object"


def strategy_for(role: str, like: Any) -> st.SearchStrategy[Any]:
    """The hostile strategy of a role, seeded with the parameter's valid value.

    Parameters
    ----------
    role : str
        From :func:`role_of`.
    like : object
        The valid value.

    Returns
    -------
    SearchStrategy
    """
    if isinstance(like, Layout):
        like = like.array
    if role == "image":
        return hs.hostile_images(like=like if isinstance(like, np.ndarray) else None)
    if role == "points":
        return hs.hostile_points(like=like)
    if role == "array":
        return hs.hostile_arrays(like=like)
    if role == "scalar":
        return hs.hostile_scalars(like=like)
    if role == "work":
        return hs.hostile_work_sizes(like=like)
    if role == "flag":
        return hs.hostile_flags(like)
    if role == "choice":
        return hs.hostile_choices(like)
    if role == "tuple":
        return hs.hostile_tuples(like=like)
    if role == "sequence":
        return hs.hostile_sequences(like=like)
    if role == "path":
        if isinstance(like, Fixture):
            return hs.hostile_paths(str(IN_DIR), like=like.name)
        # an output: hostile names in the output folder, so that no write can replace
        # the empty and garbage inputs that the readers are given
        return hs.hostile_paths(str(OUT_DIR), like=like)
    if role == "cloud":
        return hs.hostile_clouds(like=like)
    if role == "tensor":
        values, dtype = tensor_like(like)
        return hs.hostile_tensors(like=values, dtype=dtype)
    if role == "tensors":
        items = _tensor_items(like)
        values, dtype = tensor_like(items[0])
        return hs.hostile_sequences(like=items, item=hs.hostile_tensors(like=values, dtype=dtype))
    if role == "mesh":
        v, f = (*like.args, None, None)[:2] if isinstance(like, Build) else (None, None)
        return hs.hostile_meshes(
            vertices=v.array if isinstance(v, Layout) else v,
            faces=f.array if isinstance(f, Layout) else f,
        )
    if role == "frame":
        return st.one_of(hs.hostile_objects(), st.builds(_hostile_frame, hs.hostile_images()))
    if role == "frames":
        return st.one_of(
            hs.hostile_sequences(like=None),
            st.builds(lambda f: [f], st.builds(_hostile_frame, hs.hostile_images())),
        )
    return hs.hostile_objects(like)


#: the recipes of valid tensors (their role is ``"tensor"``)
_TENSOR_TARGETS = frozenset({"tests.fuzz.api:torch_tensor", "tests.fuzz.api:torch_image"})


def tensor_like(value: Any) -> tuple[np.ndarray, str]:
    """The values (float64) and dtype of a valid tensor recipe, made without torch.

    Parameters
    ----------
    value : Build
        A :func:`torch_tensor` or :func:`torch_image` recipe.

    Returns
    -------
    values : numpy.ndarray
    dtype : str
    """
    if isinstance(value, Build) and value.target == "tests.fuzz.api:torch_tensor":
        dtype = value.args[1] if len(value.args) > 1 else "float32"
        return np.asarray(value.args[0], np.float64), str(dtype)
    if isinstance(value, Build) and value.target == "tests.fuzz.api:torch_image":
        shape = tuple(int(n) for n in value.args)
        return np.random.default_rng(0).uniform(0, 1, shape), "float32"
    return np.array([[0.0, 0, 4, 4], [1, 1, 5, 6], [2, 0, 7, 3]]), "float32"


def _tensor_items(value: Any) -> list[Any]:
    """The items of a valid list of tensors (a list of recipes, or the detectors' two
    images)."""
    if isinstance(value, list):
        return value
    return [
        _b("tests.fuzz.api:torch_image", 3, 16, 16),
        _b("tests.fuzz.api:torch_image", 3, 16, 24),
    ]


def _hostile_frame(image: Any) -> Build:
    """A frame of the synthetic scene whose depth map is replaced by a hostile image
    (made with :func:`dataclasses.replace`, so the frame's own checks run)."""
    return _b("tests.fuzz.api:replace_frame", image)


def replace_frame(depth: Any) -> Any:
    """Frame 0 of the synthetic scene with ``depth`` as its depth map."""
    return dataclasses.replace(scene_frame(0), depth=depth)


def _qual(obj: Any) -> str:
    return f"{obj.__module__}:{obj.__qualname__}"


def _walk() -> Iterator[tuple[str, str, Any]]:
    """(package, plan-name prefix, object) for every name of every ``__all__``."""
    for pkg in PACKAGES:
        mod = importlib.import_module(f"robopercept.{pkg}")
        if pkg == "nn":
            for sub in mod.MODULES:
                submod = importlib.import_module(f"robopercept.nn.{sub}")
                for name in submod.__all__:
                    yield pkg, f"nn.{sub}.{name}", getattr(submod, name)
        else:
            for name in mod.__all__:
                yield pkg, f"{pkg}.{name}", getattr(mod, name)


def _resolve_special(value: Any) -> Any:
    if isinstance(value, str) and value in _SPECIAL:
        return _SPECIAL[value]
    if isinstance(value, list):
        return [_resolve_special(v) for v in value]
    return value


def _signature_plan(
    name: str,
    package: str,
    fn: Any,
    target: str,
    method: str = "",
    init: dict[str, Any] | None = None,
) -> Plan:
    """A plan from ``fn``'s signature, :data:`VALID`, :data:`BY_NAME` and the defaults."""
    table = {k: _resolve_special(v) for k, v in VALID.get(name, {}).items()}
    sig = inspect.signature(fn)
    hints: dict[str, Any] = {}
    args: list[Any] = list(table.pop("*", []))
    kwargs: dict[str, Any] = {}
    roles: list[tuple[str, str]] = []
    for i in range(len(args)):
        roles.append((f"*{i}", role_of(f"*{i}", args[i])))
    covered = len(args)  # leading positional parameters given by the table's "*"
    for pname, p in sig.parameters.items():
        if pname == "self" or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        if covered and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD):
            covered -= 1
            continue
        if pname in table:
            value = table.pop(pname)
        elif p.default is not inspect.Parameter.empty:
            value = p.default
        elif pname in BY_NAME:
            value = BY_NAME[pname]
        else:
            raise LookupError(
                f"{name}: no valid value for required parameter {pname!r}: add it to VALID"
            )
        if p.kind == p.POSITIONAL_ONLY:
            args.append(value)
            roles.append((f"*{len(args) - 1}", role_of(pname, value, p.annotation)))
            continue
        kwargs[pname] = value
        role = ROLES.get(name, {}).get(pname) or role_of(
            pname, value, hints.get(pname, p.annotation)
        )
        if pname in ("progress",):
            role = "fixed"  # a progress bar switch: not part of the computation
        roles.append((pname, role))
    if table:  # **kwargs of the callable (build_model's builder arguments)
        for pname, value in table.items():
            kwargs[pname] = value
            roles.append((pname, role_of(pname, value)))
    roles = [(p, r) for p, r in roles if r != "fixed"]
    pre = tuple((m, tuple(_resolve_special(a) for a in margs)) for m, margs in PRE.get(name, ()))
    return Plan(
        name=name,
        package=package,
        target=target,
        method=method,
        init=tuple((init or {}).items()),
        pre=pre,
        args=tuple(args),
        kwargs=tuple(kwargs.items()),
        roles=tuple(roles),
    )


_ESTIMATOR_METHODS = (
    "fit",
    "predict",
    "transform",
    "decision_function",
    "predict_proba",
    "inverse_transform",
    "score",
)


def _estimator_methods(cls: type) -> tuple[str, ...]:
    return tuple(m for m in _ESTIMATOR_METHODS if callable(getattr(cls, m, None)))


def _estimator_valid(
    name: str, cls: type, method: str
) -> tuple[dict[str, Any], tuple[tuple[str, tuple[Any, ...]], ...]]:
    """Valid X, y for an estimator's ``method`` and the ``fit`` call before it."""
    y = YR if "Regressor" in cls.__name__ else YB
    if method == "fit":
        return {"X": XB, "y": y}, ()
    if method == "inverse_transform":
        return {"X": XB[:, :2]}, (("fit", (XB, y)),)
    return {"X": XB}, (("fit", (XB, y)),)


def build_plans(
    packages: tuple[str, ...] | list[str] = PACKAGES,
) -> tuple[list[Plan], dict[str, str]]:
    """Every plan of the given packages, and the skipped callables with their reasons.

    Parameters
    ----------
    packages : sequence of str
        Package names of :data:`PACKAGES`.

    Returns
    -------
    plans : list of Plan
        Constructors, functions and methods, in ``__all__`` order.
    skipped : dict
        Plan name -> reason.

    Raises
    ------
    LookupError
        A required parameter has no valid value (a new public function: add it to
        :data:`VALID` or :data:`SKIP`).
    """
    _prepare_inputs()
    preload(packages)
    plans: list[Plan] = []
    skipped: dict[str, str] = {}
    seen: set[int] = set()
    for package, name, obj in _walk():
        if package not in packages:
            continue
        if name in SKIP:
            skipped[name] = SKIP[name]
            continue
        reason = skip_reason(obj)
        if reason is not None:
            skipped[name] = reason
            if name not in METHODS:  # a record's methods that take user data still run
                continue
        if id(obj) in seen and inspect.isclass(obj):
            skipped[name] = "the same class as another public name"
            continue
        seen.add(id(obj))
        target = _qual(obj)
        if reason is None:
            plans.append(_signature_plan(name, package, obj, target))
        if not inspect.isclass(obj):
            continue
        init = {k: _resolve_special(v) for k, v in VALID.get(name, {}).items()}
        init.update(INIT.get(name, {}))
        if package == "learning" and hasattr(obj, "fit"):
            for m in _estimator_methods(obj):
                mname = f"{name}.{m}"
                valid, pre = _estimator_valid(name, obj, m)
                VALID.setdefault(mname, valid)
                PRE.setdefault(mname, pre)
                plans.append(_signature_plan(mname, package, getattr(obj, m), target, m, init))
        for m in METHODS.get(name, ()):
            mname = f"{name}.{m}"
            if mname in SKIP:
                skipped[mname] = SKIP[mname]
                continue
            plans.append(_signature_plan(mname, package, getattr(obj, m), target, m, init))
    return plans, skipped


def preload(packages: tuple[str, ...] | list[str] = PACKAGES) -> None:
    """Import in this (the parent) process what the callables import lazily on first use.

    The sandbox's worker is a fork of this process, re-forked after every crash or
    hang, and it traces allocations: a first-time import there is paid again after
    each respawn, and traced (torch's optimizers pull in ``torch._dynamo`` and sympy,
    about 800 modules: 10 s traced against 0.4 s warm). Imports only: nothing runs a
    thread pool before the fork.

    Parameters
    ----------
    packages : sequence of str
    """
    if "nn" in packages:
        import torch._dynamo
        import torch.optim  # noqa: F401
    if "viz" in packages or "nn" in packages:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot


def _prepare_inputs() -> None:
    """Empty and garbage files of every extension the readers use, in :data:`IN_DIR`."""
    IN_DIR.mkdir(parents=True, exist_ok=True)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for suffix in (
        "",
        ".png",
        ".pcd",
        ".ply",
        ".mp4",
        ".txt",
        ".yaml",
        ".json",
        ".csv",
        ".pt",
        ".onnx",
    ):
        (IN_DIR / f"empty{suffix}").touch()
        garbage = IN_DIR / f"garbage{suffix}"
        if not garbage.exists():
            garbage.write_bytes(rng.integers(0, 256, 512, dtype=np.uint8).tobytes())


# =========================================================================== calling


def invoke(plan: Plan, param: str = "", value: Any = None) -> None:
    """Call ``plan``'s callable with ``param`` replaced by ``value`` (in the worker).

    The instance of a method is built first (with the plan's valid constructor
    arguments) and warmed up by the plan's ``pre`` calls; a returned iterator is run
    to at most 5 items, so lazy sources do their work. The result is dropped. The
    worker's current folder is the campaign's scratch folder (``WORKDIR/cwd``), so that
    a hostile empty or relative output path writes nothing into the project.

    Parameters
    ----------
    plan : Plan
    param : str
        The parameter made hostile (``""``: none, the valid call).
    value : object
        Its hostile value (:class:`~tests.fuzz.strategies.Layout` and
        :class:`~tests.fuzz.strategies.Build` values are made here).
    """
    # a relative or empty path ("" is the current folder) lands in the scratch folder,
    # never in the folder the campaign was started from
    cwd = WORKDIR / "cwd"
    cwd.mkdir(parents=True, exist_ok=True)
    os.chdir(cwd)
    args = list(plan.args)
    kwargs = dict(plan.kwargs)
    if param.startswith("*"):
        args[int(param[1:])] = value
    elif param:
        kwargs[param] = value
    fn = resolve(plan.target)
    if plan.method:
        obj = fn(**materialize(dict(plan.init)))
        for m, margs in plan.pre:
            _drain(getattr(obj, m)(*materialize(margs)))
        fn = getattr(obj, plan.method)
    _drain(fn(*materialize(args), **materialize(kwargs)))


def _drain(result: Any) -> None:
    if isinstance(result, Iterator):
        for i, _ in enumerate(result):
            if i >= 4:
                break


def draw_examples(plan: Plan, n: int, seed_: int) -> list[tuple[str, Any]]:
    """``n`` fuzz inputs for ``plan``: (parameter, hostile value), deterministic in ``seed_``.

    Hypothesis draws the parameter (uniformly among the plan's roles) and then its
    value from the role's strategy; generation only (no shrinking: nothing fails
    inside Hypothesis, outcomes are classified afterwards).

    Parameters
    ----------
    plan : Plan
    n : int
        Number of inputs.
    seed_ : int
        Hypothesis seed.

    Returns
    -------
    list of (str, object)
        Empty when the plan has no parameter to attack.
    """
    if not plan.roles or n <= 0:
        return []
    strat = st.sampled_from(plan.roles).flatmap(
        lambda pr: strategy_for(pr[1], plan.value(pr[0])).map(lambda v, p=pr[0]: (p, v))
    )
    out: list[tuple[str, Any]] = []

    @seed(seed_)
    @settings(
        max_examples=n,
        database=None,
        deadline=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
        derandomize=False,
    )
    @given(strat)
    def collect(example: tuple[str, Any]) -> None:
        out.append(example)

    collect()
    return out[:n]


@dataclass
class PlanRun:
    """The outcomes of one plan: the valid call's and the tally of the fuzz inputs."""

    plan: Plan
    baseline: Any
    tally: Tally
    examples: list[tuple[str, str, Any]] = field(default_factory=list)  # (param, value, outcome)


def run_plan(
    plan: Plan,
    sandbox: Any,
    n: int,
    seed_: int,
    *,
    baseline: bool = True,
    confirm_timeout: float | None = None,
    pinned: bool = True,
) -> PlanRun:
    """Run the valid call of ``plan``, its :data:`PINNED` inputs and ``n`` hostile
    inputs in ``sandbox``.

    A call over the sandbox's time limit is run once more with ``confirm_timeout``
    seconds (when given) and counted as a hang only if it runs over again: the first
    call of a numba kernel with a new dtype compiles it (seconds to tens of seconds on
    a loaded machine, then cached on disk), which is slow, not a hang.

    Parameters
    ----------
    plan : Plan
    sandbox : Sandbox
    n : int
        Hostile inputs.
    seed_ : int
        Hypothesis seed of :func:`draw_examples`.
    baseline : bool
        Also run the valid call (its outcome is :attr:`PlanRun.baseline`, not counted
        in the tally).
    confirm_timeout : float, optional
        The limit of the second try of a call that hung; None: no second try.
    pinned : bool
        Also run the plan's :data:`PINNED` inputs (before the drawn ones; counted).

    Returns
    -------
    PlanRun
    """
    base = _run(sandbox, functools.partial(invoke, plan), confirm_timeout) if baseline else None
    tally = Tally(plan.name, plan.package)
    run = PlanRun(plan, base, tally)
    examples = list(PINNED.get(plan.name, ())) if pinned else []
    for param, value in [*examples, *draw_examples(plan, n, seed_)]:
        text = describe(value)
        outcome = _run(sandbox, functools.partial(invoke, plan, param, value), confirm_timeout)
        tally.add(outcome, param, text)
        run.examples.append((param, text, outcome))
    return run


def _run(sandbox: Any, call: Any, confirm_timeout: float | None) -> Any:
    outcome = sandbox.run(call)
    if outcome.kind == "hang" and confirm_timeout:
        outcome = sandbox.run(call, timeout=confirm_timeout)
    return outcome


def _fixtures_in(value: Any) -> Iterator[Fixture]:
    if isinstance(value, Fixture):
        yield value
    elif isinstance(value, Build):
        for v in (*value.args, *(v for _, v in value.kwargs)):
            yield from _fixtures_in(v)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _fixtures_in(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _fixtures_in(v)


def make_fixtures(plans: list[Plan]) -> list[str]:
    """Make every fixture file the plans' valid calls read, here (in the parent), once.

    A fixture is otherwise made on first use in the worker, inside a timed call: the
    tiny training run behind ``run/checkpoint.pt`` takes a minute on a loaded machine
    under tracemalloc, over the time limit, and its plans were then reported as valid
    calls that hang. The sandbox's workers are forked from a clean fork server, so what
    this process imports (torch) does not reach them.

    Parameters
    ----------
    plans : list of Plan

    Returns
    -------
    list of str
        The fixtures' paths.
    """
    names = {}
    for plan in plans:
        for value in (plan.args, plan.kwargs, plan.init, plan.pre):
            for fx in _fixtures_in(value):
                names.setdefault(fx.name, fx)
    return [fx.make() for _, fx in sorted(names.items())]


def plan_seed(seed_: int, name: str, round_: int) -> int:
    """A seed per (campaign seed, plan, round), stable across runs and Python versions."""
    h = 2166136261
    for ch in f"{seed_}:{name}:{round_}".encode():
        h = ((h ^ ch) * 16777619) & 0xFFFFFFFF
    return h


def run_api_campaign(
    budget_s: float,
    seed_: int,
    sandbox: Any,
    *,
    packages: tuple[str, ...] | list[str] = PACKAGES,
    batch: int = 5,
    confirm_timeout: float | None = 60.0,
    log: Callable[[str], None] | None = None,
) -> tuple[list[Tally], dict[str, str], list[str]]:
    """Fuzz every plan round-robin until ``budget_s`` seconds have passed.

    The valid call of every plan runs first. Then each round gives every plan ``batch``
    new inputs (seeded by round; 2 in the first round, with the plan's :data:`PINNED`
    inputs), so that a short budget still touches every callable and a long one goes
    deeper everywhere.

    Parameters
    ----------
    budget_s : float
        Seconds (wall clock) for the whole campaign; a round in progress stops when it
        is spent.
    seed_ : int
        Campaign seed.
    sandbox : Sandbox
    packages : sequence of str
    batch : int
        Inputs per plan per round.
    confirm_timeout : float, optional
        The second try of a plan's first hang (see :func:`run_plan`), even when it runs
        the campaign past its budget (a hang at the end of the budget was once counted
        unconfirmed: a slow call on a loaded machine); later hangs of the same plan
        count at once.
    log : callable, optional
        Called with a progress line after each round.

    Returns
    -------
    tallies : list of Tally
        One per plan (valid calls not counted).
    skipped : dict
        Skipped callables and why.
    broken : list of str
        Plans whose *valid* call did not succeed (the table needs fixing, or the
        callable is broken for valid input), with the outcome.
    """
    start = time.monotonic()
    plans, skipped = build_plans(packages)
    make_fixtures(plans)
    start = time.monotonic()  # the budget is for the calls
    tallies = {p.name: Tally(p.name, p.package) for p in plans}
    broken: list[str] = []
    active = []
    for p in plans:
        base = _run(sandbox, functools.partial(invoke, p), confirm_timeout)
        if base.kind == "ok":
            active.append(p)
        else:
            broken.append(
                f"{p.name}: valid call gave {base.kind} {base.error}: {base.message[:160]}"
            )
        if time.monotonic() - start > budget_s:
            break
    round_ = 0
    while time.monotonic() - start < budget_s and active:
        for p in active:
            if time.monotonic() - start >= budget_s:
                break
            first = tallies[p.name].hangs == 0
            confirm = confirm_timeout if first and confirm_timeout else None
            r = run_plan(
                p,
                sandbox,
                min(batch, 2) if round_ == 0 else batch,
                plan_seed(seed_, p.name, round_),
                baseline=False,
                confirm_timeout=confirm,
                pinned=round_ == 0,
            )
            tallies[p.name].merge(r.tally)
        round_ += 1
        if log is not None:
            n = sum(t.inputs for t in tallies.values())
            log(f"api round {round_}: {n} inputs, {time.monotonic() - start:.0f} s")
    return list(tallies.values()), skipped, broken


# imaging.segmentation and features.selective_search (issue 26, item 2)
VALID.update(
    {
        "imaging.felzenszwalb": {"image": IMG_RGB, "scale": 50.0},
        "imaging.grid_edges": {"shape": (4, 5)},
        "features.hierarchical_grouping": {"image": IMG_RGB, "labels": LABELS},
        "features.selective_search": {"image": IMG_RGB, "rng": 0},
    }
)


# nn.detection (issue 26): tiny detectors, a batch of two images with their targets
def detector_value(kind: str) -> Any:
    """A valid nn.detection value: a tiny ``fcos`` / ``faster`` / ``fast`` /
    ``localizer`` model (seeded), ``images`` (two 3 x 16 x 16 tensors) or ``targets``
    (one box each)."""
    import torch

    from robopercept.nn.detection.fast_rcnn import FastRCNN
    from robopercept.nn.detection.faster_rcnn import FasterRCNN
    from robopercept.nn.detection.fcos import FCOS
    from robopercept.nn.detection.localizer import SingleObjectLocalizer
    from robopercept.nn.detection.mask_rcnn import MaskRCNN

    torch.manual_seed(0)
    if kind == "images":
        return [torch_image(3, 16, 16), torch_image(3, 16, 24)]
    if kind == "targets":
        return [
            {"boxes": torch.tensor([[1.0, 2.0, 9.0, 12.0]]), "labels": torch.tensor([1])},
            {"boxes": torch.tensor([[4.0, 0.0, 20.0, 10.0]]), "labels": torch.tensor([2])},
        ]
    if kind == "mtargets":
        masks = []
        for box, (h, w) in (([1, 2, 9, 12], (16, 16)), ([4, 0, 20, 10], (16, 24))):
            m = torch.zeros(1, h, w, dtype=torch.uint8)
            m[0, box[1] : box[3], box[0] : box[2]] = 1
            masks.append(m)
        return [
            {
                "boxes": torch.tensor([[1.0, 2.0, 9.0, 12.0]]),
                "labels": torch.tensor([1]),
                "masks": masks[0],
            },
            {
                "boxes": torch.tensor([[4.0, 0.0, 20.0, 10.0]]),
                "labels": torch.tensor([2]),
                "masks": masks[1],
            },
        ]
    if kind == "ktargets":
        kps = [[[2.0, 3.0, 2.0], [8.0, 11.0, 1.0]], [[5.0, 1.0, 2.0], [19.0, 9.0, 0.0]]]
        return [
            {
                "boxes": torch.tensor([[1.0, 2.0, 9.0, 12.0]]),
                "labels": torch.tensor([1]),
                "keypoints": torch.tensor([kps[0]]),
            },
            {
                "boxes": torch.tensor([[4.0, 0.0, 20.0, 10.0]]),
                "labels": torch.tensor([2]),
                "keypoints": torch.tensor([kps[1]]),
            },
        ]
    if kind == "maskrcnn":
        return MaskRCNN(2, width=4, hidden=8, mask_channels=4, mask_convs=1)
    if kind == "fcos":
        return FCOS(2, width=4, head_channels=8)
    if kind == "faster":
        return FasterRCNN(2, width=4, hidden=8)
    if kind == "fast":
        return FastRCNN(2, width=4, hidden=8)
    return SingleObjectLocalizer(2, width=4)


_DIMAGES = _b("tests.fuzz.api:detector_value", "images")
_DTARGETS = _b("tests.fuzz.api:detector_value", "targets")
_DPROPS = _b("tests.fuzz.api:torch_tensor", [[0.0, 0.0, 8.0, 8.0], [2.0, 2.0, 14.0, 12.0]])
VALID.update(
    {
        "nn.train.config.resolve_device": {"name": "cpu"},
        "nn.core.backbones.FPN": {"in_channels": [4, 8], "out_channels": 4},
        "nn.core.backbones.DetectionBackbone": {"width": 4, "strides": (8, 16)},
        "nn.detection.localizer.SingleObjectLocalizer": {"num_classes": 2, "width": 4},
        "nn.detection.fast_rcnn.FastRCNN": {"num_classes": 2, "width": 4, "hidden": 8},
        "nn.detection.faster_rcnn.FasterRCNN": {"num_classes": 2, "width": 4, "hidden": 8},
        "nn.detection.fcos.FCOS": {
            "num_classes": 2,
            "width": 4,
            "head_channels": 8,
            "box_activation": "exp",
            "centerness_weighted": True,
        },
        "nn.detection.fcos.FCOS.forward": {"images": _DIMAGES, "targets": _DTARGETS},
        "nn.detection.faster_rcnn.FasterRCNN.forward": {"images": _DIMAGES, "targets": _DTARGETS},
        "nn.detection.fast_rcnn.FastRCNN.forward": {
            "images": _DIMAGES,
            "targets": _DTARGETS,
            "proposals": [_DPROPS, _DPROPS],
        },
        "nn.detection.localizer.SingleObjectLocalizer.forward": {
            "images": _DIMAGES,
            "targets": _DTARGETS,
        },
        "nn.detection.targets.match_boxes": {
            "iou": _b("tests.fuzz.api:torch_tensor", [[0.9, 0.2, 0.5]]),
            "fg_threshold": 0.7,
            "bg_threshold": 0.3,
        },
        "nn.detection.targets.sample_balanced": {
            "labels": _b("tests.fuzz.api:torch_tensor", [1, 0, -1, 0], "int64"),
            "batch_size": 2,
            "positive_fraction": 0.5,
        },
        "nn.ops.losses.sigmoid_focal_loss": {"inputs": TSCORES, "targets": TSCORES},
        "nn.detection.train.train_detector": {
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "dataset": _DDS,
            "config": TRAIN_CFG,
            "progress": False,
        },
        "nn.detection.train.evaluate_detector": {
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "dataset": _DDS,
        },
    }
)
for _cls in (
    "fcos.FCOS",
    "faster_rcnn.FasterRCNN",
    "fast_rcnn.FastRCNN",
    "localizer.SingleObjectLocalizer",
):
    METHODS[f"nn.detection.{_cls}"] = ("forward",)
VALID.update(
    {
        "nn.detection.base.check_images": {"images": _DIMAGES},
        "nn.detection.train.check_detection_dataset": {"dataset": _DDS},
    }
)
VALID.update(
    {
        "nn.detection.rcnn.RCNN": {"num_classes": 2, "warp_size": 8, "width": 4, "hidden": 8},
        "nn.detection.rcnn.RCNN.forward": {
            "images": _DIMAGES,
            "targets": _DTARGETS,
            "proposals": [_DPROPS, _DPROPS],
        },
        "nn.detection.rcnn.RCNN.warp": {
            "image": _b("tests.fuzz.api:torch_image", 3, 16, 16),
            "boxes": _DPROPS,
        },
        "nn.detection.rcnn.selective_search_proposals": {
            "image": _b("tests.fuzz.api:torch_image", 3, 16, 16),
            "max_proposals": 5,
        },
        "nn.detection.zoo.build_detector": {"kind": "fcos", "num_classes": 2, "width": 4},
        "nn.detection.zoo.save_detector": {
            "path": _out("detector.pt"),
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "kind": "fcos",
            "settings": {"width": 4},
            "classes": ["a", "b"],
        },
        "nn.detection.zoo.load_detector": {"path": Fixture("detector.pt")},
        "nn.detection.zoo.detect_arrays": {
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "images": [IMG_RGB],
        },
    }
)
METHODS["nn.detection.rcnn.RCNN"] = ("forward", "warp")
_ONE_BOX = _b("tests.fuzz.api:detection_value", "one_box")
VALID.update(
    {
        "nn.detection.localizer.evaluate_localizer": {
            "model": _b("tests.fuzz.api:detector_value", "localizer"),
            "dataset": _ONE_BOX,
        },
        "nn.detection.faster_rcnn.FasterRCNN.rpn_outputs": {"images": _DIMAGES},
        "nn.detection.augment.FlipRotate": {"horizontal": 0.5, "vertical": 0.5, "rotate90": True},
        "nn.detection.augment.FlipRotate.__call__": {
            "image": _b("tests.fuzz.api:torch_image", 3, 16, 24),
            "target": _b("tests.fuzz.api:detection_value", "target"),
        },
        "nn.detection.tta.TestTimeAugmentation": {
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "views": "flips",
        },
        "nn.detection.tta.TestTimeAugmentation.forward": {"images": _DIMAGES},
        "nn.detection.tta.TestTimeAugmentation.predict": {"images": _DIMAGES},
        "nn.detection.tta.check_scales": {"scales": [0.9, 1.0, 1.1]},
        "nn.detection.tta.check_tta_config": {
            "config": {"views": "flips", "scales": [0.9, 1.0], "iou_thresh": 0.55},
        },
        "nn.detection.tta.rescale_image": {
            "image": _b("tests.fuzz.api:torch_image", 3, 16, 24),
            "scale": 0.9,
        },
        "nn.detection.tta.resolve_tta": {
            "stored": {"views": "flips", "scales": [0.9, 1.0], "iou_thresh": 0.55},
            "views": "hflip",
            "scales": [1.0, 1.1],
        },
        "nn.detection.tta.wrap_tta": {
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "config": {"views": "hflip", "scales": [1.0, 1.1], "iou_thresh": None},
        },
        "nn.detection.tta.choose_tta": {
            "model": _b("tests.fuzz.api:detector_value", "fcos"),
            "dataset": _ONE_BOX,
            "grid": [{"views": "hflip", "scales": (1.0, 0.9), "iou_thresh": None}],
        },
        "nn.detection.augment.ScaleJitter": {"scale": (0.75, 1.33), "min_visible": 0.5},
        "nn.detection.augment.ScaleJitter.__call__": {
            "image": _b("tests.fuzz.api:torch_image", 3, 16, 24),
            "target": _b("tests.fuzz.api:detection_value", "target"),
        },
    }
)
METHODS["nn.detection.faster_rcnn.FasterRCNN"] = ("forward", "rpn_outputs")
# the parts of the two-stage detectors (issue 45): the RPN alone, the RoI heads and
# their box head, predictor and branches
VALID.update(
    {
        "nn.detection.rpn.RegionProposalNetwork": {
            "in_channels": 4,
            "anchor_generator": _b("robopercept.nn.ops.anchors:AnchorGenerator", (8.0,), (1.0,)),
        },
        "nn.detection.rpn.RegionProposalNetwork.forward": {
            "features": _b("tests.fuzz.api:torch_image", 2, 4, 2, 3),
            "image_shape": (16, 24),
            "sizes": [(16, 16), (16, 24)],
            "targets": _DTARGETS,
        },
        "nn.detection.roi_heads.TwoMLPHead": {"in_channels": 4, "pool_size": 2, "hidden": 8},
        "nn.detection.roi_heads.FastRCNNPredictor": {"in_features": 8, "num_classes": 2},
        "nn.detection.roi_heads.RoIHeads": {
            "box_pooler": _b("robopercept.nn.ops.roi:RoIAlign", 2, 0.125, 2),
            "box_head": _b("robopercept.nn.detection.roi_heads:TwoMLPHead", 4, 2, 8),
            "box_predictor": _b("robopercept.nn.detection.roi_heads:FastRCNNPredictor", 8, 2),
            "num_classes": 2,
        },
        "nn.detection.mask_rcnn.MaskHead": {
            "in_channels": 4,
            "num_classes": 2,
            "mask_channels": 4,
            "mask_convs": 1,
        },
        "nn.detection.keypoint_rcnn.KeypointHead": {
            "in_channels": 4,
            "num_keypoints": 2,
            "keypoint_channels": 4,
            "keypoint_convs": 1,
        },
    }
)
METHODS["nn.detection.rpn.RegionProposalNetwork"] = ("forward",)
SKIP["nn.detection.roi_heads.RegionBranch"] = (
    "a typing Protocol (its implementations are fuzzed: MaskHead, KeypointHead)"
)
VALID.update(
    {
        "nn.ops.roi.paste_masks": {
            "masks": _b("tests.fuzz.api:torch_image", 3, 6, 6),
            "boxes": TBOXES,
            "size": (16, 24),
        },
        "nn.detection.mask_rcnn.MaskRCNN": {
            "num_classes": 2,
            "width": 4,
            "hidden": 8,
            "mask_channels": 4,
            "mask_convs": 1,
        },
        "nn.detection.mask_rcnn.MaskRCNN.forward": {
            "images": _DIMAGES,
            "targets": _b("tests.fuzz.api:detector_value", "mtargets"),
        },
    }
)
METHODS["nn.detection.mask_rcnn.MaskRCNN"] = ("forward",)
METHODS["nn.detection.augment.FlipRotate"] = ("__call__",)
METHODS["nn.detection.augment.ScaleJitter"] = ("__call__",)
METHODS["nn.detection.tta.TestTimeAugmentation"] = ("forward", "predict")


# nn.segmentation.networks checkpoints and inference, the built-in sets (issue 27)
def _write_segmenter(path: Path) -> None:
    """A width-4 U-Net checkpoint of two classes (save_segmenter)."""
    from robopercept.nn.segmentation.networks import UNet, save_segmenter

    save_segmenter(path, UNet(3, 3, 4, 2), "unet", {"width": 4, "depth": 2}, ["a", "b"])


FIXTURES["segmenter.pt"] = _write_segmenter
_SEG3 = _b("robopercept.nn.segmentation.networks:UNet", 3, 3, 4, 2)
VALID.update(
    {
        "nn.segmentation.networks.save_segmenter": {
            "path": _out("segmenter.pt"),
            "model": _SEG3,
            "name": "unet",
            "settings": {"width": 4, "depth": 2},
            "classes": ["a", "b"],
        },
        "nn.segmentation.networks.load_segmenter": {"path": Fixture("segmenter.pt")},
        "nn.segmentation.networks.segment_arrays": {"model": _SEG3, "images": [IMG_RGB, IMG]},
        "nn.segmentation.networks.coco_segmentation_results": {
            "image_id": 1,
            "labels": (IMG // 100).astype(np.int64),
        },
        "nn.train.checkpoint.save_built_model": {
            "path": _out("built.pt"),
            "model": _SEG3,
            "kind": "unet",
            "settings": {"width": 4, "depth": 2},
            "classes": ["a", "b"],
        },
        "nn.train.checkpoint.load_built_model": {
            "path": Fixture("segmenter.pt"),
            "kinds": ["unet"],
            "build": _b("tests.fuzz.api:unet_builder"),
            "what": "segmenter",
            "writer": "save_segmenter",
        },
        "nn.segmentation.data.segmentation_sets": {
            "data": "shapes",
            "n_images": 3,
            "size": (32, 32),
            "seed": 0,
        },
    }
)


def unet_builder() -> Any:
    """A builder for load_built_model: (kind, n_classes, **settings) -> a U-Net."""
    from robopercept.nn.segmentation.networks import UNet

    def build(kind: str, n_classes: int, **settings: Any) -> Any:
        return UNet(n_classes + 1, **settings)

    return build


# nn.segmentation.run (issue 45): the run of `nn segment train|eval` on 32 x 32 shapes
_SHAPES = ["circle", "square", "triangle", "cross"]


def _write_shapes_segmenter(path: Path) -> None:
    """A width-4 U-Net checkpoint of the shapes' classes (what train_run writes)."""
    from robopercept.nn.segmentation.networks import UNet, save_segmenter

    save_segmenter(path, UNet(5, 3, 4, 2), "unet", {"width": 4, "depth": 2}, _SHAPES)


def segmentation_val() -> Any:
    """The validation set of three 32 x 32 shapes canvases (with masks)."""
    from robopercept.nn.segmentation.data import segmentation_sets

    return segmentation_sets("shapes", 3, (32, 32), 0).val


FIXTURES["shapes_segmenter.pt"] = _write_shapes_segmenter
VALID.update(
    {
        "nn.segmentation.run.load_segmentation_data": {
            "data": "shapes",
            "images": 3,
            "size": (32, 32),
        },
        "nn.segmentation.run.resolve_segment_model": {"task": "instance"},
        "nn.segmentation.run.score_segmentation": {
            "model": _SEG3,
            "val": _b("tests.fuzz.api:segmentation_val"),
            "device": "cpu",
        },
        "nn.segmentation.run.evaluate_run": {
            "model": Fixture("shapes_segmenter.pt"),
            "data": "shapes",
            "images": 3,
            "size": (32, 32),
            "device": "cpu",
        },
    }
)
SKIP["nn.segmentation.run.train_run"] = (
    "trains a network and writes a run folder (seconds per call); its parts are fuzzed: "
    "load_segmentation_data, resolve_segment_model, train_segmenter, score_segmentation"
)


# nn.pose.io (issue 28): a two-person MPII list and an imgaug keypoint file
_MPII_JSON = [
    {
        "image": f"{i:03d}.jpg",
        "joints": [[float(10 + j), float(20 + i + j)] for j in range(16)],
        "joints_vis": [1] * 15 + [0],
        "center": [30.0, 30.0],
        "scale": 0.2,
    }
    for i in range(2)
]
_IMGAUG_JSON = {
    "bounding_boxes": [{"x1": 2.0, "y1": 3.0, "x2": 40.0, "y2": 30.0, "label": "animal"}],
    "keypoints": [
        {"x": 10.0, "y": 5.0, "label": "eye_left"},
        {"x": 20.0, "y": 5.0, "label": "eye_right"},
    ],
    "polygons": [{"keypoints": [{"x": 2.0, "y": 3.0}, {"x": 40.0, "y": 3.0}, {"x": 20, "y": 30}]}],
}
FIXTURES.update(
    {
        "mpii.json": lambda p: p.write_text(json.dumps(_MPII_JSON)),
        "imgaug.json": lambda p: p.write_text(json.dumps(_IMGAUG_JSON)),
    }
)
VALID.update(
    {
        "nn.pose.io.read_mpii_json": {"path": Fixture("mpii.json")},
        "nn.pose.io.read_imgaug_keypoints": {"path": Fixture("imgaug.json")},
    }
)

# nn.pose.pictorial (issue 28): cost maps, a 3-joint chain, four 16x16 pictures with poses
_PS_RNG = np.random.default_rng(28)
PS_COSTS = _PS_RNG.normal(size=(3, 6, 7))
PS_IMAGES = _PS_RNG.uniform(0, 1, (4, 16, 16, 3))
PS_KEYPOINTS = np.concatenate([_PS_RNG.uniform(2, 13, (4, 3, 2)), np.full((4, 3, 1), 2.0)], axis=2)
_PS_ARM = _b("robopercept.nn.skeleton:Skeleton", "arm", ["a", "b", "c"], [(0, 1), (1, 2)], [])
VALID.update(
    {
        "nn.pose.pictorial.distance_transform_1d": {"f": _PS_RNG.normal(size=(5, 9))},
        "nn.pose.pictorial.generalized_distance_transform": {"f": PS_COSTS[0]},
        "nn.pose.pictorial.pictorial_structures": {
            "unary_costs": PS_COSTS,
            "parents": [-1, 0, 1],
            "offsets": np.ones((3, 2)),
            "weights": np.ones((3, 2)),
        },
        "nn.pose.pictorial_learn.grid_descriptors": {"image": IMG_RGB},
        "nn.pose.pictorial_learn.PictorialStructures": {"skeleton": _PS_ARM, "random_state": 0},
        "nn.pose.pictorial_learn.PictorialStructures.fit": {
            "images": PS_IMAGES,
            "keypoints": PS_KEYPOINTS,
        },
        "nn.pose.pictorial_learn.PictorialStructures.predict": {"images": PS_IMAGES[:2]},
        "nn.pose.pictorial_learn.PictorialStructures.predict_costs": {"image": IMG_RGB},
    }
)
METHODS["nn.pose.pictorial_learn.PictorialStructures"] = ("fit", "predict", "predict_costs")
PRE["nn.pose.pictorial_learn.PictorialStructures.predict"] = (("fit", (PS_IMAGES, PS_KEYPOINTS)),)
PRE["nn.pose.pictorial_learn.PictorialStructures.predict_costs"] = (
    ("fit", (PS_IMAGES, PS_KEYPOINTS)),
)


# nn.skeleton, nn.pose.data, nn.ops.heatmaps, the pose networks and the keypoint detector
# (issue 28)
_ARM = {"name": "arm", "joints": ["a", "left_b", "right_b"], "links": [(0, 1), (0, 2)]}
_POSE_DS = _b("robopercept.nn.pose.data:procedural_pose_set", 2, (32, 32), 0)
_POSE_NET = _b("robopercept.nn.pose.networks:SimpleBaseline", 16, 2)
_POSE_STAGE = _b("robopercept.nn.pose.networks:DeepPoseRefiner", 16, 8.0, 8, 2)
_K = np.array([[40.0, 0.0, 16.0], [0.0, 40.0, 16.0], [0.0, 0.0, 1.0]])


def _write_pose_model(path: Path) -> None:
    """A width-2 SimpleBaseline checkpoint of MPII's 16 joints (save_pose_model)."""
    from robopercept.nn.pose.networks import SimpleBaseline, save_pose_model
    from robopercept.nn.skeleton import MPII_16

    save_pose_model(path, SimpleBaseline(16, 2), "heatmap", {"width": 2}, MPII_16)


FIXTURES["pose.pt"] = _write_pose_model
VALID.update(
    {
        "nn.skeleton.Skeleton": {**_ARM, "flip_pairs": [(1, 2)]},
        "nn.skeleton.Skeleton.index": {"joint": "left_b"},
        "nn.skeleton.Skeleton.parents": {"root": 0},
        "nn.skeleton.Skeleton.from_dict": {"data": {**_ARM, "flip_pairs": [[1, 2]]}},
        "nn.skeleton.skeleton_from_coco_category": {
            "category": {
                "id": 1,
                "name": "person",
                "keypoints": ["a", "left_b", "right_b"],
                "skeleton": [[1, 2], [1, 3]],
            },
        },
        "nn.data.textures.photo_background": {
            "gen": _b("numpy.random:default_rng", 0),
            "w": 16,
            "h": 12,
        },
        "nn.data.textures.random_texture": {
            "gen": _b("numpy.random:default_rng", 0),
            "w": 16,
            "h": 12,
        },
        "nn.detection.keypoint_rcnn.KeypointRCNN": {
            "num_classes": 2,
            "num_keypoints": 2,
            "width": 4,
            "hidden": 8,
            "keypoint_channels": 4,
            "keypoint_convs": 1,
        },
        "nn.detection.keypoint_rcnn.KeypointRCNN.forward": {
            "images": _DIMAGES,
            "targets": _b("tests.fuzz.api:detector_value", "ktargets"),
        },
        "nn.pose.data.random_poses_3d": {"n": 2, "rng": 0},
        "nn.pose.data.project_points": {"points": [[0.1, -0.2, 2.0]], "camera_matrix": _K},
        "nn.pose.data.procedural_pose_set": {"n_images": 2, "size": (32, 32), "rng": 0},
        "nn.pose.data.procedural_pose_scenes": {"n_images": 1, "size": (48, 40), "rng": 0},
        "nn.pose.data.pose_sets": {"data": "figures", "images": 2, "size": (32, 32)},
        "nn.pose.data.PoseDataset": {
            "images": np.zeros((2, 8, 8, 3), np.float32),
            "keypoints": np.full((2, 16, 3), 2.0),
            "boxes": np.array([[0.0, 0.0, 8.0, 8.0]] * 2),
            "skeleton": _b("tests.fuzz.api:mpii_skeleton"),
            "joints3d": np.ones((2, 16, 3)),
            "cameras": np.stack([_K, _K]),
        },
        "nn.pose.data.PoseDataset.subset": {"indices": [1, 0]},
        "nn.pose.data.PoseDataset.split": {"fractions": (0.5, 0.5), "rng": 0},
        "nn.pose.data.PoseDataset.__getitem__": {"i": 0},
        "nn.ops.heatmaps.gaussian_heatmaps": {
            "keypoints": [[[6.0, 2.0, 2.0], [1.0, 7.0, 1.0]]],
            "image_size": (8, 8),
            "stride": 4,
        },
        "nn.ops.heatmaps.decode_heatmaps": {
            "heatmaps": np.random.default_rng(0).uniform(0, 1, (1, 2, 4, 5)),
            "stride": 4,
        },
        "nn.ops.heatmaps.heatmap_loss": {
            "output": _b("tests.fuzz.api:torch_image", 2, 3, 4, 4),
            "target": _b("tests.fuzz.api:torch_image", 2, 3, 4, 4),
            "weight": _b("tests.fuzz.api:torch_tensor", [[1.0, 0.0, 1.0], [1.0, 1.0, 1.0]]),
        },
        "nn.pose.inference.predict_heatmaps": {
            "model": _POSE_NET,
            "images": np.zeros((1, 32, 32, 3)),
        },
        "nn.pose.networks.SimpleBaseline": {"num_joints": 3, "width": 2},
        "nn.pose.networks.HRNet": {"num_joints": 3, "width": 2, "blocks": 1},
        "nn.pose.networks.DeepPose": {
            "num_joints": 3,
            "image_size": (32, 32),
            "width": 2,
            "hidden": 8,
        },
        "nn.pose.networks.DeepPoseRefiner": {"num_joints": 3, "crop": 8.0, "patch": 8, "width": 2},
        "nn.pose.networks.build_pose_model": {"name": "heatmap", "num_joints": 3},
        "nn.pose.networks.crop_patches": {
            "images": _b("tests.fuzz.api:torch_image", 1, 1, 6, 6),
            "centres": _b("tests.fuzz.api:torch_tensor", [[[2.0, 3.0], [4.5, 1.0]]]),
            "crop": 2.0,
            "patch": 2,
        },
        "nn.pose.train.augment_pose_batch": {
            "images": _b("tests.fuzz.api:torch_image", 2, 3, 8, 8),
            "keypoints": _b("tests.fuzz.api:torch_tensor", [[[2.0, 3.0, 2.0]], [[5.0, 1.0, 1.0]]]),
            "flip_permutation": [0],
            "generator": _b("torch:Generator"),
        },
        "nn.pose.inference.predict_keypoints": {
            "model": _POSE_NET,
            "images": np.zeros((1, 32, 32, 3)),
        },
        "nn.pose.inference.refine_keypoints": {
            "images": np.zeros((1, 32, 32, 3)),
            "keypoints": np.full((1, 16, 2), 16.0),
            "refiners": [_POSE_STAGE],
        },
        "nn.pose.train.train_pose": {
            "model": _POSE_NET,
            "train": _POSE_DS,
            "config": TRAIN_CFG,
            "progress": False,
        },
        "nn.pose.train.train_refiner": {
            "refiner": _POSE_STAGE,
            "train": _POSE_DS,
            "estimates": np.full((2, 16, 2), 16.0),
            "config": TRAIN_CFG,
            "progress": False,
        },
        "nn.pose.train.train_cascade": {
            "model": _POSE_NET,
            "train": _POSE_DS,
            "stages": 1,
            "config": TRAIN_CFG,
            "crop": 8.0,
            "width": 2,
            "progress": False,
        },
        "nn.pose.networks.save_pose_model": {
            "path": _out("pose.pt"),
            "model": _POSE_NET,
            "name": "heatmap",
            "settings": {"width": 2},
            "skeleton": _b("tests.fuzz.api:mpii_skeleton"),
        },
        "nn.pose.networks.load_pose_model": {"path": Fixture("pose.pt")},
        "nn.pose.inference.pose_arrays": {"model": _POSE_NET, "images": [IMG_RGB, IMG]},
        "nn.pose.evaluate.evaluate_pose": {"model": _POSE_NET, "data": _POSE_DS},
        "nn.pose.inference.samples_picture": {"model": _POSE_NET, "data": _POSE_DS, "count": 2},
    }
)
METHODS["nn.skeleton.Skeleton"] = ("index", "flip_permutation", "parents", "to_dict", "from_dict")
METHODS["nn.pose.data.PoseDataset"] = ("subset", "split", "areas", "to_coco", "__getitem__")
METHODS["nn.detection.keypoint_rcnn.KeypointRCNN"] = ("forward",)

# nn.pose.run (issue 45): the run of `nn pose train|eval`, on a width-2 SimpleBaseline
VALID.update(
    {
        "nn.pose.run.load_pose_data": {"data": "figures", "images": 2, "size": (32, 32)},
        "nn.pose.run.model_path": {"model": Fixture("pose.pt")},
        "nn.pose.run.evaluate_run": {
            "model": Fixture("pose.pt"),
            "data": "figures",
            "images": 2,
            "size": (32, 32),
            "out_dir": _out("pose_eval"),
        },
    }
)
SKIP["nn.pose.run.train_run"] = (
    "trains a network and writes a run folder (seconds per call); its parts are fuzzed: "
    "load_pose_data, train_pose, train_cascade, evaluate_pose, save_pose_model"
)


def mpii_skeleton() -> Any:
    """MPII's 16-joint skeleton."""
    from robopercept.nn.skeleton import MPII_16

    return MPII_16


# nn.pose.views, .library and .lifting (issue 28): three 16-joint 3-D poses (metres), 2-D
# joints, a tiny lifter
_P3_RNG = np.random.default_rng(283)
P3D = _P3_RNG.normal(0.0, 0.3, (3, 16, 3))
P3D_PRED = P3D[:2] + _P3_RNG.normal(0.0, 0.05, (2, 16, 3))
KP2D = _P3_RNG.uniform(0.0, 100.0, (6, 16, 2))
_LIFTER = _b("robopercept.nn.pose.lifting:LiftingMLP", 16, 8, 1)
VALID.update(
    {
        "nn.pose.lifting.procrustes_align": {"pred": P3D_PRED, "truth": P3D[:2]},
        "nn.pose.lifting.mpjpe": {"pred": P3D_PRED, "truth": P3D[:2]},
        "nn.pose.lifting.pa_mpjpe": {"pred": P3D_PRED, "truth": P3D[:2]},
        "nn.pose.views.normalize_pose2d": {"keypoints2d": KP2D},
        "nn.pose.views.random_views": {"poses3d": P3D, "views_per_pose": 2, "rng": 0},
        "nn.pose.library.PoseLibrary": {"poses3d": P3D, "views_per_pose": 2},
        "nn.pose.library.PoseLibrary.lift": {"keypoints2d": KP2D},
        "nn.pose.lifting.LiftingMLP": {"width": 8, "blocks": 1},
        "nn.pose.lifting.LiftingMLP.lift": {"keypoints2d": KP2D},
        "nn.pose.lifting.LiftingMLP.forward": {"x": _b("tests.fuzz.api:torch_image", 2, 32)},
        "nn.pose.lifting.train_lifter": {
            "model": _LIFTER,
            "keypoints2d": KP2D,
            "joints3d": P3D_PRED[[0, 1, 0, 1, 0, 1]],
            "epochs": 1,
            "batch_size": 4,
        },
    }
)
METHODS["nn.pose.library.PoseLibrary"] = ("lift",)
METHODS["nn.pose.lifting.LiftingMLP"] = ("lift", "forward")

# the checks and internal steps that the pose modules share (issue 45)
VALID.update(
    {
        "nn.ops.heatmaps.keypoint_tensor": {"keypoints": [[[6.0, 2.0, 2.0], [1.0, 7.0, 1.0]]]},
        "nn.ops.heatmaps.check_float_tensor": {
            "value": _b("tests.fuzz.api:torch_image", 2, 3),
            "name": "weight",
            "ndim": 2,
            "what": "(N, J)",
        },
        "nn.pose.inference.image_batch": {"images": np.zeros((1, 16, 16, 3))},
        "nn.pose.inference.pose_data_arrays": {"data": _POSE_DS, "what": "data"},
        "nn.pose.views.check_seed": {"value": 7, "name": "rng"},
        "nn.pose.views.check_keypoints2d": {"value": KP2D},
        "nn.pose.views.check_poses3d": {"value": P3D},
    }
)
_CHECKED = "on inputs its callers checked"
SKIP.update(
    {
        "nn.ops.heatmaps.check_image_size": "checks an image size against a stride the caller "
        "checked; fuzzed through gaussian_heatmaps and DeepPose",
        "nn.ops.heatmaps.check_permutation": "checks a flip permutation against a joint count "
        "the caller checked; fuzzed through predict_heatmaps and augment_pose_batch",
        "nn.ops.heatmaps.heatmap_probabilities": "an internal step of predict_heatmaps on a "
        "network's output; fuzzed through it",
        "nn.ops.heatmaps.flip_heatmaps": "an internal step of predict_heatmaps on a network's "
        "output; fuzzed through it",
        "nn.pose.inference.check_input_size": "a boundary step of predict_heatmaps and "
        "train_pose on a checked batch; fuzzed through them",
        "nn.pose.views.check_root": "checks a root against the joint count of checked poses; "
        "fuzzed through normalize_pose2d, random_views, mpjpe and LiftingMLP",
        "nn.pose.views.visibility_mask": "an internal step of normalize_pose2d and "
        f"PoseLibrary.lift {_CHECKED}; fuzzed through them",
        "nn.pose.views.normalize_joints": "the unchecked arithmetic of normalize_pose2d "
        f"{_CHECKED}; fuzzed through it, PoseLibrary and LiftingMLP",
        "nn.pose.views.check_scales": "an internal step of normalize_pose2d, PoseLibrary and "
        f"LiftingMLP {_CHECKED}; fuzzed through them",
        "nn.pose.pictorial.check_tree": "checks parents against the joint count of checked "
        "costs; fuzzed through pictorial_structures and PictorialStructures",
        "nn.pose.pictorial.solve_tree": "the unchecked arithmetic of pictorial_structures "
        f"{_CHECKED}; fuzzed through it and PictorialStructures.predict",
    }
)


# viz.cloud_dl (issue 29): a 60-point cloud, its labels, two 4-neighbour graphs
_CDL_LABELS = (np.arange(60) % 3).astype(np.int64)
_CDL_NEAR = np.argsort(((PTS3[:, None] - PTS3[None]) ** 2).sum(-1), axis=1)[:, :4]
VALID.update(
    {
        "viz.cloud_picture": {
            "points": PTS3,
            "labels": _CDL_LABELS,
            "names": ["a", "b", "c"],
            "size": (300, 200),
        },
        "viz.clouds_grid": {
            "clouds": [PTS3, PTS3[:20]],
            "titles": ["a", "b / c"],
            "labels": [_CDL_LABELS, None],
            "title_colors": [None, "red"],
            "size": (300, 200),
        },
        "viz.critical_points_picture": {"points": PTS3, "critical": [0, 5, 5], "size": (300, 200)},
        "viz.feature_neighbours_picture": {
            "points": PTS3,
            "graphs": [_CDL_NEAR, _CDL_NEAR[::-1]],
            "queries": [0, 7],
            "size": (300, 200),
        },
    }
)


# nn.train.loop.epoch_loop (issue 29: the loop shared by the pose and point-cloud trainers)
def loop_batch() -> Any:
    """A valid epoch_loop ``batch``: indices -> a scalar loss with a graph."""
    import torch

    w = torch.nn.Parameter(torch.ones(2))
    return lambda idx: (w * w).sum() * float(len(idx))


VALID["nn.train.loop.epoch_loop"] = {
    "model": TINY_NET,
    "n": 4,
    "cfg": TRAIN_CFG,
    "generator": _b("torch:Generator"),
    "batch": _b("tests.fuzz.api:loop_batch"),
    "validate": None,
    "desc": "fuzz",
    "progress": False,
}
METHODS["nn.train.loop.EpochHistory"] = ("to_dict",)


# nn.train.loop.train_loop (issue 45: THE loop every trainer runs)
def loop_part(kind: str) -> Any:
    """A valid train_loop ``optimizer`` (SGD on one parameter), ``batches`` (epoch ->
    two batches) or ``step`` (batch -> a scalar loss with a graph)."""
    import torch

    w = torch.nn.Parameter(torch.ones(2))
    parts = {
        "optimizer": torch.optim.SGD([w], lr=0.1),
        "batches": lambda epoch: [1, 2],
        "step": lambda batch, epoch, b: (w * w).sum() * float(batch),
    }
    return parts[kind]


VALID["nn.train.loop.train_loop"] = {
    "model": TINY_NET,
    "optimizer": _b("tests.fuzz.api:loop_part", "optimizer"),
    "batches": _b("tests.fuzz.api:loop_part", "batches"),
    "step": _b("tests.fuzz.api:loop_part", "step"),
    "epochs": 2,
    "progress": False,
}
VALID["nn.train.runs.prepare_run_folder"] = {"out_dir": _out("fuzz_run")}
VALID["nn.train.runs.check_output_folder"] = {"value": _out("fuzz_eval")}
VALID["nn.train.runs.write_json"] = {"path": _out("x.json"), "value": {"a": 1}}
VALID["nn.classification.run.model_summary"] = {
    "model": "vgg_small",
    "input_shape": (1, 8, 8),
    "num_classes": 3,
}


# nn.cloud.pointnet and nn.cloud.dgcnn (issue 29): tiny PointNet / DGCNN, two clouds of 16 points
_CLOUDS = _b("tests.fuzz.api:torch_image", 2, 16, 3)
_CLOUD_MASK = _b("tests.fuzz.api:torch_tensor", [[True] * 12 + [False] * 4, [True] * 16], "bool")
_CLOUD_CATS = _b("tests.fuzz.api:torch_tensor", [0, 1], "int64")
_TINY_POINTNET = _b("robopercept.nn.cloud.pointnet:PointNet", 3, width=0.125)
_CLOUD_GRAPH = _b("robopercept.nn.cloud.dgcnn:knn_graph", _CLOUDS, 4)
VALID.update(
    {
        "nn.cloud.pointnet.check_cloud_batch": {
            "x": _CLOUDS,
            "in_channels": 3,
            "mask": _CLOUD_MASK,
            "category": _CLOUD_CATS,
            "num_categories": 2,
        },
        "nn.cloud.pointnet.masked_max_pool": {
            "features": _b("tests.fuzz.api:torch_image", 2, 16, 5),
            "mask": _CLOUD_MASK,
        },
        "nn.cloud.pointnet.MaskedBatchNorm": {"num_features": 4},
        "nn.cloud.pointnet.MaskedBatchNorm.forward": {
            "x": _b("tests.fuzz.api:torch_image", 2, 16, 4),
            "mask": _CLOUD_MASK,
        },
        "nn.cloud.pointnet.SharedMLP": {"channels": [3, 8, 4]},
        "nn.cloud.pointnet.SharedMLP.forward": {"x": _CLOUDS, "mask": _CLOUD_MASK},
        "nn.cloud.pointnet.TNet": {"k": 3, "width": 0.125},
        "nn.cloud.pointnet.TNet.forward": {"x": _CLOUDS, "mask": _CLOUD_MASK},
        "nn.cloud.pointnet.transform_regularizer": {
            "transform": _b("tests.fuzz.api:torch_image", 2, 3, 3)
        },
        "nn.cloud.pointnet.PointNet": {"num_outputs": 3, "width": 0.125},
        "nn.cloud.pointnet.PointNet.forward": {"x": _CLOUDS, "mask": _CLOUD_MASK},
        "nn.cloud.pointnet.PointNet.forward_aux": {"x": _CLOUDS, "mask": _CLOUD_MASK},
        "nn.cloud.pointnet.critical_points": {
            "model": _TINY_POINTNET,
            "points": np.random.default_rng(29).uniform(-1, 1, (32, 3)),
        },
        "nn.cloud.dgcnn.knn_graph": {"x": _CLOUDS, "k": 4, "mask": _CLOUD_MASK, "chunk_size": 5},
        "nn.cloud.dgcnn.edge_features": {"x": _CLOUDS, "idx": _CLOUD_GRAPH},
        "nn.cloud.dgcnn.EdgeConv": {"in_channels": 3, "out_channels": 8, "k": 4},
        "nn.cloud.dgcnn.EdgeConv.forward": {"x": _CLOUDS, "idx": _CLOUD_GRAPH, "mask": _CLOUD_MASK},
        "nn.cloud.dgcnn.DGCNN": {"num_outputs": 3, "k": 4, "widths": (8, 8), "embedding": 16},
        "nn.cloud.dgcnn.DGCNN.forward": {"x": _CLOUDS, "mask": _CLOUD_MASK},
        "nn.cloud.dgcnn.DGCNN.forward_aux": {"x": _CLOUDS, "mask": _CLOUD_MASK},
    }
)
METHODS["nn.cloud.pointnet.MaskedBatchNorm"] = ("forward",)
METHODS["nn.cloud.pointnet.SharedMLP"] = ("forward",)
METHODS["nn.cloud.pointnet.TNet"] = ("forward",)
METHODS["nn.cloud.pointnet.PointNet"] = ("forward", "forward_aux")
METHODS["nn.cloud.dgcnn.EdgeConv"] = ("forward",)
METHODS["nn.cloud.dgcnn.DGCNN"] = ("forward", "forward_aux")


# pointcloud.mesh and nn.cloud.data (issue 29): a tetrahedron, a mesh file, a class folder
_TETRA_V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
_TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
_TETRA = _b("robopercept.pointcloud:TriangleMesh", _TETRA_V, _TETRA_F)
_TETRA_OFF = (
    "OFF\n4 4 0\n"
    + "".join(f"{x:g} {y:g} {z:g}\n" for x, y, z in _TETRA_V)
    + "".join(f"3 {a} {b} {c}\n" for a, b, c in _TETRA_F)
)


def _write_cloud_folder(path: Path) -> None:
    """Two classes: ``a`` with a tetrahedron (OFF), ``b`` with a 60-point cloud (PCD)."""
    from robopercept.pointcloud import PointCloud, write_point_cloud

    (path / "a").mkdir(parents=True, exist_ok=True)
    (path / "a" / "tetra.off").write_text(_TETRA_OFF)
    write_point_cloud(path / "b" / "cloud.pcd", PointCloud(PTS3))


FIXTURES["mesh.off"] = lambda p: p.write_text(_TETRA_OFF)
FIXTURES["clouds"] = _write_cloud_folder
_CLOUD_DS_ARGS = {
    "points": np.random.default_rng(29).uniform(-1, 1, (4, 8, 3)).astype(np.float32),
    "labels": [0, 1, 0, 1],
    "class_names": ("a", "b"),
    "parts": np.tile([0, 1, 2, 2, 0, 1, 2, 2], (4, 1)),
    "part_names": ("a/x", "b/y", "b/z"),
    "part_classes": np.array([0, 1, 1]),
}
VALID.update(
    {
        "pointcloud.TriangleMesh": {"vertices": _TETRA_V, "faces": _TETRA_F},
        "pointcloud.read_mesh": {"path": Fixture("mesh.off")},
        "pointcloud.sample_surface": {"mesh": _TETRA, "n": 16, "rng": 0},
        "pointcloud.farthest_point_sampling": {"points": PTS3, "n": 8},
        "pointcloud.chamfer_distance": {"a": PTS3[:30], "b": PTS3[30:]},
        "nn.cloud.data.CloudDataset": _CLOUD_DS_ARGS,
        "nn.cloud.data.CloudDataset.subset": {"indices": [1, 0]},
        "nn.cloud.data.CloudDataset.split": {"fractions": (0.5, 0.5), "rng": 0},
        "nn.cloud.synthetic.shape_mesh": {"name": "mug", "rng": 0},
        "nn.cloud.synthetic.procedural_shapes": {
            "n_per_class": 1,
            "n_points": 16,
            "classes": ("sphere", "torus"),
            "rng": 0,
        },
        "nn.cloud.data.augment_clouds": {
            "points": _b("tests.fuzz.api:torch_image", 2, 16, 3),
            "generator": 0,
            "dropout": 0.2,
        },
        "nn.cloud.data.read_cloud_file": {"path": Fixture("mesh.off"), "n_points": 16},
        "nn.cloud.data.read_cloud_folder": {"root": Fixture("clouds"), "n_points": 16},
        "nn.cloud.data.check_n_points": {"n_points": 16},
        "nn.cloud.data.pick_points": {"points": PTS3, "n": 8, "rng": 0},
    }
)
METHODS["nn.cloud.data.CloudDataset"] = ("subset", "split")


# nn.cloud.train and nn.cloud.run (issues 29, 45): building, training, scoring and files of the
# point-cloud networks; the run (data sets, evaluation of a saved network, one file's prediction)
_CLOUD_NET = _b("robopercept.nn.cloud.train:build_cloud_model", "pointnet", 2, width=0.125, seed=0)
_CLOUD_DS = _b("robopercept.nn.cloud.data:CloudDataset", **_CLOUD_DS_ARGS)


def _write_cloud_model(path: Path) -> None:
    """A tiny PointNet classifier of the classes ("a", "b") saved by save_cloud_model."""
    from robopercept.nn.cloud.train import build_cloud_model, save_cloud_model

    save_cloud_model(path, build_cloud_model("pointnet", 2, width=0.125, seed=0), ["a", "b"])


def _write_shapes_model(path: Path) -> None:
    """A tiny PointNet classifier of the 12 procedural shapes (8 points per cloud)."""
    from robopercept.nn.cloud.synthetic import SHAPE_CLASSES
    from robopercept.nn.cloud.train import build_cloud_model, save_cloud_model

    net = build_cloud_model("pointnet", len(SHAPE_CLASSES), width=0.125, seed=0)
    save_cloud_model(path, net, list(SHAPE_CLASSES), n_points=8)


FIXTURES["cloud_model.pt"] = _write_cloud_model
FIXTURES["cloud_shapes_model.pt"] = _write_shapes_model
VALID.update(
    {
        "nn.cloud.train.build_cloud_model": {
            "name": "dgcnn",
            "num_outputs": 2,
            "k": 4,
            "widths": [8],
        },
        "nn.cloud.train.train_cloud_model": {
            "model": _CLOUD_NET,
            "train": _CLOUD_DS,
            "config": TRAIN_CFG,
            "val": _CLOUD_DS,
            "progress": False,
        },
        "nn.cloud.train.predict_clouds": {"model": _CLOUD_NET, "points": _CLOUD_DS_ARGS["points"]},
        "nn.cloud.train.evaluate_cloud_model": {"model": _CLOUD_NET, "data": _CLOUD_DS},
        "nn.cloud.train.part_ious": {
            "pred": _CLOUD_DS_ARGS["parts"],
            "parts": _CLOUD_DS_ARGS["parts"],
            "labels": _CLOUD_DS_ARGS["labels"],
            "part_classes": _CLOUD_DS_ARGS["part_classes"],
        },
        "nn.cloud.run.cloud_sets": {"data": "shapes", "shapes": 1, "n_points": 8},
        "nn.cloud.train.save_cloud_model": {
            "path": _out("cloud.pt"),
            "model": _CLOUD_NET,
            "class_names": ["a", "b"],
        },
        "nn.cloud.train.load_cloud_model": {"path": Fixture("cloud_model.pt")},
        "nn.cloud.train.cloud_model_spec": {"model": _CLOUD_NET},
        "nn.cloud.train.CloudModelSpec": {
            "kind": "pointnet",
            "task": "classify",
            "num_outputs": 2,
            "in_channels": 3,
            "config": {"width": 0.125},
        },
        "nn.cloud.run.evaluate_run": {
            "model": Fixture("cloud_shapes_model.pt"),
            "data": "shapes",
            "shapes": 1,
            "n_points": 8,
            "device": "cpu",
            "progress": False,
        },
        "nn.cloud.run.shipped_cloud_model": {"name": "pointnet"},
        "nn.cloud.run.classify_cloud_file": {
            "path": Fixture("mesh.off"),
            "model": _CLOUD_NET,
            "info": {"class_names": ["a", "b"], "n_points": 16},
        },
    }
)
VALID["nn.cloud.train.CloudEvaluation"] = {
    "accuracy": 0.5,
    "mean_class_accuracy": 0.5,
    "confusion": np.array([[1, 1], [0, 0]]),
    "predictions": np.array([0, 1]),
}
VALID["nn.cloud.run.CloudPrediction"] = {
    "path": "a.ply",
    "label": "a",
    "probabilities": {"a": 0.75, "b": 0.25},
    "points": PTS3,
}
METHODS["nn.cloud.train.CloudEvaluation"] = ("summary",)
METHODS["nn.cloud.run.CloudPrediction"] = ("to_dict",)

# ---- issue 30: text on images (viz.draw) and match pictures (viz.features); the names
# take effect once robopercept.viz exports them (draw_label, label_font, label_size_for,
# matches_picture, select_matches, project_outline)
VALID.update(
    {
        "viz.draw_label": {"image": IMG_RGB, "text": "ID 7", "xy": (10.0, 20.0)},
        "viz.label_font": {"size": 24},
        "viz.label_size_for": {"height": 1080},
        "viz.matches_picture": {
            "image_a": IMG_RGB,
            "xy_a": PTS2[:5],
            "image_b": IMG_RGB,
            "xy_b": PTS2[5:10],
            "inliers": np.array([True, False, True, True, False]),
            "distance": np.linspace(0.1, 0.5, 5),
            "homography": np.array([[1.0, 0.1, 2.0], [0.0, 1.0, -3.0], [1e-4, 0.0, 1.0]]),
            "max_matches": 3,
        },
        "viz.select_matches": {
            "n": 5,
            "distance": np.linspace(0.1, 0.5, 5),
            "inliers": np.array([True, False, True, True, False]),
            "max_matches": 3,
        },
        "viz.project_outline": {"homography": np.eye(3), "size": (64, 48)},
    }
)


# tracking.metrics (issue 30): VOT ground truth and the success curve, CLEAR-MOT / IDF1.
# The names are planned once robopercept.tracking exports them (its __init__ lists them).
_VOT_POLY = "10,20,40,20,40,60,10,60\n12,20,42,20,42,60,12,60\nnan,nan,nan,nan\n"
FIXTURES["vot_groundtruth.txt"] = lambda p: p.write_text(_VOT_POLY)
_MOT_ROWS = _b("robopercept.tracking:read_mot", Fixture("mot.txt"))
_SUCCESS = _b("robopercept.tracking.metrics:evaluate_single_object", BOXES, BOXES)
VALID.update(
    {
        "tracking.polygons_to_boxes": {"polygons": np.array([[10.0, 20, 40, 20, 40, 60, 10, 60]])},
        "tracking.read_vot_groundtruth": {"path": Fixture("vot_groundtruth.txt")},
        "tracking.paired_iou": {"a": BOXES, "b": BOXES[::-1].copy()},
        "tracking.evaluate_single_object": {
            "predicted": BOXES,
            "truth": BOXES,
            "frames": np.array([0, 1]),
            "thresholds": np.linspace(0.0, 1.0, 5),
        },
        "tracking.success_plot": {"scores": _SUCCESS, "labels": "run", "size": (320, 240)},
        "tracking.MotAccumulator": {"iou_threshold": 0.5},
        "tracking.MotAccumulator.update": {
            "gt_ids": np.array([1, 2]),
            "gt_boxes": BOXES,
            "hyp_ids": np.array([7, 8]),
            "hyp_boxes": BOXES,
        },
        "tracking.MotAccumulator.metrics": {},
        "tracking.select_ground_truth": {"rows": _MOT_ROWS, "classes": (1,)},
        "tracking.evaluate_mot": {
            "ground_truth": _MOT_ROWS,
            "hypotheses": _MOT_ROWS,
            "iou_threshold": 0.5,
            "frames": np.array([1, 2]),
        },
    }
)
METHODS["tracking.MotAccumulator"] = ("update", "metrics")


# calibration files and point-cloud labels (issue 30): OpenCV FileStorage and ROS YAML
# writers, quaternions and transforms, hand-eye reports, stereo image pairs
def _write_transform(path: Path) -> None:
    """A ROS transform YAML (header.frame_id, child_frame_id, translation, rotation)."""
    from robopercept.calibration import transform_stamped, write_ros_yaml

    write_ros_yaml(path, transform_stamped(np.eye(4), "base_link", "camera"))


FIXTURES["transform.yaml"] = _write_transform
_HAND_EYE = _b(
    "robopercept.calibration:HandEyeResult",
    T4,
    T4,
    "eye_in_hand",
    "tsai",
    np.zeros(1),
    np.zeros(1),
)
VALID.update(
    {
        "calibration.calibration_format": {"path": "camera.yaml", "format": "ros"},
        "calibration.camera_info": {"K": K, "dist": np.zeros(5), "image_size": (64, 48)},
        "calibration.find_board_pairs": {"left": [IMG], "right": [IMG2], "pattern_size": (5, 3)},
        "calibration.hand_eye_format": {"path": "handeye.yaml"},
        "calibration.hand_eye_report": {"result": _HAND_EYE, "metres_per_unit": 0.001},
        "calibration.quaternion_from_rotation": {"R": np.eye(3)},
        "calibration.read_transform": {"path": Fixture("transform.yaml")},
        "calibration.rotation_from_quaternion": {"q": np.array([0.0, 0.0, 0.0, 1.0])},
        "calibration.save_hand_eye": {"path": _out("handeye.json"), "result": _HAND_EYE},
        "calibration.transform_stamped": {
            "T": T4,
            "parent_frame": "base_link",
            "child_frame": "camera",
        },
        "calibration.write_opencv_storage": {
            "path": _out("storage.yml"),
            "data": {"camera_matrix": K, "image_width": 64},
        },
        "calibration.write_ros_yaml": {
            "path": _out("info.yaml"),
            "data": {"rows": 1, "data": [1.0, 2.0]},
        },
        "pointcloud.PointCloud.with_labels": {"labels": np.arange(60)},
    }
)
METHODS["pointcloud.PointCloud"] = ("select", "with_colors", "with_labels")


# motion.flow_truth, viz.flow.arrow_scale (issue 30): Middlebury .flo files, endpoint
# error, the automatic arrow scale of flow pictures
def _write_flo_fixture(path: Path) -> None:
    from robopercept.motion import write_flo

    write_flo(path, FLOW)


FIXTURES["flow.flo"] = _write_flo_fixture
VALID.update(
    {
        "motion.read_flo": {"path": Fixture("flow.flo")},
        "motion.write_flo": {"path": _out("flow.flo"), "flow": FLOW},
        "motion.known_flow": {"flow": FLOW},
        "motion.endpoint_error": {"flow": FLOW + 0.25, "truth": FLOW},
        "viz.arrow_scale": {"flow": np.tile([1.5, -0.5], (40, 1)), "size": (64, 48)},
    }
)


# learning.persist (issue 30): model files (save_model / load_model, never pickle) and
# predicting a CSV table with a saved model
def _write_learn_model(path: Path) -> None:
    """An LDA on the three-blob data with feature and class names and standardization,
    written by save_model."""
    from robopercept.learning import LDA, SavedModel, save_model

    lda = LDA().fit(XB, YB)
    names, classes = ["a", "b", "c", "d"], ["x", "y", "z"]
    save_model(SavedModel(lda, names, classes, "label", XB.mean(0), XB.std(0)), path)


FIXTURES["model.npz"] = _write_learn_model
_BLOB_ROWS = [
    f"r{i},{','.join(map(str, x))},{'xyz'[c]}\n"
    for i, (x, c) in enumerate(zip(XB, YB, strict=True))
]
FIXTURES["blobs.csv"] = lambda p: p.write_text("id,a,b,c,d,label\n" + "".join(_BLOB_ROWS))
VALID.update(
    {
        "learning.SavedModel": {
            "model": "fitted:SVC",
            "feature_names": ["a", "b", "c", "d"],
            "class_names": ["x", "y", "z"],
            "label_column": "label",
            "mean": XB.mean(0),
            "scale": XB.std(0),
            "info": {"note": "fuzz"},
        },
        "learning.SavedModel.predict": {"X": XB},
        "learning.SavedModel.transform": {"X": XB},
        "learning.save_model": {"model": "fitted:SVC", "path": _out("model.npz")},
        "learning.load_model": {"path": Fixture("model.npz")},
        "learning.predict_table": {
            "model": _b("robopercept.learning:load_model", Fixture("model.npz")),
            "path": Fixture("blobs.csv"),
            "label": "label",
        },
        "learning.read_npz": {"path": Fixture("model.npz")},
        "learning.read_features": {"path": Fixture("table.csv"), "names": ["b", "a"]},
        "learning.standard_scaling": {"train": XB},
    }
)
METHODS["learning.SavedModel"] = ("predict", "transform")


# viz.plot / viz.learning (issue 30): matplotlib plots, their figures and scalar maps
def plot_panels() -> Any:
    """Two panels of the plot_series kind: a line with a gap and dots (valid panels)."""
    from robopercept.viz.plot import Panel, Series

    t = np.arange(12.0)
    y = np.sin(t)
    y[4:6] = np.nan
    return [
        Panel("a", [Series(t, y, "line"), Series(t, y * 0.5, "dots", (214, 39, 40), "dots")], "y"),
        Panel("b", [Series(t, t**0.5, "sqrt")], "d [m]"),
    ]


_PLOT_PANELS = _b("tests.fuzz.api:plot_panels")
_MAP = np.tile(np.arange(16.0), (12, 1))
_MAP[2:4, 3:6] = np.nan
_CURVES = [(np.linspace(0, 1, 5), np.linspace(0, 1, 5) ** 2, "a")]
VALID.update(
    {
        "viz.Panel": {"title": "p", "series": [], "ylabel": "y [m]"},
        "viz.Series": {"x": np.arange(5.0), "y": np.arange(5.0), "label": "s"},
        "viz.plot_series": {"panels": _PLOT_PANELS, "width": 300, "panel_height": 120},
        "viz.series_figure": {"panels": _PLOT_PANELS, "width": 300, "panel_height": 120},
        "viz.scalar_map_picture": {"values": _MAP, "width": 300, "height": 200},
        "viz.scalar_map_figure": {"values": _MAP, "width": 300, "height": 200},
        "viz.curves_figure": {
            "curves": _CURVES,
            "title": "t",
            "xlabel": "x",
            "ylabel": "y",
            "width": 200,
            "height": 160,
        },
        "viz.scatter_figure": {"points": PTS2, "labels": Y2, "width": 200, "height": 160},
        "viz.confusion_figure": {"matrix": np.array([[5, 1], [2, 7]]), "names": ["a", "b"]},
        "viz.readable_dpi": {"width": 640, "height": 480},
    }
)

# motion.differencing (issue 30): the three-frame difference fills the holes of its mask
VALID.update({"motion.fill_holes": {"mask": MASK}})

# -- geometry.min_area_rectangle (the plane tracker's board outline) --------------------
VALID.update(
    {
        "geometry.min_area_rectangle": {
            "points": np.array([[0.0, 1.0], [1.0, 0.0], [2.0, 1.0], [1.0, 2.0]])
        }
    }
)

# -- nn.train.distributed (issue 31): DDP training on several processes ----------------------
VALID.update(
    {
        "nn.train.distributed.free_port": {"host": "127.0.0.1"},
        "nn.train.distributed.torchrun_env": {"environ": {}},
        "nn.train.distributed.check_world_batch": {"nproc": 2, "batch_size": 64},
        "nn.train.distributed.rank_device": {"cfg": TRAIN_CFG},
    }
)
SKIP.update(
    {
        "nn.train.distributed.run_ranks": "starts processes joined in a process group (seconds "
        "per call); its argument checks and a failing rank are tested in "
        "tests/nn/train/test_distributed.py",
        "nn.classification.run.train_ddp": "trains a network on several processes (tens of "
        "seconds per call); its checks are tested in tests/nn/classification/test_run.py",
        "nn.detection.base.check_targets": "a detector's boundary check, given images and "
        "num_classes already checked by the detector; fuzzed through every detector's forward",
        "nn.detection.base.check_proposals": "a detector's boundary check, given the checked "
        "image sizes; fuzzed through FastRCNN.forward and RCNN.forward",
        "nn.detection.base.clip_boxes": "an internal step of the detectors on boxes they made; "
        "fuzzed through every detector's forward",
        "nn.detection.base.init_conv": "initializes a layer the detector built; fuzzed through "
        "the FCOS and FasterRCNN constructors",
        "nn.detection.train.detections_per_image": "an internal step of evaluate_detector and "
        "evaluate_localizer on a checked model and dataset; fuzzed through them",
    }
)

# -- nn.shipped and nn.predict (issue 31): the shipped models, one image-predict path
_IP_VALUES = {
    "boxes": np.array([[2.0, 3.0, 20.0, 30.0]]),
    "labels": np.array([1]),
    "scores": np.array([0.75]),
}
VALID.update(
    {
        "nn.shipped.shipped_model_path": {"kind": "detect", "name": "fcos"},
        "nn.shipped.resolve_model": {"kind": "segment", "model": "unet"},
        "nn.predict.load_image_predictor": {
            "kind": "detect",
            "model": Fixture("detector.pt"),
            "device": "cpu",
            "score_thresh": 0.5,
        },
        "nn.predict.load_segment_model": {"path": Fixture("segmenter.pt")},
        "nn.predict.ImagePrediction": {
            "kind": "detect",
            "image": IMG_RGB,
            "classes": ["a", "b"],
            "values": _IP_VALUES,
        },
        "nn.predict.ImagePrediction.coco_results": {"image_id": 1},
        "nn.predict.ImagePrediction.pictures": {"stem": "ip"},
        "nn.predict.ImagePrediction.write": {"out_dir": _out("image_predict"), "stem": "ip"},
        "nn.predict.ImagePredictor": {
            "kind": "detect",
            "path": None,
            "model": _b("robopercept.nn.detection.zoo:build_detector", "fcos", 2, width=4),
            "info": {"classes": ["a", "b"]},
        },
        "nn.predict.ImagePredictor.predict": {"image": IMG_RGB},
        "nn.predict.ImagePredictor.predict_file": {"path": Fixture("image.png")},
    }
)
METHODS["nn.predict.ImagePrediction"] = ("record", "coco_results", "pictures", "write")
METHODS["nn.predict.ImagePredictor"] = ("predict", "predict_file")

# viz.plot.disparity_picture (issue 31: robopercept stereo and batch stereo)
VALID.update({"viz.disparity_picture": {"disparity": _MAP, "max_disparity": 8}})


# nn.classification.run.predict_loaded (issue 31: batch nn-predict loads a run once per worker)
def loaded_run(part: int) -> Any:
    """``load_run``'s model (0) or architecture (1) of a tiny digits run."""
    from robopercept.nn.classification.saved import load_run

    # the shared run fixture (made once), not a new training run per call
    return load_run(Fixture("run/checkpoint.pt").make(), device="cpu")[part]


VALID.update(
    {
        "nn.classification.run.predict_loaded": {
            "model": _b("tests.fuzz.api:loaded_run", 0),
            "arch": _b("tests.fuzz.api:loaded_run", 1),
            "image_paths": [Fixture("image.png")],
        }
    }
)


# -- issue 46: models useful on real inputs (tiling, thresholds, cards, one Python path)
def box_per_window() -> Any:
    """A detector of one window: one box at its centre (for the tiling plans)."""
    return _box_per_window


def _box_per_window(window: np.ndarray) -> dict[str, np.ndarray]:
    h, w = window.shape[:2]
    box = np.array([[w / 2 - 2, h / 2 - 2, w / 2 + 2, h / 2 + 2]])
    return {"boxes": box, "labels": np.array([1]), "scores": np.array([0.9])}


def threshold_value() -> Any:
    """A window's class map: bright pixels (for the tiled segmentation plan)."""
    return _bright


def _bright(window: np.ndarray) -> np.ndarray:
    x = np.asarray(window, np.float64).reshape((*window.shape[:2], -1))
    return (x.mean(-1) > 0.5).astype(np.int64)


_DETS = [
    {
        "boxes": np.array([[0.0, 0, 10, 10], [20.0, 20, 30, 30]]),
        "labels": np.array([1, 1]),
        "scores": np.array([0.9, 0.4]),
    }
]
_TRUTHS = [{"boxes": np.array([[0.0, 0, 10, 10]]), "labels": np.array([1])}]
VALID.update(
    {
        "nn.detection.tiling.tile_origins": {"length": 1000, "tile": 400, "overlap": 100},
        "nn.detection.tiling.tile_windows": {
            "height": 500,
            "width": 300,
            "tile": 400,
            "overlap": 100,
        },
        "nn.detection.tiling.check_tiling": {"tile": 400, "overlap": 100},
        "nn.detection.tiling.detect_tiled": {
            "detect": _b("tests.fuzz.api:box_per_window"),
            "image": IMG_RGB,
            "tile": 32,
            "overlap": 8,
            "nms_thresh": 0.5,
        },
        "nn.detection.tiling.segment_tiled": {
            "segment": _b("tests.fuzz.api:threshold_value"),
            "image": IMG_RGB,
            "tile": 32,
            "overlap": 8,
        },
        "nn.detection.thresholds.choose_score_threshold": {
            "detections": _DETS,
            "truths": _TRUTHS,
            "iou": 0.5,
        },
        "nn.detection.thresholds.f1_threshold": {
            "scores": np.array([0.9, 0.5, 0.2]),
            "hits": np.array([True, False, True]),
            "positives": 3,
        },
        "nn.detection.thresholds.domain_warning": {
            "best": 0.3,
            "calibration": {"score_thresh": 0.4, "match_median": 0.7},
            "model_name": "m",
            "trained_on": "x",
        },
        "nn.detection.thresholds.input_warning": {
            "image": IMG_RGB,
            "info": {"canvas": [16, 16], "input_colour": "grey"},
            "model_name": "m",
            "trained_on": "x",
        },
        "nn.detection.zoo.calibrate_detector": {
            "model": _b("robopercept.nn.detection.zoo:build_detector", "fcos", 1, width=4),
            "dataset": _DDS,
        },
        "nn.detection.deepforest.deepforest_strip": {"folder": Fixture("deepforest")},
        "nn.pose.evaluate.joint_threshold": {"model": _POSE_NET, "data": _POSE_DS},
        "nn.shipped.model_card": {"name": "trees"},
        "nn.shipped.domain_line": {"kind": "detect", "model": "trees"},
        "nn.predict.load_predictor": {"model": "fcos", "device": "cpu"},
    }
)
SKIP.update(
    {
        "nn.train.checkpoint.update_checkpoint": "rewrites a checkpoint file in place: its "
        "reading and writing are load_checkpoint's and save_checkpoint's, both fuzzed",
        "nn.shipped.ModelCard": "a model card of the shipped table, built by the library "
        "(MODEL_CARDS); model_card and domain_line, which read it, are fuzzed",
    }
)
VALID.update(
    {
        "nn.train.distributed.SyncBatchNorm": {"num_features": 3},
        "nn.train.distributed.sync_batchnorm": {"model": TINY_NET},
    }
)


def _labelme_folder(p: Path) -> None:
    """A labelme folder: one 10 x 8 image and its file with one rectangle."""
    from robopercept.imaging import write_image

    p.mkdir()
    write_image(p / "a.png", np.zeros((8, 10, 3), np.uint8))
    _labelme_file(p / "a.json")


def _labelme_file(p: Path) -> None:
    doc = {"imagePath": "a.png", "imageHeight": 8, "imageWidth": 10, "shapes": [
        {"label": "cat", "points": [[1, 2], [5, 6]], "shape_type": "rectangle", "group_id": None}
    ]}  # fmt: skip
    p.write_text(json.dumps(doc))


def _voc_masks_folder(p: Path) -> None:
    """A VOC segmentation folder: one 8 x 6 image with one instance of class 15."""
    from robopercept.imaging import write_image

    for d in ("SegmentationObject", "SegmentationClass", "JPEGImages"):
        (p / d).mkdir(parents=True)
    obj = np.zeros((6, 8), np.uint8)
    obj[1:4, 2:6] = 1
    write_image(p / "SegmentationObject" / "a.png", obj)
    write_image(p / "SegmentationClass" / "a.png", obj * 15)
    write_image(p / "JPEGImages" / "a.png", np.zeros((6, 8, 3), np.uint8))


def labelme_value() -> Any:
    """A list of one LabelmeAnnotation (a 4 x 4 square labelled cat)."""
    from robopercept.nn.coco.folders import LabelmeAnnotation, LabelmeShape

    sq = np.array([[0.0, 0], [4, 0], [4, 4], [0, 4]])
    return [LabelmeAnnotation("a.png", 10, 8, (LabelmeShape("cat", sq, None, "polygon"),))]


FIXTURES.update(
    {
        "labelme.json": _labelme_file,
        "labelme_folder": _labelme_folder,
        "voc_masks": _voc_masks_folder,
    }
)
VALID.update(
    {
        "nn.coco.folders.read_labelme_json": {"path": Fixture("labelme.json")},
        "nn.coco.folders.labelme_to_coco": {"annotations": _b("tests.fuzz.api:labelme_value")},
        "nn.coco.folders.read_voc_segmentation": {"folder": Fixture("voc_masks")},
        "nn.coco.folders.read_annotations": {"path": Fixture("labelme_folder")},
    }
)


def _pose_coco_file(p: Path) -> None:
    """A COCO keypoint file with one person in a 40 x 40 image beside it."""
    from robopercept.imaging import write_image

    write_image(p.parent / "pose_a.png", np.zeros((40, 40, 3), np.uint8))
    doc = {
        "images": [{"id": 1, "file_name": "pose_a.png", "width": 40, "height": 40}],
        "categories": [{"id": 1, "name": "person", "keypoints": ["a", "b"], "skeleton": [[1, 2]]}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [5, 5, 20, 20],
                         "keypoints": [10, 10, 2, 15, 20, 2]}],
    }  # fmt: skip
    p.write_text(json.dumps(doc))


FIXTURES["pose_coco.json"] = _pose_coco_file
VALID.update(
    {
        "nn.pose.crops.crop_window": {"box": [5.0, 5.0, 20.0, 10.0], "size": (32, 32)},
        "nn.pose.crops.pose_set_from_coco": {"path": Fixture("pose_coco.json"), "size": (32, 32)},
    }
)
VALID.update(
    {
        "nn.classification.run.class_probabilities": {
            "model": _b("tests.fuzz.api:loaded_run", 0),
            "arch": _b("tests.fuzz.api:loaded_run", 1),
            "image": np.zeros((8, 8), np.uint8),
        },
        "nn.cloud.data.sample_cloud": {
            "points": np.random.default_rng(0).normal(size=(40, 3)),
            "n_points": 16,
        },
        "nn.predict_class.load_class_predictor": {"kind": "cloud", "model": "pointnet"},
    }
)
VALID.update(
    {
        "nn.predict_class.ClassPrediction": {
            "source": "a.off",
            "probabilities": {"box": 0.7, "cone": 0.3},
            "points": np.random.default_rng(0).normal(size=(32, 3)).astype(np.float32),
        },
        "nn.predict_class.ClassPrediction.top": {"k": 1},
        "nn.predict_class.ClassPrediction.write": {"out_dir": _out("class_predict"), "stem": "c"},
        "nn.predict_class.ClassPredictor": {
            "kind": "cloud",
            "name": "m",
            "model": _b("robopercept.nn.cloud.train:build_cloud_model", "pointnet", 2, width=0.25),
            "info": {"class_names": ["a", "b"]},
            "n_points": 32,
        },
        "nn.predict_class.ClassPredictor.predict": {
            "x": np.random.default_rng(0).normal(size=(40, 3))
        },
    }
)
METHODS["nn.predict_class.ClassPrediction"] = ("record", "top", "picture", "write")
METHODS["nn.predict_class.ClassPredictor"] = ("predict",)
VALID["nn.segmentation.run.padded_class_maps"] = {"ds": _b("tests.fuzz.api:segmentation_val")}


# -- issue 47: hostile inputs that every run tries, whatever the draw ---------------------
# Values a random draw reaches rarely, from the campaign that found R50-R53: boxes with
# corners at 1e31 (int64 overflow once scaled to feature-map cells), a stride of 0 or
# None, a batch of no image, a bare number as a size. Each is run before the drawn
# inputs of its plan (in `make test` and in the first round of `make fuzz`).
_HUGE_ROI = hs.TensorOf(np.array([[0.0, 0.0, 0.0, 1e31, 1e31]]), "float64")
_NEG_ROI = hs.TensorOf(np.array([[0.0, -1e31, -1e31, 4.0, 4.0]]), "float64")
_HUGE_BOXES = hs.TensorOf(np.array([[0.0, 0.0, 1e31, 1e31], [1.0, 1.0, 5.0, 6.0]]), "float64")
_EMPTY_FEATURES = _b("tests.fuzz.api:torch_image", 0, 2, 8, 8)
PINNED: dict[str, tuple[tuple[str, Any], ...]] = {
    "nn.ops.roi.roi_align": (  # R50
        ("boxes", _HUGE_ROI),
        ("boxes", _NEG_ROI),
        ("input", _EMPTY_FEATURES),
    ),
    "nn.ops.roi.RoIAlign.forward": (("boxes", _HUGE_ROI),),  # R50
    "nn.ops.roi.roi_pool": (("boxes", _HUGE_ROI), ("boxes", _NEG_ROI)),
    "nn.ops.roi.RoIPool.forward": (("boxes", _HUGE_ROI),),
    "nn.ops.roi.paste_masks": (("boxes", _HUGE_BOXES),),
    "nn.ops.nms.nms": (
        ("boxes", _HUGE_BOXES),
        ("boxes", hs.TensorOf(np.array([[0.0, 0, 4, 4], [1, 1, 5, 6], [2, 0, 7, 3]]), "bfloat16")),
    ),
    "nn.ops.nms.batched_nms": (("boxes", _HUGE_BOXES),),
    "nn.ops.boxes.box_iou": (("boxes1", _HUGE_BOXES),),
    "nn.ops.boxes.generalized_box_iou": (("boxes1", _HUGE_BOXES),),
    "nn.ops.boxes.box_area": (("boxes", _HUGE_BOXES),),
    "nn.ops.anchors.BoxCoder.decode": (("boxes", _HUGE_BOXES),),
    "nn.coco.rle.rle_from_counts": (("size", 7), ("size", None)),  # R51
    "nn.ops.heatmaps.gaussian_heatmaps": (("stride", 0), ("stride", None)),  # R52
    "nn.ops.heatmaps.decode_heatmaps": (  # R53
        ("heatmaps", Layout(np.zeros((0, 2, 4, 5)))),
        ("heatmaps", Layout(np.zeros((1, 0, 4, 5)))),
        ("stride", 0),
    ),
    "nn.pose.inference.predict_heatmaps": (("images", Layout(np.zeros((0, 32, 32, 3)))),),
    # the third full campaign (94,246 inputs): untyped errors, typed since
    "nn.train.distributed.SyncBatchNorm": (("device", Layout(np.eye(3))),),
    "nn.segmentation.networks.train_segmenter": (
        ("class_weights", "object"),
        ("class_weights", [1.0, 2.0, 3.0]),
        ("class_weights", [1.0, -1.0]),
    ),
    "nn.pose.evaluate.evaluate_pose": (("alphas", (0.05, [1, 2], 0.2)),),
    "nn.cloud.train.save_cloud_model": (("part_classes", float("nan")), ("part_classes", [5])),
    # the fourth (128,109 inputs)
    "nn.detection.run.evaluate_run": (("out_dir", Fixture("image.png")),),
    "nn.segmentation.run.evaluate_run": (("out_dir", Fixture("image.png")),),
    "nn.pose.run.evaluate_run": (("out_dir", Fixture("image.png")),),
    "nn.cloud.run.evaluate_run": (("out_dir", Fixture("image.png")),),
    "nn.pose.networks.save_pose_model": (("refiners", 3),),
    "nn.pose.inference.pose_arrays": (("images", 3),),
}


def state_dict_of(model: Any) -> dict[str, Any]:
    """The state dict of a built model (check_state_dict's valid weights)."""
    return dict(model.state_dict())


# issue 47 (R39-R41): the one validation of every loader of weights
VALID["nn.train.checkpoint.check_state_dict"] = {
    "model": TINY_NET,
    "weights": _b("tests.fuzz.api:state_dict_of", TINY_NET),
    "where": "checkpoint.pt",
}
