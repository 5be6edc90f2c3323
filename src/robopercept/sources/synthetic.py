r"""A synthetic D435-like RGB-D scene with ground truth, rendered analytically.

The scene is a room (floor, three walls, ceiling), boxes of several colours on the
floor (one of them a small green distractor), a green board that moves and rotates
between about 0.6 and 2.4 m along one of several motion profiles, leaving the view in
part, and a grey panel that passes in front of the camera for a moment. Every surface is
a rectangle; each pixel's ray is intersected with all of them and the nearest hit wins.

Motion profiles (``motion``, :data:`MOTIONS`; :func:`board_pose`). Time is
:math:`\tau = i / \text{fps}` seconds, taken modulo the loop of :math:`T` = ``period``
seconds, and :math:`t = \tau / T \in [0, 1)` in loops. The orientation is
:math:`R = R_y(\psi) R_x(\theta) R_z(\phi)` (yaw, pitch, roll); the board's normal is
:math:`R e_z` and stays within 50 deg of the optical axis, so the front is always seen.

* ``"smooth"`` (the default), at phase :math:`s = t`, :math:`w = 2 \pi s`:
  :math:`z = 1.5 - 0.9 \cos w`, :math:`x = 0.45 z \sin 1.5 w + 0.35 z
  e^{-((s - 0.3) / 0.05)^2}` (a sideways dash half out of view at t = 0.3),
  :math:`y = 0.08 \sin 2 w - 0.05`, :math:`\psi = 40^\circ \sin 1.3 w`,
  :math:`\theta = 25^\circ \sin(0.9 w + 1)`, :math:`\phi = 15^\circ \sin 0.7 w`. Speeds about
  0.55 m/s (median), 2 m/s in the dash.
* ``"fast"``: the same formulas at :math:`s = 3 t` (:data:`FAST_RATE`; the dash at
  :math:`s \bmod 1`): three passes per loop, 1.6 m/s median, about 6 m/s in the dashes,
  rotation rates up to about 110 deg/s; the position is continuous over the loop.
* ``"jerky"``: piecewise-linear between waypoints :math:`q_k = (x, y, z, \psi, \theta,
  \phi)` at knots :math:`\tau_k`, :math:`q(\tau) = q_k + (\tau - \tau_k)
  (q_{k+1} - q_k) / (\tau_{k+1} - \tau_k)`: constant velocity and rotation rate on
  each segment, jumps at the knots. Segment lengths are uniform in 0.2..0.6 s (scaled
  by at most a few percent to fill the loop); each step is, with probability 0.35, the
  previous one reversed and scaled by U(0.5, 1), otherwise a random direction at
  U(0.3, 1.5) m/s and angle rates U(-100, 100) deg/s; waypoints are clipped to
  :math:`z \in [0.8, 2.2]`, :math:`|x| \le 0.35 z`, :math:`y \in [-0.15, 0.05]`,
  :math:`|\psi| \le 35^\circ`, :math:`|\theta| \le 20^\circ`, :math:`|\phi| \le 15^\circ`.
  Drawn from ``numpy.random.default_rng([seed, 1])``.
* ``"stop-go"``: the smooth path at the phase :func:`stop_go_phase`: in each 2.5 s cycle
  the board dwells 0.5, 1.0, 1.5 or 0.8 s (in turn) with the pose exactly unchanged,
  then moves linearly in phase to catch up with the smooth schedule (1.25 to 2.5 times
  the smooth speed); the position is continuous.
* ``"handheld"``: the smooth pose plus hand motion, :math:`c = c_s + o_{1:3}(\tau)`,
  :math:`R = R_s \exp([o_{4:6}(\tau)]_\times)` with
  :math:`o_j(\tau) = \sum_m a_{jm} \sin(2 \pi f_{jm} \tau + \varphi_{jm})`: tremor,
  six sinusoids per axis at :math:`f` ~ U(3, 10) Hz giving 2 mm and 0.3 deg RMS per
  axis, and drift, two at U(0.05, 0.3) Hz of 3 mm and 0.3 deg amplitude. Drawn from
  ``numpy.random.default_rng([seed, 2])``.

The random profiles depend on ``seed`` and time only (never on the frame index), so
any frame can be rendered alone and in any order. Like the smooth path, every profile
may jump at the loop's end (the rotation of ``"fast"``, everything of the others).

Options: ``occluder`` (default True) is the grey 0.30 x 2.0 m panel crossing 0.5 m in
front of the camera between t = 0.62 and 0.70 (present for t in 0.60..0.72);
``distractor`` (:data:`DISTRACTORS`) is ``"box"`` (default: a 0.2 m green box on the red
box), ``"wall"`` (a 0.5 x 0.4 m patch of :data:`WALL_PATCH_COLOR` on the back wall at
x = -0.6, y = -0.4 m, in view most of the time; OpenCV hue 56, inside the default green
HSV box like the board), ``"both"`` or ``"none"``.

Depth is rendered from the left infrared imager (the depth origin, as on a D435) and
degraded the way active stereo degrades it:

* a point is measured only if the right imager, :math:`B` = 50 mm to the right, also
  sees it: this gives the invalid band on the left edge of the image (where the
  disparity :math:`f B / z` reaches past the right image) and the shadows left of
  foreground edges;
* noise is added in disparity, :math:`\delta = f B / z + \epsilon`,
  :math:`\epsilon \sim N(0, \sigma_d^2)` with :math:`\sigma_d` = 0.08 px, and quantized
  to 1/32 px (the D435's subpixel step), then back to depth and quantized to the depth
  unit (1 mm); hence :math:`\sigma_z \approx z^2 \sigma_d / (f B)`, about 2.4 mm at 1 m
  for :math:`f` = 640 px (1280x720) and 3.6 mm for :math:`f` = 425 px (848x480);
* flying pixels: a share of the pixels at depth edges take a depth between the two
  surfaces;
* random dropouts, and nothing nearer than ``min_depth`` or farther than ``max_depth``.

The colour camera is a separate pinhole :math:`t` = 15 mm to the side with its own
intrinsics and resolution, so colour must be aligned through the extrinsics. Surfaces
are shaded (ambient + Lambert) and get sensor noise.

Ground truth per frame (``RGBDFrame.ground_truth``): ``"plane"``, the board plane
``(n, d)`` with :math:`n^\top x = d`, :math:`d \ge 0` (n points from the camera toward
the board) in the depth camera frame; ``"board_mask"``, the depth pixels whose ray hits
the board (before any invalidation); ``"valid_board_pixels"``, how many of those have a
depth.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit, prange

from robopercept._checks import check_bool, check_int, check_real, check_size
from robopercept.depth import pixel_rays
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.transforms import invert, rotation_from_rotvec, se3
from robopercept.sources.frames import RGBDFrame

__all__ = [
    "BOARD_COLOR",
    "DISTRACTORS",
    "FAST_RATE",
    "MOTIONS",
    "WALL_PATCH_COLOR",
    "SyntheticRGBDScene",
    "board_pose",
    "stop_go_phase",
]

BOARD_COLOR = (60, 170, 60)  # OpenCV hue 60, saturation 165: inside the default HSV box
_BOARD_SIZE = (0.60, 0.45)  # metres
_ROOM = (-3.0, 3.0, -1.5, 1.2, 6.0)  # x min, x max, ceiling y, floor y, back wall z
_MARGIN = 0.002  # metres: a point counts as seen by the right imager up to this short of it
_LIGHT = np.array([0.3, -0.8, -0.5]) / np.linalg.norm([0.3, -0.8, -0.5])


# ------------------------------------------------------------------ ray casting kernels
# A rectangle is 15 numbers: centre c (3), unit axes a1, a2 (3 + 3), unit normal
# n = a1 x a2 (3), half sizes h1, h2, and a flag: 1 = seen from both sides, 0 = seen only
# from the side its normal points to (box faces point out, room surfaces in; both
# cameras are outside every box and inside the room, so back faces are never nearest).


@njit(cache=True, nogil=True, inline="always")
def _hit(rects, j, ox, oy, oz, dx, dy, dz, t_max):  # pragma: no cover - compiled
    nx = rects[j, 9]
    ny = rects[j, 10]
    nz = rects[j, 11]
    den = nx * dx + ny * dy + nz * dz
    if den >= 0.0 and (rects[j, 14] == 0.0 or den == 0.0):
        return np.inf
    cx = rects[j, 0] - ox
    cy = rects[j, 1] - oy
    cz = rects[j, 2] - oz
    t = (nx * cx + ny * cy + nz * cz) / den
    if t <= 1e-6 or t >= t_max:
        return np.inf
    px = t * dx - cx
    py = t * dy - cy
    pz = t * dz - cz
    if abs(rects[j, 3] * px + rects[j, 4] * py + rects[j, 5] * pz) > rects[j, 12]:
        return np.inf
    if abs(rects[j, 6] * px + rects[j, 7] * py + rects[j, 8] * pz) > rects[j, 13]:
        return np.inf
    return t


@njit(cache=True, nogil=True, inline="always")
def _nearest(rects, groups, g0, ox, oy, oz, dx, dy, dz, best, best_id):  # pragma: no cover
    # the nearest hit closer than `best` among groups g0, g0 + 1, ... (best_id: the hit
    # so far, -1 for none); groups: (start, stop, centre x, y, z, radius) of rectangles
    # inside one bounding sphere (a box's six faces); a group is skipped when the ray
    # misses its sphere or the sphere lies beyond the nearest hit so far. Groups are
    # visited in order and a hit must be strictly nearer, so continuing from g0 with the
    # nearest hit among groups < g0 gives the same hit as one pass over all of them.
    dd = dx * dx + dy * dy + dz * dz
    for g in range(g0, groups.shape[0]):
        r = groups[g, 5]
        if r < np.inf:
            cx = groups[g, 2] - ox
            cy = groups[g, 3] - oy
            cz = groups[g, 4] - oz
            tc = (cx * dx + cy * dy + cz * dz) / dd
            ex = cx - tc * dx
            ey = cy - tc * dy
            ez = cz - tc * dz
            if ex * ex + ey * ey + ez * ez > r * r:
                continue
            norm = math.sqrt(dd)
            if tc * norm + r < 0.0 or tc * norm - r > best * norm:
                continue
        for j in range(int(groups[g, 0]), int(groups[g, 1])):
            t = _hit(rects, j, ox, oy, oz, dx, dy, dz, best)
            if t < best:
                best = t
                best_id = j
    return best, best_id


@njit(cache=True, parallel=True)
def _cast_kernel(origin, dirs, rects, groups, g0, t_out, id_out):  # pragma: no cover - compiled
    # t_out, id_out: in, the nearest hit among groups < g0 (inf, -1 for none); out, the
    # nearest among all groups
    ox, oy, oz = origin[0], origin[1], origin[2]
    for i in prange(dirs.shape[0]):
        best, best_id = _nearest(
            rects, groups, g0, ox, oy, oz, dirs[i, 0], dirs[i, 1], dirs[i, 2], t_out[i], id_out[i]
        )
        t_out[i] = best
        id_out[i] = best_id


@njit(cache=True, parallel=True)
def _depth_kernel(
    rays,
    rects,
    groups,
    g0,
    t_still,
    id_still,
    seen_still,
    n_still,
    fx,
    cx,
    width,
    baseline,
    margin,
    t_out,
    id_out,
    seen_out,
):  # pragma: no cover - compiled
    # depth rays from the left imager (the origin): the nearest hit among groups g0, g0
    # + 1, ... continuing from the hits among groups < g0 (t_still, id_still: inf, -1
    # for none; see _nearest), and whether the right imager (at x = baseline) sees it:
    # inside its image and no rectangle across the segment to it, short of `margin`. A
    # hit on a rectangle id < n_still has its occluders among groups < g0 known in
    # seen_still, so only groups from g0 are tested for it.
    for i in prange(rays.shape[0]):
        dx, dy, dz = rays[i, 0], rays[i, 1], rays[i, 2]
        t, best_id = _nearest(rects, groups, g0, 0.0, 0.0, 0.0, dx, dy, dz, t_still[i], id_still[i])
        t_out[i] = t
        id_out[i] = best_id
        seen_out[i] = False
        if not t < np.inf:
            continue
        px, py, pz = dx * t, dy * t, dz * t
        u = fx * (px - baseline) / pz + cx
        if not (u >= -0.5 and u <= width - 0.5):
            continue
        start = 0
        if 0 <= best_id < n_still:
            if not seen_still[i]:
                continue
            start = g0
        ex, ey, ez = px - baseline, py - 0.0, pz - 0.0
        t_max = 1.0 - margin / math.sqrt(ex * ex + ey * ey + ez * ez)
        seen_out[i] = (
            _nearest(rects, groups, start, baseline, 0.0, 0.0, ex, ey, ez, t_max, -1)[1] < 0
        )


@njit(cache=True)
def _sensor_kernel(
    z,
    edge_draw,
    mix_draw,
    noise,
    drop_draw,
    fb,
    fly_rate,
    subpixel,
    z_min,
    z_max,
    scale,
    drop_rate,
    out,
):  # pragma: no cover - compiled
    # the depth sensor's effects on true depths z (H, W), 0 where unseen, written to out
    # (uint16 depth units): flying pixels (a pixel between two sides of a depth edge,
    # |z_l - z_r| > 5 % of the nearer, takes a random mix of them with probability
    # fly_rate), disparity noise, subpixel quantization of the disparity, the depth
    # range, dropouts. The draws come from the frame's generator, as NumPy would use
    # them elementwise: edge_draw, mix_draw (H, W - 2) and drop_draw (H, W) are uniform,
    # noise (H, W) normal (scaled).
    h, w = z.shape
    for i in range(h):
        for j in range(w):
            zij = z[i, j]
            if fly_rate > 0.0 and 1 <= j < w - 1:
                left = z[i, j - 1]
                right = z[i, j + 1]
                if left > 0.0 and right > 0.0:
                    if (
                        abs(left - right) > 0.05 * min(left, right)
                        and edge_draw[i, j - 1] < fly_rate
                    ):
                        a = mix_draw[i, j - 1]
                        zij = a * left + (1 - a) * right
            valid = zij > 0.0
            disp = fb / (zij if valid else 1.0)
            disp = disp + noise[i, j]
            if subpixel > 0.0:
                disp = np.rint(disp / subpixel) * subpixel
            valid = valid and disp > 0.0
            zq = fb / (disp if valid else 1.0)
            valid = valid and zq >= z_min and zq <= z_max
            if drop_rate > 0.0:
                valid = valid and drop_draw[i, j] >= drop_rate
            v = np.rint(zq / scale) if valid else 0.0
            out[i, j] = np.uint16(min(max(v, 0.0), 65535.0))


@njit(cache=True, nogil=True, inline="always")
def _splitmix(z):  # pragma: no cover - compiled
    z = z + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, parallel=True)
def _shade_kernel(
    origin, dirs, rects, groups, g0, t0, id0, colors, light, noise, key, out
):  # pragma: no cover - compiled
    # t0, id0: the nearest hit of each ray among groups < g0 (inf, -1 for none)
    ox, oy, oz = origin[0], origin[1], origin[2]
    for i in prange(dirs.shape[0]):
        best_id = _nearest(
            rects, groups, g0, ox, oy, oz, dirs[i, 0], dirs[i, 1], dirs[i, 2], t0[i], id0[i]
        )[1]
        if best_id < 0:
            for c in range(3):
                out[i, c] = 0
            continue
        lam = abs(
            rects[best_id, 9] * light[0]
            + rects[best_id, 10] * light[1]
            + rects[best_id, 11] * light[2]
        )
        shade = 0.45 + 0.55 * lam
        # sensor noise: one 64-bit hash of (key, pixel) gives six 10-bit uniforms; the
        # sum of two is triangular, rescaled to unit variance (sqrt 6)
        z = _splitmix(key + np.uint64(i) * np.uint64(0x632BE59BD9B4E019))
        for c in range(3):
            v = colors[best_id, c] * shade
            if noise > 0.0:
                u1 = float(z & np.uint64(1023)) / 1023.0
                u2 = float((z >> np.uint64(10)) & np.uint64(1023)) / 1023.0
                z = z >> np.uint64(20)
                v += noise * (u1 + u2 - 1.0) * 2.449489742783178
            v = math.floor(v + 0.5)
            out[i, c] = np.uint8(min(max(v, 0.0), 255.0))


def _rect(center, axis1, axis2, half1: float, half2: float, two_sided: bool = False) -> np.ndarray:
    a1 = np.asarray(axis1, dtype=np.float64)
    a2 = np.asarray(axis2, dtype=np.float64)
    a1 = a1 / np.linalg.norm(a1)
    a2 = a2 / np.linalg.norm(a2)
    n = np.cross(a1, a2)
    flag = 1.0 if two_sided else 0.0
    return np.concatenate([np.asarray(center, dtype=np.float64), a1, a2, n, [half1, half2, flag]])


def _box(center, size, color) -> tuple[list[np.ndarray], list[tuple[int, int, int]]]:
    c = np.asarray(center, dtype=np.float64)
    sx, sy, sz = (s / 2 for s in size)
    ex, ey, ez = np.eye(3)
    # a1 x a2 points out of the box on every face
    faces = [
        _rect(c - sz * ez, ey, ex, sy, sx),
        _rect(c + sz * ez, ex, ey, sx, sy),
        _rect(c - sx * ex, ez, ey, sz, sy),
        _rect(c + sx * ex, ey, ez, sy, sz),
        _rect(c - sy * ey, ex, ez, sx, sz),
        _rect(c + sy * ey, ez, ex, sz, sx),
    ]
    return faces, [color] * 6


# a part of the scene: its rectangles (R, 15), their colours (R, 3) and a bounding sphere
# (centre, radius; radius inf for the room, which contains the cameras)
_Part = tuple[np.ndarray, np.ndarray, np.ndarray, float]


def _box_part(center, size, color) -> _Part:
    faces, colors = _box(center, size, color)
    radius = 0.5 * float(np.linalg.norm(size)) * 1.0001
    return np.array(faces), np.array(colors, dtype=np.float64), np.asarray(center, float), radius


def _static_scene(distractor: str = "box") -> list[_Part]:
    """The room and the boxes; ``distractor`` (one of :data:`DISTRACTORS`) adds the small
    green box on the red box (``"box"``), the green patch on the back wall (``"wall"``),
    or both."""
    x0, x1, yc, yf, zb = _ROOM
    ex, ey, ez = np.eye(3)
    cx, cy = (x0 + x1) / 2, (yc + yf) / 2
    hx, hy, hz = (x1 - x0) / 2, (yf - yc) / 2, (zb + 1.0) / 2
    zc = zb - hz
    # a1 x a2 points into the room on every surface
    room = [
        _rect((cx, yf, zc), ex, ez, hx, hz),  # floor (normal -y, up)
        _rect((cx, yc, zc), ez, ex, hz, hx),  # ceiling (normal +y, down)
        _rect((cx, cy, zb), ey, ex, hy, hx),  # back wall (normal -z)
        _rect((x0, cy, zc), ey, ez, hy, hz),  # left wall (normal +x)
        _rect((x1, cy, zc), ez, ey, hz, hy),  # right wall (normal -x)
    ]
    colors = [(125, 112, 100), (215, 215, 210), (205, 192, 168), (165, 172, 192), (180, 176, 170)]
    parts: list[_Part] = [
        (np.array(room), np.array(colors, dtype=np.float64), np.zeros(3), math.inf)
    ]
    boxes = [
        ((-1.1, yf - 0.30, 3.0), (0.6, 0.6, 0.6), (200, 45, 40)),  # red
        ((1.3, yf - 0.35, 3.6), (0.7, 0.7, 0.5), (45, 70, 200)),  # blue
        ((0.4, yf - 0.20, 4.2), (0.8, 0.4, 0.4), (225, 200, 40)),  # yellow
        ((-1.1, yf - 0.70, 3.0), (0.2, 0.2, 0.2), (70, 160, 72)),  # green, on the red box
        ((2.2, yf - 0.75, 4.6), (0.5, 1.5, 0.5), (150, 150, 150)),  # grey cabinet
    ]
    if distractor in ("none", "wall"):
        del boxes[3]
    for center, size, color in boxes:
        parts.append(_box_part(center, size, color))
    if distractor in ("wall", "both"):
        # 0.5 m wide, 0.4 m tall, 3 mm in front of the back wall, facing the camera; the
        # ray from the camera to it passes clear of every box
        patch_center = np.array([-0.6, -0.4, zb - 0.003])
        patch = _rect(patch_center, ey, ex, 0.20, 0.25)
        patch_color = np.array([WALL_PATCH_COLOR], float)
        parts.append((patch[None], patch_color, patch_center, math.hypot(0.20, 0.25)))
    return parts


MOTIONS = ("smooth", "fast", "jerky", "stop-go", "handheld")
DISTRACTORS = ("none", "box", "wall", "both")
FAST_RATE = 3.0  # the fast profile runs the smooth path this many times per loop
WALL_PATCH_COLOR = (70, 160, 55)  # OpenCV hue 56, saturation 167: inside the default box
# the jerky profile's workspace: depth, lateral extent (times the depth), height, and
# the yaw, pitch, roll limits (degrees)
_JERKY_Z = (0.8, 2.2)
_JERKY_X_PER_Z = 0.35
_JERKY_Y = (-0.15, 0.05)
_JERKY_ANGLES = (35.0, 20.0, 15.0)
_STOP_GO_CYCLE = 2.5  # seconds: one dwell plus one catch-up move
_STOP_GO_DWELLS = (0.5, 1.0, 1.5, 0.8)  # seconds, used in turn


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """:math:`R = R_y(\\text{yaw}) R_x(\\text{pitch}) R_z(\\text{roll})` (3, 3)."""
    return (
        rotation_from_rotvec(np.array([0.0, yaw, 0.0]))
        @ rotation_from_rotvec(np.array([pitch, 0.0, 0.0]))
        @ rotation_from_rotvec(np.array([0.0, 0.0, roll]))
    )


def _smooth_pose(s: float, s_bump: float) -> tuple[np.ndarray, np.ndarray]:
    """The smooth path at phase ``s`` (loops, unwrapped) with the sideways dash at the
    loop phase ``s_bump`` in [0, 1)."""
    w = 2.0 * math.pi * s
    z = 1.5 - 0.9 * math.cos(w)
    x = 0.45 * z * math.sin(1.5 * w) + 0.35 * z * math.exp(-(((s_bump - 0.3) / 0.05) ** 2))
    y = 0.08 * math.sin(2.0 * w) - 0.05
    yaw = math.radians(40.0) * math.sin(1.3 * w)
    pitch = math.radians(25.0) * math.sin(0.9 * w + 1.0)
    roll = math.radians(15.0) * math.sin(0.7 * w)
    return np.array([x, y, z]), _rotation(yaw, pitch, roll)


@functools.lru_cache(maxsize=32)
def _jerky_waypoints(seed: int, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Knot times (K + 1,) in seconds, from 0 to ``period``, and waypoints (K + 1, 6):
    ``x, y, z, yaw, pitch, roll`` (radians), drawn from ``default_rng([seed, 1])``."""
    rng = np.random.default_rng([seed, 1])
    durations: list[float] = []
    while sum(durations) < period:
        durations.append(float(rng.uniform(0.2, 0.6)))
    times = np.concatenate([[0.0], np.cumsum(durations) * (period / sum(durations))])
    zlo, zhi = _JERKY_Z
    lim = np.radians(_JERKY_ANGLES)
    p = np.array([0.0, -0.05, 1.5, 0.0, 0.0, 0.0])
    points = [p]
    prev_step = np.zeros(6)
    for d in np.diff(times):
        if rng.random() < 0.35 and np.any(prev_step):
            # a reversal: go back along the last segment, part or all of the way
            step = -prev_step * rng.uniform(0.5, 1.0)
        else:
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            step = np.concatenate(
                [
                    direction * rng.uniform(0.3, 1.5) * d,  # 0.3 .. 1.5 m/s
                    rng.uniform(-1.0, 1.0, 3) * np.radians(100.0) * d,  # <= 100 deg/s
                ]
            )
        q = points[-1] + step
        q[2] = min(max(q[2], zlo), zhi)
        q[0] = min(max(q[0], -_JERKY_X_PER_Z * q[2]), _JERKY_X_PER_Z * q[2])
        q[1] = min(max(q[1], _JERKY_Y[0]), _JERKY_Y[1])
        q[3:] = np.clip(q[3:], -lim, lim)
        prev_step = q - points[-1]
        points.append(q)
    return times, np.array(points)


@functools.lru_cache(maxsize=32)
def _handheld_terms(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies (Hz), phases and amplitudes (6, M) of the hand's sinusoids: rows are
    x, y, z (metres) and the rotation vector (radians); columns 0..5 are the tremor
    (3..10 Hz, 2 mm and 0.3 deg RMS per axis), 6..7 the drift (0.05..0.3 Hz, 3 mm and
    0.3 deg amplitude). Drawn from ``default_rng([seed, 2])``."""
    rng = np.random.default_rng([seed, 2])
    n_tremor, n_drift = 6, 2
    freq = np.concatenate(
        [rng.uniform(3.0, 10.0, (6, n_tremor)), rng.uniform(0.05, 0.3, (6, n_drift))], axis=1
    )
    phase = rng.uniform(0.0, 2.0 * math.pi, freq.shape)
    # a sum of M sinusoids of amplitude a has RMS a sqrt(M / 2)
    tremor_rms = np.array([0.002] * 3 + [math.radians(0.3)] * 3)
    drift_amp = np.array([0.003] * 3 + [math.radians(0.3)] * 3)
    amp = np.concatenate(
        [
            np.repeat((tremor_rms / math.sqrt(n_tremor / 2))[:, None], n_tremor, axis=1),
            np.repeat(drift_amp[:, None], n_drift, axis=1),
        ],
        axis=1,
    )
    return freq, phase, amp


def stop_go_phase(t: float, period: float = 10.0) -> float:
    r"""Phase of the smooth path reached at loop time ``t`` by the stop-go profile.

    With :math:`\tau = t T` seconds (:math:`T` = ``period``), cycle :math:`k =
    \lfloor \tau / C \rfloor` of :math:`C` = 2.5 s dwells :math:`D_k` seconds
    (0.5, 1.0, 1.5, 0.8 s in turn) and then moves linearly to the smooth schedule's
    phase at the cycle's end:

    .. math:: s(\tau) = \frac{k C + C \max(0, \tau - k C - D_k) / (C - D_k)}{T}

    so :math:`s` is continuous, exactly constant during a dwell and
    :math:`C / (C - D_k)` (1.25 to 2.5) times the smooth rate during a move.

    Parameters
    ----------
    t : float
        Time in loops (``seconds / period``), in [0, 1).
    period : float
        Seconds of one loop.

    Returns
    -------
    float
        The phase in [0, 1] at which to evaluate the smooth path.

    Examples
    --------
    >>> stop_go_phase(0.01), stop_go_phase(0.25)  # still at 0.1 s; on schedule at 2.5 s
    (0.0, 0.25)
    """
    tau = t * period
    c = _STOP_GO_CYCLE
    k = math.floor(tau / c)
    dwell = _STOP_GO_DWELLS[k % len(_STOP_GO_DWELLS)]
    moved = max(0.0, tau - k * c - dwell) / (c - dwell)
    return (k * c + c * min(moved, 1.0)) / period


def board_pose(
    t: float, motion: str = "smooth", seed: int = 0, period: float = 10.0
) -> tuple[np.ndarray, np.ndarray]:
    r"""Centre (3,) and rotation (3, 3) of the board at time ``t`` in loops.

    ``t`` is in loops, :math:`t = \tau / T` for :math:`\tau` seconds into a loop of
    :math:`T` = ``period`` seconds, in [0, 1) (``SyntheticRGBDScene`` passes
    ``(i / fps / period) % 1``). The rotation's columns are the board's width axis,
    height axis and normal, in the depth camera frame; :math:`R = R_y(\text{yaw})
    R_x(\text{pitch}) R_z(\text{roll})`. The profiles (see the module docstring for
    the formulas):

    * ``"smooth"``: depth :math:`1.5 - 0.9 \cos 2\pi t` m, sideways sweeps that take the
      board half out of view around t = 0.3, yaw +-40 deg, pitch +-25 deg, roll +-15 deg;
    * ``"fast"``: the smooth formulas at phase :math:`3 t` (three sweeps per loop);
    * ``"jerky"``: constant-velocity segments of 0.2..0.6 s between seeded waypoints;
    * ``"stop-go"``: the smooth path at phase :func:`stop_go_phase`;
    * ``"handheld"``: the smooth path plus seeded tremor and drift.

    Parameters
    ----------
    t : float
        Time in loops, in [0, 1).
    motion : str
        One of :data:`MOTIONS`.
    seed : int
        Seeds the ``"jerky"`` waypoints and the ``"handheld"`` tremor (others ignore it).
    period : float
        Seconds of one loop; the profiles defined in seconds (jerky segments, stop-go
        dwells, tremor frequencies) use it.

    Returns
    -------
    center : (3,) ndarray
        Board centre in metres.
    rotation : (3, 3) ndarray
        Board orientation.

    Examples
    --------
    >>> c, r = board_pose(0.0)
    >>> c.round(3).tolist()
    [0.0, -0.05, 0.6]
    """
    if motion not in MOTIONS:
        raise InputError(f"motion must be one of {', '.join(MOTIONS)}; got {motion!r}")
    if motion == "smooth":
        return _smooth_pose(t, t)
    if motion == "fast":
        s = FAST_RATE * t
        return _smooth_pose(s, s % 1.0)
    if motion == "stop-go":
        s = stop_go_phase(t, period)
        return _smooth_pose(s, s)
    tau = t * period
    if motion == "jerky":
        times, points = _jerky_waypoints(int(seed), float(period))
        k = min(max(int(np.searchsorted(times, tau, side="right")) - 1, 0), len(times) - 2)
        a = (tau - times[k]) / (times[k + 1] - times[k])
        q = (1.0 - a) * points[k] + a * points[k + 1]
        return q[:3].copy(), _rotation(q[3], q[4], q[5])
    # handheld
    center, rot = _smooth_pose(t, t)
    freq, phase, amp = _handheld_terms(int(seed))
    offset = (amp * np.sin(2.0 * math.pi * freq * tau + phase)).sum(axis=1)
    return center + offset[:3], rot @ rotation_from_rotvec(offset[3:])


def _occluder_x(t: float) -> float:
    # the grey panel crosses the view at 0.5 m between t = 0.62 and t = 0.70
    return -1.2 + 2.4 * (t - 0.62) / 0.08


@dataclass(frozen=True)
class SyntheticRGBDScene:
    """A seeded synthetic RGB-D sequence with ground truth (see the module docstring).

    Parameters
    ----------
    n_frames : int
        Frames in the sequence.
    seed : int
        Seeds every random degradation; frame ``i`` depends only on ``(seed, i)``, so
        frames can be rendered in any order.
    depth_size, color_size : (width, height)
        Resolutions of the depth and colour streams (default 848x480 and 1280x720).
    fps : float
        Frame rate; timestamps are ``i / fps``.
    disparity_noise : float
        RMS disparity noise in pixels (D435: about 0.08).
    subpixel : float
        Disparity quantization step in pixels (D435: 1/32).
    depth_scale : float
        Metres per depth unit (D435: 0.001).
    baseline : float
        Stereo baseline in metres (D435: 0.050).
    flying_pixel_rate, dropout_rate : float
        Share of depth-edge pixels made flying pixels; share of all pixels dropped.
    min_depth, max_depth : float
        Measurable range in metres.
    color_noise : float
        RMS colour noise in 8-bit levels.
    period : float
        Seconds of one loop of the board's trajectory (the default sequence, 300 frames
        at 30 fps, is one loop); the trajectory depends on time, not on ``n_frames``.
    motion : str
        The board's motion profile, one of :data:`MOTIONS`: ``"smooth"`` (default),
        ``"fast"`` (the smooth path 3x faster), ``"jerky"`` (constant-velocity
        segments of 0.2..0.6 s with abrupt turns and reversals), ``"stop-go"`` (dwells of
        0.5..1.5 s with the pose exactly still, then fast catch-up moves),
        ``"handheld"`` (the smooth path plus 3..10 Hz tremor of a few mm and a slow
        drift); formulas in the module docstring. ``seed`` also seeds the ``"jerky"``
        waypoints and the ``"handheld"`` tremor.
    occluder : bool
        Whether the grey panel passes in front of the camera (t 0.60..0.72 of the loop).
    distractor : str
        Green things that are not the board, one of :data:`DISTRACTORS`: ``"box"``
        (default, the small green box on the red box), ``"wall"`` (a 0.5 x 0.4 m green
        patch on the back wall), ``"both"`` or ``"none"``.
    depth_hfov, color_hfov : float
        Horizontal fields of view of the depth and colour cameras, degrees in (1, 170]
        (D435: about 87 and 69, the defaults; a Kinect-style 640x480 camera such as
        TUM's fr1 has about 62 for both). The focal lengths are
        :math:`f = (w / 2) / \\tan(\\mathrm{hfov} / 2)` with square pixels.

    Examples
    --------
    >>> scene = SyntheticRGBDScene(n_frames=3, depth_size=(212, 120), color_size=(320, 180))
    >>> frame = next(iter(scene))
    >>> frame.depth.shape, frame.color.shape, sorted(frame.ground_truth)
    ((120, 212), (180, 320, 3), ['board_mask', 'plane', 'valid_board_pixels'])
    """

    n_frames: int = 300
    seed: int = 0
    depth_size: tuple[int, int] = (848, 480)
    color_size: tuple[int, int] = (1280, 720)
    fps: float = 30.0
    disparity_noise: float = 0.08
    subpixel: float = 1.0 / 32.0
    depth_scale: float = 0.001
    baseline: float = 0.050
    flying_pixel_rate: float = 0.3
    dropout_rate: float = 0.003
    min_depth: float = 0.2
    max_depth: float = 10.0
    color_noise: float = 2.0
    period: float = 10.0
    motion: str = "smooth"
    occluder: bool = True
    distractor: str = "box"
    depth_hfov: float = 87.0
    color_hfov: float = 69.0

    def __post_init__(self) -> None:
        check_int(self.n_frames, "n_frames", 1)
        if not isinstance(self.motion, str) or self.motion not in MOTIONS:
            raise InputError(f"motion must be one of {', '.join(MOTIONS)}; got {self.motion!r}")
        if not isinstance(self.distractor, str) or self.distractor not in DISTRACTORS:
            raise InputError(
                f"distractor must be one of {', '.join(DISTRACTORS)}; got {self.distractor!r}"
            )
        check_bool(self.occluder, "occluder")
        check_int(self.seed, "seed", 0)
        for name in ("depth_size", "color_size"):
            # each frame renders a few float64 arrays per pixel: 2**24 pixels (4K UHD has
            # 2**23) keep a frame within a few GiB
            size = check_size(getattr(self, name), name, minimum=8, max_pixels=1 << 24)
            object.__setattr__(self, name, size)
        for name in ("fps", "depth_scale", "baseline", "max_depth", "period"):
            object.__setattr__(
                self, name, check_real(getattr(self, name), name, 0.0, low_inclusive=False)
            )
        for name in ("disparity_noise", "subpixel", "color_noise", "min_depth"):
            object.__setattr__(self, name, check_real(getattr(self, name), name, 0.0))
        for name in ("flying_pixel_rate", "dropout_rate"):
            object.__setattr__(self, name, check_real(getattr(self, name), name, 0.0, 1.0))
        for name in ("depth_hfov", "color_hfov"):
            object.__setattr__(
                self,
                name,
                check_real(getattr(self, name), name, 1.0, 170.0, low_inclusive=False),
            )
        wd, hd = self.depth_size
        wc, hc = self.color_size
        # D435 by default: depth HFOV about 87 deg, colour HFOV about 69 deg; square pixels
        fd = (wd / 2) / math.tan(math.radians(self.depth_hfov / 2))
        fc = (wc / 2) / math.tan(math.radians(self.color_hfov / 2))
        kd = CameraIntrinsics(wd, hd, fd, fd, (wd - 1) / 2 + 0.3, (hd - 1) / 2 - 0.4)
        kc = CameraIntrinsics(wc, hc, fc, fc, (wc - 1) / 2 - 0.6, (hc - 1) / 2 + 0.5)
        r = rotation_from_rotvec(np.array([0.002, -0.003, 0.001]))
        T_color_depth = se3(r, np.array([0.015, 0.0002, 0.0003]))
        object.__setattr__(self, "_kd", kd)
        object.__setattr__(self, "_kc", kc)
        object.__setattr__(self, "_T", T_color_depth)
        object.__setattr__(self, "_static", _static_scene(self.distractor))
        object.__setattr__(self, "_rays_d", None)
        object.__setattr__(self, "_rays_c", None)
        object.__setattr__(self, "_still", None)

    # -------------------------------------------------------------- calibration
    @property
    def depth_intrinsics(self) -> CameraIntrinsics:
        """Pinhole intrinsics of the depth camera (``depth_size``, no distortion)."""
        return self._kd  # type: ignore[attr-defined]

    @property
    def color_intrinsics(self) -> CameraIntrinsics:
        """Pinhole intrinsics of the colour camera (``color_size``, no distortion)."""
        return self._kc  # type: ignore[attr-defined]

    @property
    def T_color_depth(self) -> np.ndarray:
        """4x4 pose of the depth camera in the colour camera frame (a copy): maps
        depth-frame points into the colour frame."""
        return self._T.copy()  # type: ignore[attr-defined]

    def __len__(self) -> int:
        return self.n_frames

    def __iter__(self) -> Iterator[RGBDFrame]:
        for i in range(self.n_frames):
            yield self.frame(i)

    # -------------------------------------------------------------- rendering
    def _scene(
        self, t: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, tuple[np.ndarray, float]]:
        """Rectangles, colours, groups, the board's rectangle index and its plane."""
        center, rot = board_pose(t, self.motion, self.seed, self.period)
        hw, hh = _BOARD_SIZE[0] / 2, _BOARD_SIZE[1] / 2
        board = _rect(center, rot[:, 0], rot[:, 1], hw, hh, two_sided=True)
        parts = list(self._static)  # type: ignore[attr-defined]
        board_id = sum(p[0].shape[0] for p in parts)
        parts.append((board[None], np.array([BOARD_COLOR], float), center, math.hypot(hw, hh)))
        if self.occluder and 0.60 <= t <= 0.72:
            parts.append(_box_part((_occluder_x(t), 0.0, 0.5), (0.30, 2.0, 0.04), (128,) * 3))
        rects = np.concatenate([p[0] for p in parts])
        colors = np.concatenate([p[1] for p in parts])
        groups = np.zeros((len(parts), 6))
        start = 0
        for g, (r, _, c, radius) in enumerate(parts):
            groups[g] = (start, start + r.shape[0], *c, radius)
            start += r.shape[0]
        n = rot[:, 2].copy()
        d = float(n @ center)
        if d < 0:
            n, d = -n, -d
        return rects, colors, groups, board_id, (n, d)

    def frame(self, index: int) -> RGBDFrame:
        """Render frame ``index`` (0 <= index < n_frames)."""
        i = check_int(index, "index", 0)
        if i >= self.n_frames:
            raise InputError(f"index must be < n_frames = {self.n_frames}; got {i}")
        t = (i / self.fps / self.period) % 1.0
        rects, colors, groups, board_id, plane = self._scene(t)
        rng = np.random.default_rng([self.seed, i])
        kd, kc = self.depth_intrinsics, self.color_intrinsics
        if self._rays_d is None:  # type: ignore[attr-defined]
            object.__setattr__(self, "_rays_d", pixel_rays(kd))
            # colour rays turned into the depth frame once (the rig is rigid)
            r_depth_color = invert(self._T)[:3, :3]  # type: ignore[attr-defined]
            object.__setattr__(
                self, "_rays_c", np.ascontiguousarray(pixel_rays(kc) @ r_depth_color.T)
            )
        if self._still is None:  # type: ignore[attr-defined]
            object.__setattr__(self, "_still", self._cast_static(rects, groups))
        depth, board_mask = self._render_depth(rects, groups, board_id, rng)
        color = self._render_color(rects, groups, colors, rng)
        return RGBDFrame(
            index=i,
            timestamp=i / self.fps,
            depth=depth,
            color=color,
            depth_intrinsics=kd,
            color_intrinsics=kc,
            T_color_depth=self.T_color_depth,
            depth_scale=self.depth_scale,
            ground_truth={
                "plane": plane,
                "board_mask": board_mask,
                "valid_board_pixels": int(np.count_nonzero(board_mask & (depth > 0))),
            },
        )

    def _cast_static(self, rects: np.ndarray, groups: np.ndarray) -> dict[str, Any]:
        """Cast every ray against the still part of the scene (the room, the boxes, the
        distractors: the first ``len(self._static)`` groups), once; each frame then
        casts against the moving board and occluder only, starting from these hits
        (:func:`_nearest` continues a pass exactly)."""
        n_groups = len(self._static)  # type: ignore[attr-defined]
        still = groups[:n_groups]
        rays_d, rays_c = self._rays_d, self._rays_c  # type: ignore[attr-defined]
        z, ids, seen = self._cast_depth(
            rects, still, 0, np.full(rays_d.shape[0], np.inf),
            np.full(rays_d.shape[0], -1, dtype=np.int64), np.zeros(0, bool), 0,
        )  # fmt: skip
        tc = np.full(rays_c.shape[0], np.inf)
        idc = np.full(rays_c.shape[0], -1, dtype=np.int64)
        origin = np.ascontiguousarray(invert(self._T)[:3, 3])  # type: ignore[attr-defined]
        _cast_kernel(origin, rays_c, rects, still, 0, tc, idc)
        return {
            "groups": n_groups,
            "rects": int(groups[n_groups - 1, 1]),
            "z": z,
            "ids": ids,
            "seen": seen,
            "tc": tc,
            "idc": idc,
        }

    def _cast_depth(
        self,
        rects: np.ndarray,
        groups: np.ndarray,
        g0: int,
        t_still: np.ndarray,
        id_still: np.ndarray,
        seen_still: np.ndarray,
        n_still: int,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # the depth rays' hits, rectangle ids and whether the right imager sees them
        # (:func:`_depth_kernel`)
        kd, rays = self.depth_intrinsics, self._rays_d  # type: ignore[attr-defined]
        n = rays.shape[0]
        t, ids, seen = np.empty(n), np.empty(n, dtype=np.int64), np.empty(n, dtype=bool)
        _depth_kernel(
            rays, rects, groups, g0, t_still, id_still, seen_still, n_still, kd.fx, kd.cx,
            kd.width, self.baseline, _MARGIN, t, ids, seen,
        )  # fmt: skip
        return t, ids, seen

    def _render_depth(
        self, rects: np.ndarray, groups: np.ndarray, board_id: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        kd = self.depth_intrinsics
        h, w = kd.height, kd.width
        still = self._still  # type: ignore[attr-defined]
        t, ids, seen = self._cast_depth(
            rects, groups, still["groups"], still["z"], still["ids"], still["seen"],
            still["rects"],
        )  # fmt: skip
        z = np.where(seen, t, 0.0).reshape(h, w)
        f, b = kd.fx, self.baseline
        board_mask = (ids == board_id).reshape(h, w)
        # the sensor's effects from seeded draws (in this order, whether or not used)
        # applied in one compiled pass (:func:`_sensor_kernel`)
        fly = self.flying_pixel_rate > 0
        edge_draw = rng.random((h, w - 2)) if fly else np.zeros((1, 1))
        mix_draw = rng.random((h, w - 2)) if fly else np.zeros((1, 1))
        noise = rng.normal(0.0, self.disparity_noise, (h, w))
        drop = self.dropout_rate > 0
        drop_draw = rng.random((h, w)) if drop else np.zeros((1, 1))
        out = np.empty((h, w), np.uint16)
        _sensor_kernel(
            z, edge_draw, mix_draw, noise, drop_draw, float(f * b), self.flying_pixel_rate,
            float(self.subpixel), self.min_depth, self.max_depth, self.depth_scale,
            self.dropout_rate, out,
        )  # fmt: skip
        return out, board_mask

    def _render_color(
        self, rects: np.ndarray, groups: np.ndarray, colors: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        kc = self.color_intrinsics
        T_depth_color = invert(self._T)  # type: ignore[attr-defined]
        rays = self._rays_c  # type: ignore[attr-defined]
        out = np.empty((rays.shape[0], 3), dtype=np.uint8)
        key = np.uint64(rng.integers(0, 2**63))
        origin = np.ascontiguousarray(T_depth_color[:3, 3])
        noise = float(self.color_noise)
        still = self._still  # type: ignore[attr-defined]
        g0, t0, id0 = still["groups"], still["tc"], still["idc"]
        _shade_kernel(origin, rays, rects, groups, g0, t0, id0, colors, _LIGHT, noise, key, out)
        return out.reshape(kc.height, kc.width, 3)
