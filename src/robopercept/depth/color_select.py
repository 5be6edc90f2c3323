r"""Colour selection of RGB-D points: the points of a depth image whose colour, seen
through the colour camera, lies in an HSV box, computed only for the points selected.

For every depth pixel :math:`i = v W + u` with raw depth :math:`D_i > 0`:

1. **Point.** :math:`p_i = s D_i\, r_i` with the unit-depth ray
   :math:`r_i = \operatorname{deproject}((u, v), 1)` (:func:`~robopercept.depth.pixel_rays`,
   computed once per depth camera) and the depth scale :math:`s`.
2. **Colour pixel.** :math:`(u_c, v_c, z_c)` = :func:`~robopercept.depth.project_to_color`
   of :math:`p_i` through ``T_color_depth`` and the colour camera (its lens model
   included); the colour pixel is :math:`j = \operatorname{rint}(v_c) W_c +
   \operatorname{rint}(u_c)` when :math:`z_c > 0` and it lies inside the colour image.
3. **Occlusion (z-buffer).** :math:`Z_j = \min_{k \to j} z_{c,k}` over the points landing on
   colour pixel :math:`j`; point :math:`i` is hidden there when
   :math:`z_{c,i} > Z_j + \text{tol}` (``occlusion_tolerance``; None: no test), or
   with ``occlusion_grows`` :math:`z_{c,i} > Z_j + \text{tol} \max(1, z_{c,i}^2)`
   (:math:`z` in metres): stereo depth noise grows as :math:`z^2`, and a fixed
   tolerance hides the points whose noise puts them behind their neighbours, a
   one-sided cut that biases whatever is fitted to the rest (at 2.4 m with 1.7 cm of
   noise, a 2 cm tolerance tilted a board's plane by 0.6 deg).
4. **Colour box.** :math:`(H, S, V)` of colour pixel :math:`j` on OpenCV's uint8 scale
   (:func:`~robopercept.imaging.rgb_to_hsv_pixel`, bit for bit
   ``cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)``); selected when
   :math:`S_{lo} \le S \le S_{hi}`, :math:`V_{lo} \le V \le V_{hi}` and
   :math:`H_{lo} \le H \le H_{hi}` (or :math:`H \ge H_{lo} \lor H \le H_{hi}` when
   :math:`H_{lo} > H_{hi}`: the hue range wraps around, e.g. red).

This is the library path ``depth_to_points`` -> ``texture_coordinates`` (z-buffer) ->
``sample_colors`` -> ``rgb_to_hsv`` -> ``hsv_range_mask``, point for point (same points,
same order, same hues; tests/depth/test_color_select.py), fused into compiled passes:
the projection with the colour test (parallel), the z-buffer (serial: pixels collide)
and the selection (parallel), so that only the selected points are stored. The
parallel passes work in 64 blocks of rows and pack the blocks in order, so the output
is in row-major depth-pixel order on any thread count.

What makes them fast (issue 49; 640 x 480 depth and colour, 2 threads: the passes from
7.1 to 3.1 ms, then to 2.3 ms):

- The box test reads a 2 MiB bit table over all :math:`2^{24}` RGB colours, built once
  per box (about 50 ms) from the same HSV conversion; the conversion itself then runs
  only for the selected points' hues, and not at all with ``hues=False``. The HSV
  conversion of every pixel was 1.6 of the selection pass's 2.0 ms. Images under
  65,536 depth pixels skip the table.
- The colour test runs in the projection pass, and only the points whose colour pixel
  is in the box (the candidates) go on: only they can be selected, and only they need
  the z-buffer, since the z-buffer at colour pixel :math:`j` is read only by the
  points that land on :math:`j`, which are candidates exactly when :math:`j`'s colour
  is in the box. The z-buffer, the selection and the reset then visit the candidates
  instead of every pixel.
- A depth camera without lens distortion has separable rays, :math:`(r_x[u], r_y[v],
  1)` (checked exactly when the rays are cached): the passes read two short tables
  instead of streaming :math:`3 H W` numbers.
- The projection is split into a branch-free pass over each row (the rigid transform
  and the divisions :math:`X / Z`, :math:`Y / Z`, which the compiler vectorizes), a
  per-pixel pass for the lens model, and a branch-free pass for the rounding and the
  bounds (every condition evaluated, then one select: three times faster than
  testing them in turn): the same operations in the same order as
  :func:`~robopercept.depth.project_to_color`, so the same bits.
- The per-pixel work arrays are kept by the selector between calls (fresh ones cost a
  page fault every 4 KiB) and colour pixels are indexed in 32 bits where they fit.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from numba import njit, prange

from robopercept._checks import check_bool, check_real
from robopercept.depth.rgbd import (
    check_depth,
    check_intrinsics,
    check_pixels,
    pixel_rays,
)
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.camera import compiled_params, distort_point
from robopercept.geometry.transforms import check_transform
from robopercept.imaging.color import rgb_to_hsv_pixel

__all__ = ["ColorRangeSelector", "ColoredPoints", "points_in_color_range"]

_CHUNKS = 64  # row blocks of the parallel per-pixel passes
#: depth images of at least this many pixels test colours in the box's bit table
#: (:func:`_box_table`: 50 ms to build once, then a lookup instead of an HSV conversion
#: per pixel, 1.6 of the 2.0 ms of the selection pass at 640 x 480)
_TABLE_PIXELS = 1 << 16
_NO_TABLE = np.zeros(1, dtype=np.uint8)
_NO_TABLE.setflags(write=False)


@njit(cache=True, nogil=True, inline="always")
def _ray(i, r, col, separable, rx, ry, rays):  # pragma: no cover - compiled
    # the unit-depth ray of depth pixel i = (r, col): from the (W,) and (H,) tables of a
    # separable camera (every ray (rx[col], ry[r], 1), checked exactly when cached),
    # else from the (H W, 3) table
    if separable:
        return rx[col], ry[r], 1.0
    return rays[i, 0], rays[i, 1], rays[i, 2]


@njit(cache=True, nogil=True, inline="always")
def _in_box(h, s, v, low, high):  # pragma: no cover - compiled
    # the HSV box test (hue wraps around when low[0] > high[0])
    if s < low[1] or s > high[1] or v < low[2] or v > high[2]:
        return False
    if low[0] > high[0]:
        return not (h < low[0] and h > high[0])
    return not (h < low[0] or h > high[0])


@njit(cache=True, nogil=True, inline="always")
def _colour_in_box(rgb, j, low, high, use_lut, lut):  # pragma: no cover - compiled
    # whether colour pixel j's HSV lies in the box: the bit table's bit, or the conversion
    cr = np.int32(rgb[3 * j])
    cg = np.int32(rgb[3 * j + 1])
    cb = np.int32(rgb[3 * j + 2])
    if use_lut:
        key = (cr << 16) | (cg << 8) | cb
        return (lut[key >> 3] >> (key & 7)) & 1 == 1
    hh, ss, vv = rgb_to_hsv_pixel(cr, cg, cb)
    return _in_box(hh, ss, vv, low, high)


# fmt: off
@njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def _project_kernel(
    depth, w, separable, rx, ry, rays, scale, R, t, k, model, c, width, height,
    rgb, low, high, use_lut, lut, cand, pix, zc, counts,
):  # pragma: no cover - compiled
    # fmt: on
    # For every depth pixel i with depth: the point p = s D r(u, v), its colour pixel
    # j = row * width + col (none: behind the colour camera or outside its image) and
    # its depth in the colour frame; the pixels whose colour pixel is in the HSV box are
    # the candidates, kept per block of rows from the block's first pixel on:
    # cand[g] = i, pix[g] = j, zc[g] = depth at j, g in [a, a + counts[b]). Only they
    # can be selected, and only they need the z-buffer: the z-buffer at j is read only
    # by the points that land on j, and those are candidates exactly when j's colour is
    # in the box. Pixels are independent: parallel, in blocks of whole rows. Returns the
    # number of pixels with a depth.
    #
    # This is project_to_color split in two: a branch-free pass over the row (the
    # transform and the two divisions X / Z, Y / Z, which the compiler vectorizes; a
    # pixel without depth or behind the camera divides harmlessly, error_model="numpy",
    # and is dropped after), then the lens model, rounding and bounds per pixel. The same
    # operations in the same order, so the same bits as project_to_color.
    h = depth.shape[0] // w
    valid = np.zeros(_CHUNKS, dtype=np.int64)
    r00, r01, r02 = R[0, 0], R[0, 1], R[0, 2]
    r10, r11, r12 = R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22 = R[2, 0], R[2, 1], R[2, 2]
    t0, t1, t2 = t[0], t[1], t[2]
    f0, f1, f2, f3 = k[0], k[1], k[2], k[3]
    for b in prange(_CHUNKS):
        xn = np.empty(w)
        yn = np.empty(w)
        zn = np.empty(w)
        jr = np.empty(w, dtype=np.int64)
        count = 0
        a = (b * h // _CHUNKS) * w
        g = a
        for r in range(b * h // _CHUNKS, (b + 1) * h // _CHUNKS):
            base = r * w
            # the row's points p = s D r (into the three row buffers) ...
            if separable:
                yr = ry[r]
                for q in range(w):
                    z = depth[base + q] * scale
                    xn[q] = rx[q] * z
                    yn[q] = yr * z
                    zn[q] = 1.0 * z
            else:
                for q in range(w):
                    z = depth[base + q] * scale
                    xn[q] = rays[base + q, 0] * z
                    yn[q] = rays[base + q, 1] * z
                    zn[q] = rays[base + q, 2] * z
            # ... then in the colour frame, normalized (in place)
            for q in range(w):
                x0 = xn[q]
                y0 = yn[q]
                z0 = zn[q]
                X = r00 * x0 + r01 * y0 + r02 * z0 + t0
                Y = r10 * x0 + r11 * y0 + r12 * z0 + t1
                Z = r20 * x0 + r21 * y0 + r22 * z0 + t2
                xn[q] = X / Z
                yn[q] = Y / Z
                zn[q] = Z
            if model != 0:
                for q in range(w):
                    xn[q], yn[q] = distort_point(xn[q], yn[q], c, model)
            # the colour pixels, branch-free (three times faster than testing each
            # condition in turn: the compiler vectorizes it) ...
            for q in range(w):
                d = depth[base + q]
                z = d * scale
                col = np.rint(xn[q] * f0 + f2)
                row = np.rint(yn[q] * f1 + f3)
                has = (d > 0) & (d < np.inf)
                count += has
                ok = has & (z > 0) & (z < np.inf) & (zn[q] > 0)
                ok = ok & (col >= 0) & (col < width) & (row >= 0) & (row < height)
                # (row * width + col is exact in float64: one conversion, not two)
                jr[q] = np.int64(row * width + col) if ok else -1
            # ... then the candidates: the pixels whose colour is in the box
            for q in range(w):
                j = jr[q]
                if j >= 0 and _colour_in_box(rgb, j, low, high, use_lut, lut):
                    cand[g] = base + q
                    pix[g] = j
                    zc[g] = zn[q]
                    g += 1
        valid[b] = count
        counts[b] = g - a
    return valid.sum()


@njit(cache=True, nogil=True)
def _zbuffer_kernel(pix, zc, zbuf, w, h, counts):  # pragma: no cover - compiled
    # nearest colour-frame depth per colour pixel over the candidates (serial: pixels
    # collide)
    for b in range(_CHUNKS):
        a = (b * h // _CHUNKS) * w
        for g in range(a, a + counts[b]):
            j = pix[g]
            if zc[g] < zbuf[j]:
                zbuf[j] = zc[g]


@njit(cache=True, nogil=True, parallel=True)
def _box_table_kernel(low, high, r0, r1, lut):  # pragma: no cover - compiled
    # bit (key & 7) of lut[key >> 3], key = R << 16 | G << 8 | B: whether that colour's
    # HSV (rgb_to_hsv_pixel, OpenCV's bit for bit) lies in the box, for R in r0..r1-1
    for r in prange(r0, r1):
        for g in range(256):
            for b8 in range(32):
                byte = 0
                for e in range(8):
                    h, s, v = rgb_to_hsv_pixel(np.int32(r), np.int32(g), np.int32(b8 * 8 + e))
                    if _in_box(h, s, v, low, high):
                        byte |= 1 << e
                lut[(r << 13) | (g << 5) | b8] = byte


@functools.lru_cache(maxsize=8)
def _box_table(low: tuple[float, float, float], high: tuple[float, float, float]) -> np.ndarray:
    """The HSV box as a 2 MiB bit table over every RGB colour (built once per box, in
    about 50 ms, and shared by the selectors of that box)."""
    lut = np.zeros(1 << 21, dtype=np.uint8)
    _box_table_kernel(np.array(low), np.array(high), 0, 256, lut)
    lut.setflags(write=False)
    return lut


# fmt: off
@njit(cache=True, nogil=True, parallel=True)
def _select_kernel(
    depth, w, separable, rx, ry, rays, scale, rgb, cand, pix, zc, counts, zbuf, tol, grow,
    out, hues, hue,
):  # pragma: no cover - compiled
    # fmt: on
    # The candidates whose colour pixel is theirs (no other point nearer there by more
    # than tol, or tol z^2 beyond 1 m when grow; tol < 0: no test): their points and
    # hues (OpenCV's uint8 conversion, bit for bit), their pixels back into cand. Each
    # block writes from its own first candidate on (never past what it reads), then the
    # blocks are packed in order, so the result is in row-major order whatever the
    # threads. Returns the number selected.
    h = depth.shape[0] // w
    kept = np.zeros(_CHUNKS, dtype=np.int64)
    for b in prange(_CHUNKS):
        a = (b * h // _CHUNKS) * w
        g = a
        for p in range(a, a + counts[b]):
            j = pix[p]
            if tol >= 0:
                t = tol * zc[p] * zc[p] if grow and zc[p] > 1.0 else tol
                if zc[p] > zbuf[j] + t:
                    continue
            i = cand[p]
            if hues:
                cr, cg = np.int32(rgb[3 * j]), np.int32(rgb[3 * j + 1])
                hue[g] = rgb_to_hsv_pixel(cr, cg, np.int32(rgb[3 * j + 2]))[0]
            z = depth[i] * scale
            ax, ay, az = _ray(i, i // w, i % w, separable, rx, ry, rays)
            out[g, 0] = ax * z
            out[g, 1] = ay * z
            out[g, 2] = az * z
            cand[g] = i
            g += 1
        kept[b] = g - a
    m = 0
    for b in range(_CHUNKS):
        a = (b * h // _CHUNKS) * w
        for g in range(a, a + kept[b]):
            out[m, 0] = out[g, 0]
            out[m, 1] = out[g, 1]
            out[m, 2] = out[g, 2]
            if hues:
                hue[m] = hue[g]
            cand[m] = cand[g]
            m += 1
    return m


@njit(cache=True, nogil=True, parallel=True)
def _reset_kernel(pix, zbuf, w, h, counts):  # pragma: no cover - compiled
    # back to +inf for the next call (only the candidates' pixels; racing writes store
    # the same value)
    for b in prange(_CHUNKS):
        a = (b * h // _CHUNKS) * w
        for g in range(a, a + counts[b]):
            zbuf[pix[g]] = np.inf


@dataclass(frozen=True)
class ColoredPoints:
    """The points a :class:`ColorRangeSelector` selected from one RGB-D frame.

    Attributes
    ----------
    points : (M, 3) float64 ndarray
        Depth-camera-frame points, metres, in row-major depth-pixel order: exactly
        ``depth_to_points(depth, K_depth, depth_scale)`` at those pixels.
    hue : (M,) float64 ndarray or None
        OpenCV hue (0..180, integer-valued) of each point's colour pixel, as
        ``rgb_to_hsv`` of the uint8 colour gives it (None when not asked for:
        ``hues=False``).
    pixels : (M,) int64 ndarray
        The depth pixel of each point, ``row * width + col`` (increasing).
    n_valid : int
        Depth pixels with a depth (finite and > 0).
    ms : dict of str to float
        Milliseconds of the passes: ``"points"`` (projection, colour test and z-buffer)
        and ``"color"`` (occlusion test and the selected points).
    """

    points: np.ndarray = field(repr=False)
    hue: np.ndarray | None = field(repr=False)
    pixels: np.ndarray = field(repr=False)
    n_valid: int
    ms: dict[str, float]


def _check_hsv_bounds(
    hsv_low: npt.ArrayLike, hsv_high: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """The HSV box as two float64 (3,) arrays after checking the OpenCV scale."""
    try:
        lo = np.asarray(hsv_low, dtype=np.float64).reshape(-1)
        hi = np.asarray(hsv_high, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as e:
        raise InputError(
            f"hsv_low and hsv_high (--hsv-low, --hsv-high) must be three numbers H, S, V; "
            f"got {hsv_low!r}, {hsv_high!r}"
        ) from e
    if lo.shape != (3,) or hi.shape != (3,):
        raise InputError(
            f"hsv_low and hsv_high (--hsv-low, --hsv-high) need 3 values each (H, S, V); "
            f"got {lo.tolist()} and {hi.tolist()}"
        )
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise InputError(f"HSV bounds must be finite; got low={lo.tolist()}, high={hi.tolist()}")
    if not (0 <= lo[0] <= 180 and 0 <= hi[0] <= 180) or not all(
        0 <= v <= 255 for v in (lo[1], lo[2], hi[1], hi[2])
    ):
        raise InputError(
            "HSV bounds are on the OpenCV scale: H in 0..180 (degrees / 2), S and V in "
            f"0..255; got low={lo.tolist()}, high={hi.tolist()}"
            + (": hue in degrees? halve it" if 180 < max(lo[0], hi[0]) <= 360 else "")
        )
    if lo[1] > hi[1] or lo[2] > hi[2]:
        raise InputError(
            f"the low S and V bounds must be <= the high ones; got low={lo.tolist()}, "
            f"high={hi.tolist()}: swap them (only hue may wrap around, low H > high H)"
        )
    return lo, hi


class ColorRangeSelector:
    r"""Points of a depth image whose colour (through the colour camera) lies in an HSV box.

    See the module docstring for the four steps (point, colour pixel, z-buffer occlusion
    test, HSV box). The result equals, point for point and in the same order,
    ``depth_to_points`` -> ``texture_coordinates(..., occlusion_tolerance)`` ->
    ``sample_colors`` -> ``rgb_to_hsv`` -> ``hsv_range_mask`` on the pixels with depth;
    only the selected points are computed and stored.

    A selector keeps, between calls, the unit rays of the last depth camera and a
    colour-image z-buffer (all +inf between calls, also after an error), so reuse one
    for a stream of frames; one selector is not for concurrent calls from several
    threads.

    Parameters
    ----------
    hsv_low, hsv_high : (3,) array_like
        The box's bounds ``(H, S, V)`` on the OpenCV scale (H 0..180, S and V 0..255),
        inclusive. Hue wraps around when ``hsv_low[0] > hsv_high[0]`` (red:
        ``(170, 50, 50)`` .. ``(10, 255, 255)``).
    occlusion_tolerance : float or None
        Metres: a point is hidden when another one lands on its colour pixel more than
        this much nearer to the colour camera; None: no occlusion test.
    occlusion_grows : bool
        The tolerance grows like stereo depth noise, ``occlusion_tolerance * z**2``
        beyond 1 m (see the module docstring); False (default): the same everywhere,
        as ``texture_coordinates``.

    Raises
    ------
    InputError
        Bounds not 3 finite numbers on the OpenCV scale, low S or V above high, or a
        negative tolerance.

    Examples
    --------
    A 2x2 depth image 1 m away seen by a colour camera in the same place, green above,
    grey below:

    >>> from robopercept.geometry import CameraIntrinsics
    >>> k = CameraIntrinsics(2, 2, 2.0, 2.0, 0.5, 0.5)
    >>> depth = np.full((2, 2), 1000, dtype=np.uint16)
    >>> color = np.array([[[0, 200, 0], [20, 180, 30]], [[90, 90, 90], [90, 90, 90]]], np.uint8)
    >>> select = ColorRangeSelector((45, 35, 35), (65, 255, 255))
    >>> sel = select(depth, color, k, k, np.eye(4), 0.001)
    >>> sel.pixels.tolist(), sel.hue.tolist(), sel.n_valid
    ([0, 1], [60.0, 62.0], 4)
    >>> sel.points.tolist()
    [[-0.25, -0.25, 1.0], [0.25, -0.25, 1.0]]
    """

    def __init__(
        self,
        hsv_low: npt.ArrayLike,
        hsv_high: npt.ArrayLike,
        occlusion_tolerance: float | None = 0.02,
        occlusion_grows: bool = False,
    ) -> None:
        self.hsv_low, self.hsv_high = _check_hsv_bounds(hsv_low, hsv_high)
        self.occlusion_grows = check_bool(occlusion_grows, "occlusion_grows")
        if occlusion_tolerance is not None:
            occlusion_tolerance = check_real(
                occlusion_tolerance,
                "occlusion_tolerance (metres >= 0, or None for no occlusion test)",
                0.0,
            )
        self.occlusion_tolerance = occlusion_tolerance
        self._rays_key: CameraIntrinsics | None = None
        self._rays = np.zeros((0, 3))
        self._rx, self._ry, self._separable = np.zeros(0), np.zeros(0), False
        self._zbuf = np.zeros(0)  # colour-image z-buffer, +inf between calls
        self._work: dict[str, np.ndarray] = {}  # per-pixel buffers, reused between calls

    def _unit_rays(self, k: CameraIntrinsics) -> np.ndarray:
        """``pixel_rays(k)``, cached for the last depth camera, and whether it is
        separable: every ray ``(rx[col], ry[row], 1)`` exactly (a camera without lens
        distortion), so that the kernels read two short tables instead of ``3 H W``
        numbers."""
        if self._rays_key != k:
            rays = pixel_rays(k)
            grid = rays.reshape(k.height, k.width, 3)
            rx = np.ascontiguousarray(grid[0, :, 0])
            ry = np.ascontiguousarray(grid[:, 0, 1])
            self._separable = bool(
                (grid[..., 0] == rx[None, :]).all()
                and (grid[..., 1] == ry[:, None]).all()
                and (grid[..., 2] == 1.0).all()
            )
            self._rays = np.zeros((1, 3)) if self._separable else rays
            self._rx, self._ry = rx, ry
            self._rays_key = k
        return self._rays

    def _buffers(self, n: int, colour_pixels: int) -> dict[str, np.ndarray]:
        """The per-pixel work arrays for ``n`` depth pixels (kept between calls: fresh
        ones cost a page fault every 4 KiB), colour pixels as int32 where they fit."""
        index = np.int32 if colour_pixels < 2**31 else np.int64
        w = self._work
        if w.get("zc", np.zeros(0)).shape[0] != n or w["pix"].dtype != index:
            w.clear()
            w.update(
                pix=np.empty(n, dtype=index),
                zc=np.empty(n),
                out=np.empty((n, 3)),
                hue=np.empty(n),
                idx=np.empty(n, dtype=np.int64),
            )
        return w

    def __call__(
        self,
        depth: np.ndarray,
        color: np.ndarray,
        depth_intrinsics: CameraIntrinsics,
        color_intrinsics: CameraIntrinsics,
        T_color_depth: npt.ArrayLike,
        depth_scale: float,
        *,
        copy: bool = True,
        hues: bool = True,
    ) -> ColoredPoints:
        """Select the points of one RGB-D frame.

        Parameters
        ----------
        depth : (H, W) ndarray
            Raw depth (uint16 units, or float with ``depth_scale=1``); 0 (and NaN) is no
            measurement.
        color : (Hc, Wc, 3) uint8 ndarray
            RGB colour image.
        depth_intrinsics : CameraIntrinsics
            Of the depth camera, ``W x H``.
        color_intrinsics : CameraIntrinsics
            Of the colour camera, ``Wc x Hc``.
        T_color_depth : (4, 4) array_like
            Depth frame to colour frame (librealsense's depth-to-colour extrinsics).
        depth_scale : float
            Metres per depth unit (0.001 on a D435).
        copy : bool
            False: the result's arrays are views of the selector's work buffers, valid
            until its next call (for a caller done with them by then, as
            :class:`~robopercept.pipelines.PlaneMeasurer` is; a board near the camera
            has 2 x 10^5 points, and copying them out cost 1.5 ms a frame).
        hues : bool
            False: skip the selected points' hues (``hue`` is None), for a caller that
            does not use them (the HSV conversion of 10^5 points takes 0.3 ms).

        Returns
        -------
        ColoredPoints
        """
        d, rgb, T, scale = _check_frame(
            depth, color, depth_intrinsics, color_intrinsics, T_color_depth, depth_scale
        )
        copy, hues = check_bool(copy, "copy"), check_bool(hues, "hues")
        kc = color_intrinsics
        flat = np.ascontiguousarray(d).reshape(-1)
        rays = self._unit_rays(depth_intrinsics)
        sep, rx, ry = self._separable, self._rx, self._ry
        w = depth_intrinsics.width
        if self._zbuf.shape[0] != kc.width * kc.height:
            self._zbuf = np.full(kc.width * kc.height, np.inf)
        tol = self.occlusion_tolerance
        k, model, coeffs = compiled_params(kc)
        buf = self._buffers(flat.shape[0], kc.width * kc.height)
        use_lut = flat.shape[0] >= _TABLE_PIXELS
        lut = _box_table(tuple(self.hsv_low), tuple(self.hsv_high)) if use_lut else _NO_TABLE
        pix, zc, out, hue, idx = (buf[name] for name in ("pix", "zc", "out", "hue", "idx"))
        flat_rgb = np.ascontiguousarray(rgb).reshape(-1)
        h = depth_intrinsics.height
        counts = np.zeros(_CHUNKS, dtype=np.int64)
        t0 = time.perf_counter()
        n_valid = _project_kernel(
            flat, w, sep, rx, ry, rays, scale,
            np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
            k, model, coeffs, kc.width, kc.height,
            flat_rgb, self.hsv_low, self.hsv_high, use_lut, lut, idx, pix, zc, counts,
        )  # fmt: skip
        try:
            if tol is not None:
                _zbuffer_kernel(pix, zc, self._zbuf, w, h, counts)
            t1 = time.perf_counter()
            m = _select_kernel(
                flat, w, sep, rx, ry, rays, scale, flat_rgb, idx, pix, zc, counts,
                self._zbuf, -1.0 if tol is None else tol, self.occlusion_grows, out,
                hues, hue,
            )  # fmt: skip
        finally:
            if tol is not None:
                _reset_kernel(pix, self._zbuf, w, h, counts)
        t2 = time.perf_counter()
        if copy:
            out, hue, idx = out[:m].copy(), hue[:m].copy(), idx[:m].copy()
        return ColoredPoints(
            points=out[:m],
            hue=hue[:m] if hues else None,
            pixels=idx[:m],
            n_valid=int(n_valid),
            ms={"points": (t1 - t0) * 1e3, "color": (t2 - t1) * 1e3},
        )


def _check_frame(
    depth: np.ndarray,
    color: np.ndarray,
    depth_intrinsics: CameraIntrinsics,
    color_intrinsics: CameraIntrinsics,
    T_color_depth: npt.ArrayLike,
    depth_scale: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The checked inputs of :meth:`ColorRangeSelector.__call__`."""
    check_intrinsics(depth_intrinsics, "depth_intrinsics")
    check_pixels(check_intrinsics(color_intrinsics, "color_intrinsics"), "color_intrinsics")
    d = check_depth(depth, depth_intrinsics, "depth_intrinsics")
    c = np.asarray(color)
    kc = color_intrinsics
    if c.ndim != 3 or c.shape[2] != 3:
        hint = ""
        if c.ndim == 3 and c.shape[2] == 4:
            hint = ": RGBA? drop alpha with color[..., :3]"
        elif c.ndim == 3 and c.shape[0] == 3:
            hint = ": channels-first? use color.transpose(1, 2, 0)"
        elif c.ndim == 2:
            hint = ": a gray image has no hue; pass the RGB colour stream"
        raise InputError(f"color must be an (H, W, 3) RGB image; got shape {c.shape}{hint}")
    if c.dtype != np.uint8:
        hint = (
            ": scale [0, 1] floats with (color * 255).round().astype(np.uint8)"
            if c.dtype.kind == "f"
            else ": convert it to 8 bits (16-bit: (color >> 8).astype(np.uint8))"
        )
        raise InputError(
            f"color must be uint8 (HSV bounds are on its 0..255 scale); got {c.dtype}{hint}"
        )
    if c.shape[:2] != (kc.height, kc.width):
        raise InputError(
            f"color is {c.shape[1]}x{c.shape[0]} but color_intrinsics describe "
            f"{kc.width}x{kc.height}: use the colour stream's intrinsics "
            "(CameraIntrinsics.scaled for another resolution)"
        )
    T = check_transform(T_color_depth, "T_color_depth")
    scale = check_real(depth_scale, "depth_scale (metres per unit)", 0.0, low_inclusive=False)
    return d, c, T, float(scale)


def points_in_color_range(
    depth: np.ndarray,
    color: np.ndarray,
    depth_intrinsics: CameraIntrinsics,
    color_intrinsics: CameraIntrinsics,
    T_color_depth: npt.ArrayLike,
    depth_scale: float,
    hsv_low: npt.ArrayLike,
    hsv_high: npt.ArrayLike,
    occlusion_tolerance: float | None = 0.02,
) -> ColoredPoints:
    """Points of a depth image whose colour lies in an HSV box, one-shot.

    ``ColorRangeSelector(hsv_low, hsv_high, occlusion_tolerance)(depth, color,
    depth_intrinsics, color_intrinsics, T_color_depth, depth_scale)``; see
    :class:`ColorRangeSelector` for the parameters and the method. For a stream of
    frames, keep one selector (it caches the depth camera's rays and its z-buffer).

    Returns
    -------
    ColoredPoints

    Examples
    --------
    >>> from robopercept.geometry import CameraIntrinsics
    >>> k = CameraIntrinsics(2, 1, 2.0, 2.0, 0.5, 0.0)
    >>> color = np.array([[[0, 255, 0], [255, 0, 0]]], np.uint8)
    >>> depth = np.array([[500, 500]], np.uint16)
    >>> box = (45, 35, 35), (65, 255, 255)
    >>> sel = points_in_color_range(depth, color, k, k, np.eye(4), 0.001, *box)
    >>> sel.pixels.tolist(), sel.points.tolist()
    ([0], [[-0.125, 0.0, 0.5]])
    """
    selector = ColorRangeSelector(hsv_low, hsv_high, occlusion_tolerance)
    return selector(depth, color, depth_intrinsics, color_intrinsics, T_color_depth, depth_scale)
