r"""RGB-D geometry: depth images to points, colour through texture (UV) coordinates, and
alignment of one camera's image to the other's, with librealsense's conventions.

A depth pixel :math:`(u, v)` (pixel centres at integer coordinates) with raw value
:math:`D` is the point :math:`z = s D`,

.. math:: X = z \frac{u - c_x}{f_x}, \quad Y = z \frac{v - c_y}{f_y}, \quad Z = z

(without lens distortion; with it, :func:`~robopercept.geometry.deproject` undistorts
first), where :math:`s` is the depth scale (metres per unit; 0.001 on a D435). Its colour
is found by moving it into the colour camera, :math:`p_c = T_{cd}\, p`, and projecting:
the texture coordinate is the colour pixel divided by the image size,
:math:`(u_c / W_c, v_c / H_c)`, as ``rs2::pointcloud`` computes it.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba import njit

from robopercept._checks import check_bool, check_numeric, check_real, plain_repr
from robopercept.errors import InputError, RoboperceptWarning
from robopercept.geometry import CameraIntrinsics, apply, deproject, project
from robopercept.geometry.camera import compiled_params, distort_point
from robopercept.geometry.transforms import check_transform

__all__ = [
    "MAX_PIXELS",
    "PLAUSIBLE_DEPTH_M",
    "DepthScaleWarning",
    "align_color_to_depth",
    "align_depth_to_color",
    "check_depth",
    "check_intrinsics",
    "check_pixels",
    "depth_scale_warning",
    "depth_to_points",
    "pixel_rays",
    "plausible_depth",
    "project_to_color",
    "sample_colors",
    "texture_coordinates",
]


#: most pixels a camera may have where a function allocates per-pixel arrays for it
#: (2**26: 8K video has 2**25; the rays of 2**26 pixels take 1.5 GiB)
MAX_PIXELS = 1 << 26


#: median depths (metres) of the measured pixels plausible for an RGB-D camera, both
#: inclusive: a median outside means a wrong depth scale (units per metre given as metres
#: per unit, metres given as millimetres, ...). The rule of ``rgbd-import``'s warning.
PLAUSIBLE_DEPTH_M = (0.1, 20.0)

# about this many pixels (a regular grid of rows and columns) give the median of
# depth_scale_warning: 19,200 on a 640x480 image, a fraction of a millisecond
_MEDIAN_PIXELS = 1 << 14


class DepthScaleWarning(RoboperceptWarning):
    """A depth image whose median depth is implausible for the depth scale given
    (:data:`PLAUSIBLE_DEPTH_M`); silence it with
    ``warnings.simplefilter("ignore", DepthScaleWarning)``."""


def plausible_depth(median_m: float) -> bool:
    """Whether ``median_m``, the median depth in metres of a frame's measured pixels, is
    plausible for an RGB-D camera: inside :data:`PLAUSIBLE_DEPTH_M` (0.1 to 20 m).

    Parameters
    ----------
    median_m : float

    Returns
    -------
    bool
        False for NaN.

    Raises
    ------
    InputError
        ``median_m`` not a real number.

    Examples
    --------
    >>> plausible_depth(1.9), plausible_depth(9500.0)
    (True, False)
    """
    if isinstance(median_m, (bool, np.bool_)) or not isinstance(
        median_m, (int, float, np.integer, np.floating)
    ):
        raise InputError(f"median_m must be a real number (metres); got {plain_repr(median_m)}")
    lo, hi = PLAUSIBLE_DEPTH_M
    return bool(lo <= median_m <= hi)


def depth_scale_warning(depth: np.ndarray, depth_scale: float) -> str | None:
    """The warning for a depth image whose median depth is implausible at
    ``depth_scale``, naming the fix; None when it is plausible (or nothing is measured).

    The median is taken over the measured pixels (finite, > 0) of a regular grid of
    rows and columns, about 16k pixels (every 4th row and column of a 640x480 image),
    and judged by :func:`plausible_depth`. The fix offered is the first of
    ``1 / depth_scale`` (units per metre given where metres per unit are meant, TUM's
    5000 for instance), 0.001 (millimetres), 1/5000 (TUM) and 1 (metres) that brings
    the median into :data:`PLAUSIBLE_DEPTH_M`.

    Parameters
    ----------
    depth : (H, W) ndarray
        Raw depth, as :func:`depth_to_points` takes it.
    depth_scale : float
        Metres per unit (> 0).

    Returns
    -------
    str or None

    Raises
    ------
    InputError
        ``depth`` not a 2-D numeric array, ``depth_scale`` not > 0.

    Examples
    --------
    >>> tum = np.full((480, 640), 9500, dtype=np.uint16)  # 1.9 m in TUM's 1/5000 m units
    >>> print(depth_scale_warning(tum, 5000))  # doctest: +NORMALIZE_WHITESPACE
    median depth 4.75e+07 m of the measured pixels is implausible for an RGB-D camera
    (0.1 to 20 m) at depth_scale=5000 metres per unit: units per metre given? use
    depth_scale=0.0002 (1/5000)
    >>> depth_scale_warning(tum, 1 / 5000) is None
    True
    """
    d = check_numeric(depth, "depth")
    if d.ndim != 2:
        raise InputError(f"depth must be a 2-D (H, W) image; got shape {d.shape}")
    s = check_real(depth_scale, "depth_scale (metres per unit)", 0.0, low_inclusive=False)
    return _scale_message(d, s)


def _scale_message(depth: np.ndarray, depth_scale: float) -> str | None:
    """:func:`depth_scale_warning` for a checked ``(H, W)`` numeric depth and scale > 0."""
    h, w = depth.shape
    step = max(1, math.isqrt(h * w // _MEDIAN_PIXELS))
    with np.errstate(over="ignore", invalid="ignore"):
        z = depth[::step, ::step].astype(np.float64) * depth_scale
    z = z[np.isfinite(z) & (z > 0)]
    if z.size == 0:
        return None
    median = float(np.median(z))
    if plausible_depth(median):
        return None
    lo, hi = PLAUSIBLE_DEPTH_M
    raw = median / depth_scale
    candidates = [(1.0 / depth_scale, f"1/{depth_scale:g}")] if depth_scale > 1 else []
    candidates += [(0.001, "millimetres"), (1 / 5000, "TUM, 5000 units per metre")]
    candidates += [(1.0, "depth already in metres")]
    fix = next(
        (
            f"use depth_scale={c:.4g} ({why})"
            for c, why in candidates
            if c != depth_scale and plausible_depth(raw * c)
        ),
        "check the depth image and its scale",
    )
    if depth_scale > 1 and fix.endswith(f"(1/{depth_scale:g})"):
        fix = "units per metre given? " + fix
    return (
        f"median depth {median:.3g} m of the measured pixels is implausible for an RGB-D "
        f"camera ({lo:g} to {hi:g} m) at depth_scale={depth_scale:g} metres per unit: {fix}"
    )


def check_pixels(k: CameraIntrinsics, name: str) -> None:
    """InputError (naming ``name``) when camera ``k`` has more than :data:`MAX_PIXELS`
    pixels: a bound on the per-pixel arrays (rays, z-buffers) made for it."""
    if k.width * k.height > MAX_PIXELS:
        raise InputError(
            f"{name} describe a {k.width}x{k.height} image, more than {MAX_PIXELS} pixels "
            "(its per-pixel arrays would take several GiB): use "
            "CameraIntrinsics.scaled(width, height) for a smaller resolution"
        )


def check_intrinsics(value: object, name: str = "intrinsics") -> CameraIntrinsics:
    """``value`` itself after checking that it is a
    :class:`~robopercept.geometry.CameraIntrinsics`; InputError naming ``name`` otherwise.

    Examples
    --------
    >>> check_intrinsics(np.eye(3), "color_intrinsics")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: color_intrinsics must be a CameraIntrinsics; got ndarray...
    """
    if not isinstance(value, CameraIntrinsics):
        hint = (
            ": wrap a 3x3 matrix K with CameraIntrinsics.from_matrix(K, width, height)"
            if isinstance(value, np.ndarray) and value.shape == (3, 3)
            else ": build one with CameraIntrinsics(width, height, fx, fy, cx, cy)"
        )
        raise InputError(f"{name} must be a CameraIntrinsics; got {type(value).__name__}{hint}")
    return value


def check_depth(
    depth: np.ndarray, intrinsics: CameraIntrinsics, name: str = "intrinsics"
) -> np.ndarray:
    """``depth`` as an array after checking that it is a numeric (H, W) image of the size
    ``intrinsics`` (called ``name`` in the message, and checked to be a
    :class:`~robopercept.geometry.CameraIntrinsics`) describe; InputError otherwise."""
    check_intrinsics(intrinsics, name)
    d = np.asarray(depth)
    if d.ndim != 2:
        hint = (
            ": drop the channel axis with depth[..., 0]" if d.ndim == 3 and d.shape[2] == 1 else ""
        )
        raise InputError(f"depth must be a 2-D (H, W) image; got shape {d.shape}{hint}")
    if d.dtype.kind not in "uif" or d.dtype == np.float16:
        hint = ": convert with depth.astype(np.float32)" if d.dtype.kind == "f" else ""
        raise InputError(
            "depth must be numeric (uint16 raw units or float32/float64 metres); got "
            f"{d.dtype}{hint}"
        )
    if d.shape != (intrinsics.height, intrinsics.width):
        raise InputError(
            f"depth is {d.shape[1]}x{d.shape[0]} but {name} describe "
            f"{intrinsics.width}x{intrinsics.height}: use the depth stream's intrinsics "
            "(CameraIntrinsics.scaled for another resolution)"
        )
    return d


def pixel_rays(intrinsics: CameraIntrinsics) -> np.ndarray:
    """``(H * W, 3)`` unit-depth rays of every pixel in row-major order,
    ``deproject((u, v), 1)``: the point at depth ``z`` behind pixel ``i`` is
    ``z * rays[i]`` (undistortion does not depend on depth).

    Raises
    ------
    InputError
        ``intrinsics`` not a CameraIntrinsics, or more than :data:`MAX_PIXELS` pixels.

    Examples
    --------
    >>> from robopercept.geometry import CameraIntrinsics
    >>> pixel_rays(CameraIntrinsics(2, 1, 2.0, 2.0, 0.5, 0.0)).tolist()
    [[-0.25, 0.0, 1.0], [0.25, 0.0, 1.0]]
    """
    k = check_intrinsics(intrinsics)
    check_pixels(k, "intrinsics")
    v, u = np.mgrid[0 : k.height, 0 : k.width]
    pix = np.stack([u, v], axis=-1).reshape(-1, 2).astype(np.float64)
    return np.ascontiguousarray(deproject(pix, 1.0, intrinsics))


def depth_to_points(
    depth: np.ndarray,
    intrinsics: CameraIntrinsics,
    depth_scale: float = 0.001,
    *,
    organized: bool = True,
) -> np.ndarray:
    """Back-project a depth image.

    Parameters
    ----------
    depth : (H, W) ndarray
        Raw depth (uint16 units) or metres (float with ``depth_scale=1``); 0 (and NaN)
        means no measurement.
    intrinsics : CameraIntrinsics
        Of the depth camera, matching the image size.
    depth_scale : float
        Metres per unit.
    organized : bool
        ``(H, W, 3)`` with NaN where there is no depth (True), or ``(N, 3)`` of the valid
        pixels in row-major order (False).

    Returns
    -------
    ndarray
        float64 points in the depth camera frame, metres. Equal to the vertices of
        ``rs2::pointcloud`` where the depth is valid, and to Open3D's
        ``PointCloud.create_from_depth_image`` with ``depth_scale = 1 / depth_scale``
        (Open3D counts units per metre: TUM's 5000 there is ``1 / 5000`` here).

    Warns
    -----
    DepthScaleWarning
        When the median depth of the measured pixels is implausible for an RGB-D camera
        (outside 0.1 to 20 m, ``rgbd-import``'s rule): the message names the likely
        depth scale (:func:`depth_scale_warning`), e.g. ``depth_scale=0.0002`` when
        TUM's 5000 units per metre were given.
    """
    d = check_depth(depth, intrinsics)
    s = check_real(depth_scale, "depth_scale (metres per unit)", 0.0, low_inclusive=False)
    organized = check_bool(organized, "organized")
    message = _scale_message(d, s)
    if message is not None:
        warnings.warn(message, DepthScaleWarning, stacklevel=2)
    z = d.astype(np.float64) * s
    valid = np.isfinite(z) & (z > 0)
    if organized:
        v, u = np.mgrid[0 : d.shape[0], 0 : d.shape[1]]
        pts = deproject(np.stack([u, v], axis=-1).astype(np.float64), z, intrinsics)
        pts[~valid] = np.nan
        return pts
    v, u = np.nonzero(valid)
    return deproject(np.column_stack([u, v]).astype(np.float64), z[v, u], intrinsics)


@njit(cache=True, nogil=True, inline="always")
def project_to_color(x0, y0, z0, R, t, k, code, c):  # pragma: no cover - compiled
    r"""One depth-frame point onto the colour image, compiled (callable from numba kernels).

    The point moves into the colour frame, :math:`(X, Y, Z) = R\,(x_0, y_0, z_0) + t`, and
    projects through the colour camera's lens model,
    :math:`(u, v) = (f_x x_d + c_x, f_y y_d + c_y)` with
    :math:`(x_d, y_d) = \operatorname{dist}(X / Z, Y / Z)`
    (:func:`~robopercept.geometry.camera.distort_point`; librealsense's forward models,
    the inverse model projecting with the modified formula). The per-point core of
    :func:`texture_coordinates`; arguments are unchecked.

    Parameters
    ----------
    x0, y0, z0 : float
        The point in the depth camera frame, metres.
    R : (3, 3) float64 ndarray
    t : (3,) float64 ndarray
        ``T_color_depth``'s rotation and translation.
    k, code, c
        The colour camera as :func:`~robopercept.geometry.camera.compiled_params` gives
        it: ``(fx, fy, cx, cy)``, lens-model code, ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    u, v, Z : float
        Colour pixel and depth in the colour frame; when ``Z`` is not > 0 (behind the
        camera) or NaN, ``u`` and ``v`` are NaN.
    """
    X = R[0, 0] * x0 + R[0, 1] * y0 + R[0, 2] * z0 + t[0]
    Y = R[1, 0] * x0 + R[1, 1] * y0 + R[1, 2] * z0 + t[1]
    Z = R[2, 0] * x0 + R[2, 1] * y0 + R[2, 2] * z0 + t[2]
    if not Z > 0:
        return np.nan, np.nan, Z
    x, y = distort_point(X / Z, Y / Z, c, code)
    return x * k[0] + k[2], y * k[1] + k[3], Z


@njit(cache=True, nogil=True)
def _texture_kernel(p, R, t, k, model, c, width, height, tol, uv, valid):  # pragma: no cover
    # one pass: project, bounds, z-buffer; then a second pass for occlusion
    n = p.shape[0]
    zc = np.empty(n)
    pix = np.full(n, -1, dtype=np.int64)
    zbuf = np.full(width * height if tol >= 0 else 0, np.inf)
    for i in range(n):
        x0 = p[i, 0]
        y0 = p[i, 1]
        z0 = p[i, 2]
        valid[i] = False
        uv[i, 0] = np.nan
        uv[i, 1] = np.nan
        if not (np.isfinite(x0) and np.isfinite(y0) and np.isfinite(z0)):
            continue
        u, v, Z = project_to_color(x0, y0, z0, R, t, k, model, c)
        if not Z > 0:
            continue
        uv[i, 0] = u / width
        uv[i, 1] = v / height
        col = np.rint(u)
        row = np.rint(v)
        if z0 > 0 and col >= 0 and col < width and row >= 0 and row < height:
            valid[i] = True
            if tol >= 0:
                j = int(row) * width + int(col)
                pix[i] = j
                zc[i] = Z
                if Z < zbuf[j]:
                    zbuf[j] = Z
    if tol >= 0:
        for i in range(n):
            if valid[i] and zc[i] > zbuf[pix[i]] + tol:
                valid[i] = False


def texture_coordinates(
    points: np.ndarray,
    T_color_depth: np.ndarray,
    color_intrinsics: CameraIntrinsics,
    *,
    occlusion_tolerance: float | None = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """Texture coordinates of depth-frame points in the colour image, and which are usable.

    Parameters
    ----------
    points : (..., 3) array_like
        Depth-camera-frame points (NaN for none), e.g. from :func:`depth_to_points`.
    T_color_depth : (4, 4) array_like
        Depth frame to colour frame (librealsense's depth-to-colour extrinsics).
    color_intrinsics : CameraIntrinsics
    occlusion_tolerance : float or None
        A point is occluded when another point lands on the same colour pixel more than
        this many metres nearer to the colour camera (a z-buffer); None skips the test.

    Returns
    -------
    uv : (..., 2) float64 ndarray
        ``(u_c / W_c, v_c / H_c)``; ``rs2::pointcloud``'s texture coordinates.
    valid : (...) bool ndarray
        False for points without depth, outside the colour image, or occluded.
    """
    p = check_numeric(points, "points")
    if p.shape[-1:] != (3,):
        raise InputError(f"points must have shape (..., 3); got {p.shape}")
    T = check_transform(T_color_depth, "T_color_depth")
    k = check_intrinsics(color_intrinsics, "color_intrinsics")
    check_pixels(k, "color_intrinsics")
    tol = -1.0
    if occlusion_tolerance is not None:
        tol = check_real(occlusion_tolerance, "occlusion_tolerance (metres, or None)", 0.0)
    flat = np.ascontiguousarray(p.reshape(-1, 3))
    uv = np.empty((flat.shape[0], 2))
    valid = np.empty(flat.shape[0], dtype=bool)
    kk, model, coeffs = compiled_params(k)
    _texture_kernel(
        flat,
        np.ascontiguousarray(T[:3, :3]),
        np.ascontiguousarray(T[:3, 3]),
        kk,
        model,
        coeffs,
        k.width,
        k.height,
        tol,
        uv,
        valid,
    )
    return uv.reshape(*p.shape[:-1], 2), valid.reshape(p.shape[:-1])


def sample_colors(
    color_image: np.ndarray, uv: np.ndarray, valid: np.ndarray | None = None
) -> np.ndarray:
    """Colour of each texture coordinate (the nearest colour pixel).

    Parameters
    ----------
    color_image : (H, W, 3) ndarray
    uv : (..., 2) array_like
        From :func:`texture_coordinates`.
    valid : (...) bool array_like, optional
        Where False (or where ``uv`` falls outside the image) the colour is 0.

    Returns
    -------
    (..., 3) ndarray
        Same dtype as ``color_image``.
    """
    img = np.asarray(color_image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"color_image must be (H, W, 3); got {img.shape}")
    t = check_numeric(uv, "uv")
    if t.shape[-1:] != (2,):
        raise InputError(f"uv must have shape (..., 2); got {t.shape}")
    if valid is not None:
        valid = np.asarray(valid)
        if valid.shape != t.shape[:-1] or valid.dtype.kind not in "biu":
            raise InputError(
                f"valid must be a boolean array of shape uv.shape[:-1] = {t.shape[:-1]}; got "
                f"{valid.dtype} of shape {valid.shape}: pass the valid mask that "
                "texture_coordinates returned with uv"
            )
    h, w = img.shape[:2]
    with np.errstate(invalid="ignore"):
        col = np.rint(t[..., 0] * w)
        row = np.rint(t[..., 1] * h)
        ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    if valid is not None:
        ok &= valid.astype(bool)
    out = np.zeros((*t.shape[:-1], 3), dtype=img.dtype)
    out[ok] = img[row[ok].astype(np.int64), col[ok].astype(np.int64)]
    return out


def align_color_to_depth(
    color_image: np.ndarray,
    depth: np.ndarray,
    depth_intrinsics: CameraIntrinsics,
    color_intrinsics: CameraIntrinsics,
    T_color_depth: np.ndarray,
    depth_scale: float = 0.001,
) -> tuple[np.ndarray, np.ndarray]:
    """The colour image resampled on the depth pixel grid (``rs2::align`` to depth).

    Returns
    -------
    color : (Hd, Wd, 3) ndarray
        Black where there is no depth or no colour.
    valid : (Hd, Wd) bool ndarray
    """
    check_intrinsics(depth_intrinsics, "depth_intrinsics")
    check_intrinsics(color_intrinsics, "color_intrinsics")
    pts = depth_to_points(depth, depth_intrinsics, depth_scale)
    uv, valid = texture_coordinates(pts, T_color_depth, color_intrinsics)
    return sample_colors(color_image, uv, valid), valid


def align_depth_to_color(
    depth: np.ndarray,
    depth_intrinsics: CameraIntrinsics,
    color_intrinsics: CameraIntrinsics,
    T_color_depth: np.ndarray,
    depth_scale: float = 0.001,
) -> np.ndarray:
    """The depth image re-rendered in the colour camera (``rs2::align`` to colour).

    Each depth pixel is moved into the colour frame and splatted on the colour pixel it
    projects to, nearest surface winning; colour pixels that no depth pixel reaches are 0.

    Returns
    -------
    (Hc, Wc) ndarray
        Depth in the input's units and dtype, measured along the colour camera's z.
    """
    d = check_depth(depth, depth_intrinsics, "depth_intrinsics")
    k = check_intrinsics(color_intrinsics, "color_intrinsics")
    check_pixels(k, "color_intrinsics")
    T = check_transform(T_color_depth, "T_color_depth")
    depth_scale = check_real(depth_scale, "depth_scale (metres per unit)", 0.0, low_inclusive=False)
    pts = depth_to_points(d, depth_intrinsics, depth_scale, organized=False)
    pc = apply(T, pts)
    pix = np.rint(project(pc, k))
    with np.errstate(invalid="ignore"):
        ok = (pix[:, 0] >= 0) & (pix[:, 0] < k.width) & (pix[:, 1] >= 0) & (pix[:, 1] < k.height)
    ids = (pix[ok, 1] * k.width + pix[ok, 0]).astype(np.int64)
    zbuf = np.full(k.width * k.height, np.inf)
    np.minimum.at(zbuf, ids, pc[ok, 2])
    out = np.where(np.isfinite(zbuf), zbuf / depth_scale, 0.0).reshape(k.height, k.width)
    if d.dtype.kind in "ui":
        return np.clip(np.rint(out), 0, np.iinfo(d.dtype).max).astype(d.dtype)
    return out.astype(d.dtype)
