"""Every compiled (numba) kernel against its own reference path, on small inputs.

A numba ``Dispatcher`` keeps the plain Python function it compiles as ``.py_func``;
run by the interpreter, with NumPy scalars and arrays, that function is the kernel's
reference path (DESIGN.md section 1: "a compiled kernel ... has a NumPy reference path
that a test compares it with on small inputs").

:func:`reference_kernels` swaps, for the duration of a block, every dispatcher bound
at module level in every ``robopercept`` module with a recording wrapper around its
``py_func``. Kernels that call other kernels look those names up in their module's
globals when they run as Python, so swapping the globals covers nested kernels too
(the compiled outer kernel would have bound the inner one at compile time).

Each case in :data:`CASES` runs a public function on a tiny deterministic input twice,
compiled and under :func:`reference_kernels`, and compares the results: integers and
booleans exactly; floats with the tolerance written beside the case (see
:data:`F32` and :data:`F64` for the defaults and why they are not zero).
:func:`test_every_kernel_is_exercised` then discovers every dispatcher in the package
(nothing is listed by hand) and fails, naming them, if one was not run by any case:
add a case when you add a kernel.

``numba.prange`` runs as ``range`` in the interpreter, so parallel kernels are
compared too; kernels whose reductions are split across threads are compared with a
float tolerance.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import pkgutil
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

import robopercept

# Default float tolerances. The interpreter and the compiler evaluate the same formulas
# in a different order and precision: numba promotes float32 * float64-literal to
# float64 before storing back to float32 while NumPy 2 scalars stay float32, LLVM
# contracts a * b + c into one fused multiply-add, and ``fastmath`` kernels reassociate
# sums. float32 results therefore agree to a few float32 ulps, float64 ones to ~1e-12
# relative; the cases that need more say so.
F32 = {"rtol": 1e-5, "atol": 1e-5}
F64 = {"rtol": 1e-9, "atol": 1e-9}

#: dispatchers deliberately not compared, with the reason (keep this short)
EXCLUDED: dict[str, str] = {}


# -- the harness -----------------------------------------------------------------------


_MODULES: list[Any] = []


def _modules() -> list[Any]:
    """Every module of the package, imported once (``nn`` only when torch is installed)."""
    if not _MODULES:
        _MODULES.append(robopercept)
        prefix = robopercept.__name__ + "."
        for info in pkgutil.walk_packages(robopercept.__path__, prefix):
            if info.name.split(".")[1] == "nn" and importlib.util.find_spec("torch") is None:
                continue
            _MODULES.append(importlib.import_module(info.name))
    return _MODULES


def _ours(obj: Any) -> bool:
    return isinstance(obj, CPUDispatcher) and obj.py_func.__module__.startswith("robopercept")


def all_kernels() -> dict[str, CPUDispatcher]:
    """Every compiled kernel of the package: ``module.name`` -> dispatcher.

    A kernel is named after the global it is bound to in the module that defines it
    (a kernel made by a factory, like ``imaging.filters._taps1``, has its own name
    even though its ``__qualname__`` is shared with its siblings); imports of it into
    other modules are the same object and do not count twice.
    """
    found: dict[int, tuple[tuple[bool, bool], str, CPUDispatcher]] = {}
    for mod in _modules():
        for name, value in vars(mod).items():
            if _ours(value):
                # prefer the binding in the defining module, then the function's own name
                rank = (value.py_func.__module__ != mod.__name__, name != value.__name__)
                if id(value) not in found or rank < found[id(value)][0]:
                    found[id(value)] = (rank, f"{mod.__name__}.{name}", value)
    return {key: value for _, key, value in found.values()}


@contextlib.contextmanager
def reference_kernels(called: set[str] | None = None) -> Iterator[set[str]]:
    """Run every robopercept kernel as plain Python (its ``py_func``) inside the block.

    Yields the set of kernel names (as :func:`all_kernels` names them) called inside
    the block (the ``called`` set given, or a new one).
    """
    called = set() if called is None else called
    names = {id(d): name for name, d in all_kernels().items()}
    wrappers: dict[int, Callable[..., Any]] = {}

    def wrap(d: CPUDispatcher) -> Callable[..., Any]:
        key, py_func = names[id(d)], d.py_func

        def run(*args: Any, **kwargs: Any) -> Any:
            called.add(key)
            return py_func(*args, **kwargs)

        return wrappers.setdefault(id(d), run)

    saved = []
    try:
        for mod in _modules():
            for name, value in list(vars(mod).items()):
                if _ours(value):
                    saved.append((mod, name, value))
                    setattr(mod, name, wrap(value))
        with np.errstate(all="ignore"):  # compiled code raises no floating-point warnings
            yield called
    finally:
        for mod, name, value in saved:
            setattr(mod, name, value)


def assert_same(compiled: Any, reference: Any, rtol: float, atol: float, path: str = "") -> None:
    """Compare two results field by field: exact for integers, bools and strings;
    ``rtol``/``atol`` for floats (each float array gets its dtype's default unless the
    case gives its own)."""
    where = path or "result"
    if dataclasses.is_dataclass(compiled) and not isinstance(compiled, type):
        assert type(compiled) is type(reference), where
        for f in dataclasses.fields(compiled):
            assert_same(
                getattr(compiled, f.name),
                getattr(reference, f.name),
                rtol,
                atol,
                f"{where}.{f.name}",
            )
    elif isinstance(compiled, dict):
        assert compiled.keys() == reference.keys(), where
        for k in compiled:
            assert_same(compiled[k], reference[k], rtol, atol, f"{where}[{k!r}]")
    elif isinstance(compiled, list | tuple):
        assert len(compiled) == len(reference), f"{where}: lengths differ"
        for i, (a, b) in enumerate(zip(compiled, reference, strict=True)):
            assert_same(a, b, rtol, atol, f"{where}[{i}]")
    elif isinstance(compiled, np.ndarray | np.generic | int | float | bool):
        a, b = np.asarray(compiled), np.asarray(reference)
        assert a.shape == b.shape, f"{where}: shapes {a.shape} != {b.shape}"
        if a.dtype.kind in "fc" or b.dtype.kind in "fc":
            np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, err_msg=where)
        else:
            np.testing.assert_array_equal(a, b, err_msg=where)
    elif compiled is None or isinstance(compiled, str | bytes):
        assert compiled == reference, where
    elif hasattr(compiled, "__dict__"):
        assert type(compiled) is type(reference), where
        assert_same(vars(compiled), vars(reference), rtol, atol, where)
    else:
        raise TypeError(f"{where}: cannot compare {type(compiled).__name__}")


@dataclasses.dataclass(frozen=True)
class Case:
    """One public call on a small input; ``tol`` overrides the float tolerance."""

    name: str
    run: Callable[[], Any]
    tol: dict[str, float] | None = None
    why: str = ""  # the reason for a non-default tolerance


#: name -> kernels its reference run called (filled as the cases run)
CALLED: dict[str, set[str]] = {}


def _tolerance(case: Case, result: Any) -> dict[str, float]:
    if case.tol is not None:
        return case.tol
    return F32 if _has_float32(result) else F64


def _has_float32(x: Any) -> bool:
    if isinstance(x, np.ndarray | np.generic):
        return x.dtype == np.float32
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return any(_has_float32(getattr(x, f.name)) for f in dataclasses.fields(x))
    if isinstance(x, dict):
        return any(_has_float32(v) for v in x.values())
    if isinstance(x, list | tuple):
        return any(_has_float32(v) for v in x)
    return False


def run_case(case: Case) -> None:
    compiled = case.run()
    with reference_kernels() as called:
        reference = case.run()
    CALLED[case.name] = called
    assert called, f"{case.name} called no compiled kernel: the case tests nothing"
    assert_same(compiled, reference, **_tolerance(case, compiled))


# -- small deterministic inputs --------------------------------------------------------


def _scene(h: int = 24, w: int = 32, seed: int = 0) -> np.ndarray:
    """A float image in [0, 1]: two rectangles, a disc and a little noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    img = 0.2 + 0.05 * rng.random((h, w))
    img[h // 5 : h // 2, w // 6 : w // 2] = 0.8
    img[(y - 0.65 * h) ** 2 + (x - 0.7 * w) ** 2 < (0.2 * h) ** 2] = 0.6
    img[3 * h // 4 :, : w // 4] = 0.95
    return img


GRAY = _scene()
GRAY_U8 = np.round(GRAY * 255).astype(np.uint8)
GRAY_F32 = GRAY.astype(np.float32)
RGB_U8 = np.stack([GRAY_U8, np.roll(GRAY_U8, 5, axis=1), 255 - GRAY_U8], axis=-1)
RGB = RGB_U8 / 255.0


def _shifted(img: np.ndarray, dx: float) -> np.ndarray:
    """``img`` moved right by ``dx`` pixels (linear interpolation, edge clamped)."""
    w = img.shape[1]
    x = np.clip(np.arange(w) - dx, 0, w - 1)
    x0 = np.floor(x).astype(int)
    x1 = np.minimum(x0 + 1, w - 1)
    f = x - x0
    return img[:, x0] * (1 - f) + img[:, x1] * f


# -- the cases -------------------------------------------------------------------------


def _imaging_cases() -> list[Case]:
    from robopercept.imaging import (
        blob_features,
        box_filter,
        canny,
        correlate,
        gaussian_blur,
        hsv_to_rgb,
        label_components,
        laplacian,
        median_filter,
        remap,
        rgb_to_hsv,
        sobel,
        warp_perspective,
    )
    from robopercept.imaging.filters import separable_filter_unchecked

    k5 = np.arange(25.0).reshape(5, 5) / 300.0
    hom = np.array([[1.05, 0.05, -1.0], [-0.03, 0.97, 0.5], [1e-3, -5e-4, 1.0]])
    yy, xx = np.mgrid[0:20, 0:28].astype(np.float32)
    mask = GRAY > 0.5
    return [
        Case("gaussian_blur_f64", lambda: gaussian_blur(GRAY, 1.2)),
        Case("gaussian_blur_f32", lambda: gaussian_blur(GRAY_F32, 0.8, sigma_y=1.5)),
        Case(
            "gaussian_blur_f32_rgb",
            lambda: gaussian_blur(RGB_U8.astype(np.float32) / 255, 1.4, border="constant"),
        ),
        Case("gaussian_blur_u8", lambda: gaussian_blur(GRAY_U8, 2.0, border="constant")),
        Case("gaussian_blur_u8_rgb", lambda: gaussian_blur(RGB_U8, 1.1, sigma_y=2.3)),
        Case("box_filter", lambda: box_filter(GRAY_U8, (4, 3), normalize=False)),
        Case("box_filter_f32", lambda: box_filter(GRAY_F32, 5, border="replicate")),
        Case("box_filter_u8", lambda: box_filter(GRAY_U8, (5, 3), border="constant")),
        Case("box_filter_u8_rgb", lambda: box_filter(RGB_U8, 7)),
        Case("correlate_2d", lambda: correlate(GRAY, k5, border="reflect")),
        Case("correlate_2d_u8", lambda: correlate(GRAY_U8, k5, border="constant", cval=9)),
        Case("median_3", lambda: median_filter(GRAY_U8, 3)),
        Case("median_5", lambda: median_filter(GRAY_F32, 5, border="reflect101")),
        Case("median_3_rgb", lambda: median_filter(RGB_U8, 3, border="reflect")),
        Case("median_5_rgb", lambda: median_filter(RGB_U8, 5)),
        Case("median_7", lambda: median_filter(GRAY_U8, 7)),
        Case("sobel", lambda: sobel(GRAY_U8, 1, 0, 5)),
        Case("sobel_rgb_int16", lambda: sobel(RGB_U8, 0, 1, 3, border="constant")),
        Case("laplacian", lambda: laplacian(GRAY_F32, 3)),
        Case("canny", lambda: canny(GRAY_U8, 20, 60)),
        Case("canny_l1", lambda: canny(GRAY, 0.05, 0.2, l2_gradient=False)),
        Case("rgb_to_hsv_u8", lambda: rgb_to_hsv(RGB_U8)),
        Case("rgb_to_hsv_f64", lambda: rgb_to_hsv(RGB)),
        Case("hsv_round_trip", lambda: hsv_to_rgb(rgb_to_hsv(RGB_U8))),
        Case("label_8", lambda: label_components(mask, 8)),
        Case("label_4", lambda: label_components(mask, 4)),
        Case("blob_features", lambda: blob_features(label_components(mask)[0])),
        Case("warp_linear", lambda: warp_perspective(GRAY_F32, hom, (22, 30))),
        Case(
            "warp_nearest_rgb",
            lambda: warp_perspective(RGB_U8, hom, (22, 30), interpolation="nearest"),
        ),
        Case(
            "separable_2_channels",
            lambda: separable_filter_unchecked(
                np.stack([GRAY, 1 - GRAY], -1),
                np.array([0.25, 0.5, 0.25]),
                np.array([1.0, 0.0, -1.0]),
                "constant",
                0.5,
            ),
        ),
        Case("remap", lambda: remap(GRAY_U8, xx * 1.1 + 0.3, yy * 0.9 + 0.7, border_value=7)),
    ]


def _features_cases() -> list[Case]:
    from robopercept.features import harris_corners, hog, knn_match, refine_corners, sift
    from robopercept.features.hog import cell_histograms, hog_windows
    from robopercept.imaging.segmentation import felzenszwalb

    rng = np.random.default_rng(3)
    bits_q = rng.integers(0, 256, (40, 32), dtype=np.uint8)
    bits_t = rng.integers(0, 256, (60, 32), dtype=np.uint8)
    big = _scene(48, 56, seed=1)
    corners = np.array([[5.3, 4.6], [16.2, 11.7], [21.5, 15.4]])
    return [
        Case("harris", lambda: harris_corners(GRAY, min_distance=3, subpixel=True)),
        Case(
            "shi_tomasi",
            lambda: harris_corners(GRAY_U8, method="shi-tomasi", min_distance=2, max_corners=8),
        ),
        Case("harris_gaussian", lambda: harris_corners(GRAY_F32, window="gaussian", sigma=1.0)),
        Case("refine_corners", lambda: refine_corners(GRAY, corners, 3)),
        Case("hog_opencv", lambda: hog(GRAY_U8, cell_size=4)),
        Case("hog_skimage", lambda: hog(GRAY, cell_size=4, convention="skimage", block_norm="L1")),
        Case("hog_windows", lambda: hog_windows(GRAY_U8, (16, 16), 8, cell_size=4)),
        Case(
            "cell_histograms",
            lambda: cell_histograms(GRAY_U8, 4),
            F32,
            "float64 output of float32 gradients and angles (atan2_deg is float32)",
        ),
        Case("knn_hamming", lambda: knn_match(bits_q, bits_t, 2, metric="hamming")),
        Case("sift", lambda: sift(big, contrast_threshold=0.01)),
        Case("felzenszwalb", lambda: felzenszwalb(RGB_U8, scale=50, min_size=5)),
    ]


def _motion_cases() -> list[Case]:
    from robopercept.motion import (
        AveragedBackground,
        GaussianBackground,
        StaticBackground,
        clean_mask,
        dense_flow,
        lucas_kanade,
    )

    moved = _shifted(GRAY, 0.7)
    pts = np.array([[8.0, 6.0], [16.0, 9.0], [22.0, 15.0], [10.0, 18.0]])
    frames = [np.clip(GRAY_U8.astype(int) + 9 * i, 0, 255).astype(np.uint8) for i in range(4)]

    def backgrounds() -> list[np.ndarray]:
        out = []
        for model in (
            StaticBackground(frames[0], 10),
            AveragedBackground(2, 10),
            GaussianBackground(init_frames=2),
        ):
            out += [model.apply(f) for f in frames]
        return out

    return [
        Case(
            "lucas_kanade",
            lambda: lucas_kanade(GRAY, moved, pts, window=7, levels=2),
            F32,
            "fastmath kernels over float32 pyramids: sums reassociated",
        ),
        Case(
            "dense_flow",
            lambda: dense_flow(GRAY_U8, (moved * 255).round().astype(np.uint8), step=6, window=7),
            F32,
            "as lucas_kanade",
        ),
        Case("backgrounds", backgrounds),
        Case("clean_mask_median", lambda: clean_mask(GRAY > 0.5, "median", 5)),
    ]


def _estimation_cases() -> list[Case]:
    from robopercept.estimation import PlaneModel, fit_plane_inverse_depth, ransac
    from robopercept.estimation.least_squares import scatter_matrix

    rng = np.random.default_rng(4)
    pts = rng.normal(size=(200, 3)) * [1.0, 1.0, 0.01]
    pts[:30] = rng.normal(size=(30, 3))
    keep = rng.random(200) < 0.6
    front = pts + np.array([0.0, 0.0, 2.0])  # in front of the camera for the inverse-depth fit
    from robopercept.estimation.least_squares import slab_inliers
    from robopercept.pipelines.plane_measure import _take_rows, pixel_solidity_masked

    def slab_parallel(points: np.ndarray, within: np.ndarray) -> list[Any]:
        from robopercept.estimation import least_squares

        out = np.empty(points.shape[0], dtype=bool)
        sums = least_squares._slab_kernel(points, 0.0, 0.0, 1.0, 2.0, 0.02, within, True, out)
        return [*sums, out]

    blob = np.zeros((12, 16), dtype=bool)
    blob[2:9, 3:12] = True
    blob[5, 14] = blob[10, 1] = True  # specks widen the hull
    blob_pixels = np.flatnonzero(blob)
    blob_keep = np.random.default_rng(5).random(blob_pixels.size) < 0.8
    return [
        Case("pixel_solidity", lambda: pixel_solidity_masked(blob_pixels, None, 16)),
        Case("pixel_solidity_mask", lambda: pixel_solidity_masked(blob_pixels, blob_keep, 16)),
        Case("inverse_depth_plane", lambda: fit_plane_inverse_depth(front, keep)),
        Case("scatter_matrix", lambda: scatter_matrix(pts)),
        Case("scatter_matrix_mask", lambda: scatter_matrix(pts, keep)),
        Case(
            "ransac_plane",
            lambda: ransac(pts, PlaneModel(), 0.05, scoring="msac", rng=0),
        ),
        Case("ransac_plane_ransac", lambda: ransac(pts, PlaneModel(), 0.05, rng=1)),
        Case("slab_inliers", lambda: slab_inliers(front, np.array([0, 0, 1.0]), 2.0, 0.02, keep)),
        # the slab fit's parallel kernel, which the fit runs only on >= 100,000 points
        Case("slab_fit_parallel", lambda: slab_parallel(front, keep)),
        Case("take_rows_mask", lambda: _take_rows(pts, mask=keep)),
        Case("take_rows_step", lambda: [_take_rows(pts, step=k) for k in (1, 3, 7)]),
        Case("take_rows_mask_4_columns", lambda: _take_rows(np.c_[pts, pts[:, 0]], mask=keep)),
    ]


def _depth_cases() -> list[Case]:
    from robopercept.depth import (
        ColorRangeSelector,
        align_color_to_depth,
        block_matching,
        census_transform,
        semi_global_matching,
        texture_coordinates,
    )
    from robopercept.geometry import CameraIntrinsics

    # textured (flat patches make matching costs tie, and ties have no right answer)
    noise = np.random.default_rng(7).random((26, 34))
    tex = sum(noise[i : i + 24, j : j + 32] for i in range(3) for j in range(3)) / 9
    tex = 0.5 * tex + 0.5 * GRAY
    left = np.round(tex * 255).astype(np.uint8)
    right = np.round(_shifted(tex, -3.4) * 255).astype(np.uint8)
    k_depth = CameraIntrinsics(16, 12, 14.0, 14.0, 7.5, 5.5)
    k_color = CameraIntrinsics(20, 15, 18.0, 18.5, 9.7, 7.2, "brown_conrady",
                               (0.05, -0.02, 1e-3, -1e-3, 0.001))  # fmt: skip
    k_inverse = CameraIntrinsics(20, 15, 18.0, 18.5, 9.7, 7.2, "inverse_brown_conrady",
                                 (0.05, -0.02, 1e-3, -1e-3, 0.001))  # fmt: skip
    depth = (800 + 300 * GRAY[:12, :16]).astype(np.uint16)
    depth[4:7, 5:9] = 500  # an occluder in front of the wall
    depth[0, 0] = 0
    T = np.eye(4)
    T[:3, 3] = [0.015, -0.002, 0.001]
    color = RGB_U8[:15, :20]
    y, x = np.mgrid[0:12, 0:16]
    pts = np.stack([(x - 7.5) / 14.0, (y - 5.5) / 14.0, np.ones_like(x, float)], -1)
    pts = (pts * depth[..., None] * 0.001).reshape(-1, 3)
    sgm = dict(census=3, block=3)

    def color_select() -> list[Any]:
        # the whole HSV box with the z-buffer, then a wrapping box without it (the
        # occluder hides wall points); wall-clock timings are not results
        out = []
        for low, high, tol in [
            ((0, 0, 0), (180, 255, 255), 0.02),
            ((150, 20, 20), (60, 255, 255), None),
        ]:
            sel = ColorRangeSelector(low, high, tol)(depth, color, k_depth, k_color, T, 0.001)
            out.append(dataclasses.replace(sel, ms={}))
        assert out[0].pixels.size > 50 and out[1].pixels.size > 20
        return out

    def box_table() -> np.ndarray:
        # the HSV box's bit table for the colours with R = 37 and R = 200 (all 2^24 of
        # them take minutes as Python), a box that wraps around and one that does not
        from robopercept.depth import color_select

        out = []
        for low, high in [
            ((150.0, 20.0, 20.0), (60.0, 255.0, 255.0)),
            ((45.0, 35.0, 35.0), (65.0, 255.0, 255.0)),
        ]:
            lut = np.zeros(1 << 21, dtype=np.uint8)
            for r in (37, 200):
                color_select._box_table_kernel(np.array(low), np.array(high), r, r + 1, lut)
            out.append(lut)
        assert out[0].any() and out[1].any()
        return np.concatenate(out)

    return [
        Case("hsv_box_table", box_table),
        Case("census", lambda: census_transform(GRAY_U8, 5)),
        Case("sgm_8", lambda: semi_global_matching(left, right, 8, **sgm)),
        Case(
            "sgm_4_checks",
            lambda: semi_global_matching(
                left,
                right,
                8,
                paths=4,
                lr_check=1.0,
                median=True,
                uniqueness=0.05,
                min_disparity=1,
                **sgm,
            ),
            F32,
            "fastmath path costs; integers bit-identical in practice",
        ),
        Case("bm_sad", lambda: block_matching(left, right, 8, 5, median=True, lr_check=1.0)),
        Case("bm_ssd", lambda: block_matching(left, right, 8, 3, "ssd", uniqueness=0.1)),
        Case("bm_ncc", lambda: block_matching(left, right, 8, 5, "ncc", min_disparity=1)),
        Case("texture_coordinates", lambda: texture_coordinates(pts, T, k_color)),
        Case(
            "texture_inverse",
            lambda: texture_coordinates(pts, T, k_inverse, occlusion_tolerance=None),
        ),
        Case("align_color", lambda: align_color_to_depth(color, depth, k_depth, k_color, T)),
        Case("color_select", color_select),
    ]


def _calibration_cases() -> list[Case]:
    from robopercept.calibration import find_chessboard_corners, find_circles_grid
    from robopercept.imaging import gaussian_blur

    y, x = np.mgrid[0:60, 0:72]
    sq = 9
    inside = (x >= 9) & (x < 9 + 6 * sq) & (y >= 8) & (y < 8 + 5 * sq)
    black = (((x - 9) // sq + (y - 8) // sq) % 2 == 0) & inside
    board = np.where(black, 30.0, 225.0)
    board = np.round(gaussian_blur(board, 0.8)).astype(np.uint8)
    circles = np.full((60, 72), 230.0)
    for i in range(4):
        for j in range(3):
            cx, cy = 12 + 15 * i + 0.3 * j, 12 + 15 * j + 0.2 * i
            circles[(x - cx) ** 2 + (y - cy) ** 2 < 16] = 25.0
    circles = np.round(gaussian_blur(circles, 0.7)).astype(np.uint8)
    return [
        Case("chessboard", lambda: find_chessboard_corners(board, (5, 4))),
        Case(
            "circles_grid",
            lambda: find_circles_grid(circles, (4, 3), asymmetric=False, min_area=10),
        ),
    ]


def _learning_cases() -> list[Case]:
    from robopercept.learning import (
        DBSCAN,
        SVC,
        DecisionTreeClassifier,
        DecisionTreeRegressor,
        KMeans,
        LinearSVC,
    )

    rng = np.random.default_rng(5)
    X = np.concatenate([rng.normal(0, 1, (60, 2)), rng.normal(4, 1, (60, 2))])
    y = np.repeat([0, 1], 60)
    y3 = (X[:, 0] > 2).astype(int) + (X[:, 1] > 3)
    # 14-D: DBSCAN's brute-force neighbours (k-d tree below 13 dimensions)
    Xw = np.concatenate([X, 0.1 * rng.normal(size=(120, 12))], axis=1)

    def fitted(model: Any, XX: np.ndarray, yy: np.ndarray | None = None) -> dict[str, Any]:
        model.fit(XX) if yy is None else model.fit(XX, yy)
        return {k: v for k, v in vars(model).items() if k.endswith("_") and not k.startswith("_")}

    return [
        Case("kmeans", lambda: fitted(KMeans(3, random_state=0, n_init=2), X)),
        Case("dbscan", lambda: fitted(DBSCAN(0.6, 4), X)),
        Case("dbscan_brute", lambda: fitted(DBSCAN(1.2, 4), Xw)),
        Case(
            "tree_gini",
            lambda: DecisionTreeClassifier(max_depth=4, random_state=0).fit(X, y3).predict_proba(X),
        ),
        Case(
            "tree_entropy",
            lambda: (
                DecisionTreeClassifier("entropy", max_features=1, random_state=2)
                .fit(X, y3)
                .apply(X)
            ),
        ),
        Case(
            "tree_regressor",
            lambda: (
                DecisionTreeRegressor(max_depth=3, random_state=0).fit(X, X[:, 0] ** 2).predict(X)
            ),
        ),
        Case("svc_rbf", lambda: SVC(C=2.0).fit(X, y).decision_function(X)),
        Case("svc_ovr", lambda: SVC(kernel="poly", degree=2).fit(X, y3).decision_function(X)),
        Case("linear_svc", lambda: LinearSVC(random_state=0).fit(X, y3).decision_function(X)),
        Case(
            "linear_svc_hinge",
            lambda: LinearSVC(loss="hinge", random_state=0).fit(X, y).decision_function(X),
        ),
    ]


def _pointcloud_cases() -> list[Case]:
    import tempfile

    from robopercept.pointcloud import (
        PointCloud,
        euclidean_clusters,
        read_point_cloud,
        statistical_outlier_removal,
        voxel_downsample,
    )

    rng = np.random.default_rng(6)
    pts = np.concatenate([rng.normal(0, 0.05, (100, 3)), rng.normal(1, 0.05, (100, 3))])
    colors = rng.random((200, 3))
    cloud = PointCloud(pts, colors=colors)

    def lzf_pcd() -> np.ndarray:
        # 2 points at (1, 1, 1): 24 bytes of the 4-byte pattern of float32 1.0,
        # LZF-coded as a 4-byte literal and a back reference of 20 bytes at distance 4
        one = struct.pack("<f", 1.0)
        stream = bytes([3]) + one + bytes([7 << 5, 20 - 2 - 7, 3])
        header = (
            b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n"
            b"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA binary_compressed\n"
        )
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "lzf.pcd"
            path.write_bytes(header + struct.pack("<II", len(stream), 24) + stream)
            return read_point_cloud(path).points

    return [
        Case("voxel_downsample", lambda: voxel_downsample(cloud, 0.04)),
        Case("statistical_outliers", lambda: statistical_outlier_removal(cloud, 8, 1.0)),
        Case("euclidean_clusters", lambda: euclidean_clusters(cloud, 0.08)),
        Case("lzf_pcd", lzf_pcd),
    ]


def _pipeline_cases() -> list[Case]:
    from robopercept.pipelines import PlaneTracker
    from robopercept.sources import SyntheticRGBDScene

    def track() -> list[Any]:
        scene = SyntheticRGBDScene(n_frames=2, depth_size=(64, 36), color_size=(80, 45))
        frames = list(scene)
        tracker = PlaneTracker()
        results = [r for _, r in tracker.stream(frames)]
        for r in results:  # wall-clock timings are not results
            object.__setattr__(r, "ms", {})
        return [frames, results]

    def imm() -> list[Any]:
        from robopercept.tracking import IMMEstimator, constant_velocity

        filters = [constant_velocity(2, 0.1, q, 0.01) for q in (0.1, 10.0)]
        est = IMMEstimator(filters, [0.5, 0.5], [[0.9, 0.1], [0.2, 0.8]])
        out = []
        for k in range(4):
            est.predict()
            z = np.array([0.3 * k, 0.1 * k * k])
            out.append(est.mahalanobis2(z))
            est.update(z)
            out += [est.x.copy(), est.P.copy(), est.mu.copy()]
        return out

    return [Case("plane_tracker", track), Case("imm_bank", imm)]


def _geometry_cases() -> list[Case]:
    from robopercept.geometry.boxes import greedy_nms
    from robopercept.geometry.camera import distort

    x, y = np.meshgrid(np.linspace(-0.6, 0.6, 9), np.linspace(-0.4, 0.5, 7))
    c = (0.1, -0.05, 1e-3, -2e-3, 0.01)
    rng = np.random.default_rng(3)
    boxes = np.concatenate([rng.uniform(0, 40, (50, 2)), rng.uniform(2, 15, (50, 2))], axis=1)
    scores, classes = rng.permutation(50) / 50.0, rng.integers(0, 3, 50)
    return [
        Case(
            "distort",
            lambda: [
                distort(x, y, c, m) for m in ("brown_conrady", "modified_brown_conrady", "none")
            ],
        ),
        Case(
            "greedy_nms",
            lambda: [
                greedy_nms(boxes, scores, 0.3),
                greedy_nms(boxes, scores, 0.2, classes=classes),
            ],
        ),
        # 64 boxes or more of a class: the grid of candidate pairs
        Case(
            "greedy_nms_grid",
            lambda: [
                greedy_nms(np.tile(boxes, (3, 1)) * [1, 1, 0.5, 0.5], np.tile(scores, 3), 0.3),
                greedy_nms(
                    np.tile(boxes, (4, 1)), np.tile(scores, 4), 0.2, classes=np.tile(classes, 4)
                ),
            ],
        ),
    ]


def _nn_cases() -> list[Case]:
    """Detection's kernels (greedy NMS, COCO matching): only with the deep extra."""
    if importlib.util.find_spec("torch") is None:
        return []
    import torch

    from robopercept.nn.coco.dataset import coco_from_dict
    from robopercept.nn.coco.evaluate import evaluate_detections
    from robopercept.nn.coco.results import results_from_list
    from robopercept.nn.ops.nms import batched_nms

    rng = np.random.default_rng(7)
    xy = rng.uniform(0, 40, (60, 2))
    boxes = np.concatenate([xy, xy + rng.uniform(4, 20, (60, 2))], axis=1)
    scores, classes = rng.permutation(60) / 60.0, rng.integers(0, 3, 60)
    jitter = rng.normal(0, 2, (20, 2))  # drawn once: each case runs twice

    def nms() -> np.ndarray:
        t = torch.from_numpy
        return batched_nms(t(boxes), t(scores), t(classes), 0.4).numpy()

    def coco() -> list[np.ndarray]:
        images = [{"id": i, "file_name": f"{i}.png", "width": 64, "height": 64} for i in (1, 2)]
        anns = [
            {
                "id": k + 1,
                "image_id": 1 + k % 2,
                "category_id": 1 + k % 2,
                "iscrowd": 0,
                "bbox": [*xy[k], 10.0, 12.0],
                "area": 120.0,
            }
            for k in range(12)
        ]
        gt = coco_from_dict(
            {
                "images": images,
                "annotations": anns,
                "categories": [{"id": 1, "name": "a"}, {"id": 2, "name": "b"}],
            }
        )
        dets = [
            {
                "image_id": 1 + k % 2,
                "category_id": 1 + k % 2,
                "score": float(scores[k]),
                "bbox": [*(xy[k] + jitter[k]), 10.0, 12.0],
            }
            for k in range(20)
        ]
        ev = evaluate_detections(gt, results_from_list(dets))
        return [ev.precision, ev.recall, ev.scores, np.asarray(ev.stats)]

    from robopercept.nn.pose.pictorial import pictorial_structures

    costs = rng.normal(size=(4, 9, 11))
    costs[rng.random(costs.shape) < 0.2] = np.inf  # forbidden cells skip the envelope
    springs = (rng.normal(0, 2, (4, 2)), rng.uniform(0.1, 2.0, (4, 2)))

    def pictorial() -> object:
        return pictorial_structures(costs, [1, -1, 1, 2], *springs, min_marginals=True)

    from robopercept.nn.ops.roi import roi_align, roi_pool

    feats = rng.normal(size=(2, 3, 9, 7))
    rois = np.concatenate([rng.integers(0, 2, (8, 1)), xy[:8] / 4, xy[:8] / 4 + 3.0], axis=1)

    def align() -> list[np.ndarray]:
        t = torch.from_numpy
        return [
            roi_align(t(feats).float(), t(rois).float(), (2, 3), 0.5, 2, True).numpy(),
            roi_align(t(feats), t(rois), 2, 1.0, 0, False).numpy(),
        ]

    def pool() -> list[np.ndarray]:
        t = torch.from_numpy
        return [
            roi_pool(t(feats).float(), t(rois).float(), (2, 3), 0.5).numpy(),
            roi_pool(t(feats), t(rois), 2, 1.0).numpy(),
        ]

    return [
        Case("batched_nms", nms),
        Case("roi_align", align),
        Case("roi_pool", pool),
        Case("coco_matching", coco),
        Case("pictorial_structures", pictorial),
    ]


CASES: list[Case] = [
    *_geometry_cases(),
    *_depth_cases(),
    *_calibration_cases(),
    *_learning_cases(),
    *_pointcloud_cases(),
    *_pipeline_cases(),
    *_imaging_cases(),
    *_features_cases(),
    *_motion_cases(),
    *_estimation_cases(),
    *_nn_cases(),
]


# -- the tests -------------------------------------------------------------------------


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_kernel_matches_reference(case: Case) -> None:
    run_case(case)


def test_case_names_are_unique() -> None:
    assert len({c.name for c in CASES}) == len(CASES)


def test_harness_swaps_and_restores() -> None:
    from robopercept.imaging import filters

    kernels = {n: v for n, v in vars(filters).items() if isinstance(v, CPUDispatcher)}
    assert kernels
    with reference_kernels():
        assert not any(isinstance(getattr(filters, n), CPUDispatcher) for n in kernels)
    assert all(getattr(filters, n) is v for n, v in kernels.items())


def test_every_kernel_is_exercised() -> None:
    """Every dispatcher of the package is run by at least one case (this test runs the
    reference path of any case the session has not run yet)."""
    for case in CASES:
        if case.name not in CALLED:
            with reference_kernels() as called:
                case.run()
            CALLED[case.name] = called
    seen = set().union(*CALLED.values())
    missing = sorted(set(all_kernels()) - seen - set(EXCLUDED))
    assert not missing, (
        f"{len(missing)} compiled kernels are compared with their reference by no case; "
        f"add a case to tests/test_kernels.py: {missing}"
    )
    stale = sorted(set(EXCLUDED) - set(all_kernels()))
    assert not stale, f"EXCLUDED names kernels that no longer exist: {stale}"
