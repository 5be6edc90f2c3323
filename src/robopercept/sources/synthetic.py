r"""A synthetic D435-like RGB-D scene with ground truth, rendered analytically.

The scene is a room (floor, three walls, ceiling), boxes of several colours on the
floor (one of them a small green distractor), a green board that moves and rotates
along a smooth trajectory between about 0.6 and 2.4 m, leaving the view in part, and a
grey panel that passes in front of the camera for a moment. Every surface is a
rectangle; each pixel's ray is intersected with all of them and the nearest hit wins.

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

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from robopercept._checks import check_int, check_positive
from robopercept.depth import pixel_rays
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.transforms import invert, rotation_from_rotvec, se3
from robopercept.sources.frames import RGBDFrame

__all__ = ["BOARD_COLOR", "SyntheticRGBDScene"]

BOARD_COLOR = (60, 170, 60)  # OpenCV hue 60, saturation 165: inside the default HSV box
_BOARD_SIZE = (0.60, 0.45)  # metres
_ROOM = (-3.0, 3.0, -1.5, 1.2, 6.0)  # x min, x max, ceiling y, floor y, back wall z
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
def _nearest(rects, groups, ox, oy, oz, dx, dy, dz, t_max):  # pragma: no cover - compiled
    # groups: (start, stop, centre x, y, z, radius) of rectangles inside one bounding
    # sphere (a box's six faces); a group is skipped when the ray misses its sphere or
    # the sphere lies beyond the nearest hit so far
    best = t_max
    best_id = -1
    dd = dx * dx + dy * dy + dz * dz
    for g in range(groups.shape[0]):
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
def _cast_kernel(origin, dirs, rects, groups, t_out, id_out):  # pragma: no cover - compiled
    ox, oy, oz = origin[0], origin[1], origin[2]
    for i in prange(dirs.shape[0]):
        best, best_id = _nearest(
            rects, groups, ox, oy, oz, dirs[i, 0], dirs[i, 1], dirs[i, 2], np.inf
        )
        t_out[i] = best
        id_out[i] = best_id


@njit(cache=True, parallel=True)
def _visible_kernel(origin, targets, rects, groups, margin, out):  # pragma: no cover
    # out[i] &= no rectangle crosses the segment origin -> targets[i] (short of `margin`)
    ox, oy, oz = origin[0], origin[1], origin[2]
    for i in prange(targets.shape[0]):
        if not out[i]:
            continue
        dx = targets[i, 0] - ox
        dy = targets[i, 1] - oy
        dz = targets[i, 2] - oz
        t_max = 1.0 - margin / math.sqrt(dx * dx + dy * dy + dz * dz)
        if _nearest(rects, groups, ox, oy, oz, dx, dy, dz, t_max)[1] >= 0:
            out[i] = False


@njit(cache=True, nogil=True, inline="always")
def _splitmix(z):  # pragma: no cover - compiled
    z = z + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, parallel=True)
def _shade_kernel(origin, dirs, rects, groups, colors, light, noise, key, out):  # pragma: no cover
    ox, oy, oz = origin[0], origin[1], origin[2]
    for i in prange(dirs.shape[0]):
        best_id = _nearest(rects, groups, ox, oy, oz, dirs[i, 0], dirs[i, 1], dirs[i, 2], np.inf)[1]
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


def _static_scene() -> list[_Part]:
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
    for center, size, color in [
        ((-1.1, yf - 0.30, 3.0), (0.6, 0.6, 0.6), (200, 45, 40)),  # red
        ((1.3, yf - 0.35, 3.6), (0.7, 0.7, 0.5), (45, 70, 200)),  # blue
        ((0.4, yf - 0.20, 4.2), (0.8, 0.4, 0.4), (225, 200, 40)),  # yellow
        ((-1.1, yf - 0.70, 3.0), (0.2, 0.2, 0.2), (70, 160, 72)),  # green, on the red box
        ((2.2, yf - 0.75, 4.6), (0.5, 1.5, 0.5), (150, 150, 150)),  # grey cabinet
    ]:
        parts.append(_box_part(center, size, color))
    return parts


def board_pose(t: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and rotation (3, 3) of the board at time ``t`` in [0, 1) of a loop.

    The trajectory: depth 1.5 +- 0.9 m, sideways sweeps that take the board half out of
    view around t = 0.3, yaw +-40 deg, pitch +-25 deg, roll +-15 deg.
    """
    w = 2.0 * math.pi * t
    z = 1.5 - 0.9 * math.cos(w)
    x = 0.45 * z * math.sin(1.5 * w) + 0.35 * z * math.exp(-(((t - 0.3) / 0.05) ** 2))
    y = 0.08 * math.sin(2.0 * w) - 0.05
    yaw = math.radians(40.0) * math.sin(1.3 * w)
    pitch = math.radians(25.0) * math.sin(0.9 * w + 1.0)
    roll = math.radians(15.0) * math.sin(0.7 * w)
    r = (
        rotation_from_rotvec(np.array([0.0, yaw, 0.0]))
        @ rotation_from_rotvec(np.array([pitch, 0.0, 0.0]))
        @ rotation_from_rotvec(np.array([0.0, 0.0, roll]))
    )
    return np.array([x, y, z]), r


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

    def __post_init__(self) -> None:
        check_int(self.n_frames, "n_frames", 1)
        check_int(self.seed, "seed", 0)
        for name in ("depth_size", "color_size"):
            size = tuple(getattr(self, name))
            if len(size) != 2 or min(size) < 8 or not all(isinstance(v, int) for v in size):
                raise InputError(f"{name} must be (width, height) integers >= 8; got {size!r}")
            object.__setattr__(self, name, size)
        for name in ("fps", "depth_scale", "baseline", "max_depth", "period"):
            check_positive(getattr(self, name), name)
        for name in ("disparity_noise", "subpixel", "color_noise", "min_depth"):
            if not getattr(self, name) >= 0:
                raise InputError(f"{name} must be >= 0; got {getattr(self, name)}")
        for name in ("flying_pixel_rate", "dropout_rate"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise InputError(f"{name} must be in [0, 1]; got {getattr(self, name)}")
        wd, hd = self.depth_size
        wc, hc = self.color_size
        # D435: depth HFOV about 87 deg, colour HFOV about 69 deg; square pixels
        fd = (wd / 2) / math.tan(math.radians(87.0 / 2))
        fc = (wc / 2) / math.tan(math.radians(69.0 / 2))
        kd = CameraIntrinsics(wd, hd, fd, fd, (wd - 1) / 2 + 0.3, (hd - 1) / 2 - 0.4)
        kc = CameraIntrinsics(wc, hc, fc, fc, (wc - 1) / 2 - 0.6, (hc - 1) / 2 + 0.5)
        r = rotation_from_rotvec(np.array([0.002, -0.003, 0.001]))
        T_color_depth = se3(r, np.array([0.015, 0.0002, 0.0003]))
        object.__setattr__(self, "_kd", kd)
        object.__setattr__(self, "_kc", kc)
        object.__setattr__(self, "_T", T_color_depth)
        object.__setattr__(self, "_static", _static_scene())
        object.__setattr__(self, "_rays_d", None)
        object.__setattr__(self, "_rays_c", None)

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
        center, rot = board_pose(t)
        hw, hh = _BOARD_SIZE[0] / 2, _BOARD_SIZE[1] / 2
        board = _rect(center, rot[:, 0], rot[:, 1], hw, hh, two_sided=True)
        parts = list(self._static)  # type: ignore[attr-defined]
        board_id = sum(p[0].shape[0] for p in parts)
        parts.append((board[None], np.array([BOARD_COLOR], float), center, math.hypot(hw, hh)))
        if 0.60 <= t <= 0.72:
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

    def _render_depth(
        self, rects: np.ndarray, groups: np.ndarray, board_id: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        kd = self.depth_intrinsics
        h, w = kd.height, kd.width
        rays = self._rays_d  # type: ignore[attr-defined]
        z = np.empty(rays.shape[0])
        ids = np.empty(rays.shape[0], dtype=np.int64)
        _cast_kernel(np.zeros(3), rays, rects, groups, z, ids)
        hit = np.isfinite(z)
        pts = rays * np.where(hit, z, 0.0)[:, None]
        # the right imager must see the point: inside its image and not occluded
        f, b = kd.fx, self.baseline
        with np.errstate(invalid="ignore", divide="ignore"):
            u_right = f * (pts[:, 0] - b) / pts[:, 2] + kd.cx
        seen = hit & (u_right >= -0.5) & (u_right <= w - 0.5)
        _visible_kernel(np.array([b, 0.0, 0.0]), pts, rects, groups, 0.002, seen)
        z = np.where(seen, z, 0.0).reshape(h, w)
        board_mask = (ids == board_id).reshape(h, w)
        # flying pixels: mix a depth edge's two sides
        if self.flying_pixel_rate > 0:
            zz = np.where(z > 0, z, np.nan)
            left, right = zz[:, :-2], zz[:, 2:]
            with np.errstate(invalid="ignore"):
                edge = np.abs(left - right) > 0.05 * np.fmin(left, right)
            edge &= rng.random(edge.shape) < self.flying_pixel_rate
            a = rng.random(edge.shape)
            mixed = a * left + (1 - a) * right
            inner = z[:, 1:-1]
            inner[edge] = mixed[edge]
        # disparity noise, subpixel quantization, depth units
        valid = z > 0
        disp = f * b / np.where(valid, z, 1.0)
        disp = disp + rng.normal(0.0, self.disparity_noise, disp.shape)
        if self.subpixel > 0:
            disp = np.round(disp / self.subpixel) * self.subpixel
        valid &= disp > 0
        zq = f * b / np.where(valid, disp, 1.0)
        valid &= (zq >= self.min_depth) & (zq <= self.max_depth)
        if self.dropout_rate > 0:
            valid &= rng.random(valid.shape) >= self.dropout_rate
        raw = np.where(valid, np.rint(zq / self.depth_scale), 0.0)
        return np.clip(raw, 0, 65535).astype(np.uint16), board_mask

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
        _shade_kernel(origin, rays, rects, groups, colors, _LIGHT, noise, key, out)
        return out.reshape(kc.height, kc.width, 3)
