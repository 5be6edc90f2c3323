r"""Pose data with exact ground truth: procedural articulated figures, posed in 3-D, seen
from random cameras and rendered over real photos with self-occlusion.

The figure
----------
A 3-D kinematic tree in the :data:`~robopercept.nn.skeleton.MPII_16` layout, in metres,
in the figure's own frame (x to the figure's left, y up, z the way it faces), rooted at
the pelvis. Bone lengths are those of a 1.7 m adult (thigh 0.44, shin 0.42, spine
0.48, neck 0.10, head 0.22, upper arm 0.30, forearm 0.27, hip half-width 0.10,
shoulder half-width 0.19) times a body scale ``U(0.85, 1.15)`` and a per-bone factor
``U(0.92, 1.08)`` (left and right alike). :func:`random_poses_3d` draws joint angles
uniformly within limits (degrees):

========================  =========================================================
joint                     rotation
========================  =========================================================
spine                     lean forward -15..35, sideways -15..15, twist -35..35
neck                      nod -20..35, tilt -20..20
hip (each)                flexion -30..100, abduction -10..45
knee (each)               flexion 0..130 (the shin bends back)
shoulder (each)           elevation from hanging 0..170, swing about the vertical
                          -100..100
elbow (each)              flexion 0..145 in a plane rolled -90..90 about the upper arm
========================  =========================================================

The camera and the picture
--------------------------
:func:`procedural_pose_set` turns each figure by a yaw ``U(-75, 75)`` degrees away from
facing the camera (so its front, with a face, is seen and left and right are
defined by the picture), places a pinhole camera at an elevation ``U(-10, 30)`` degrees
and a distance ``U(3, 6)`` m looking at the figure's middle (OpenCV's camera frame: x
right, y down, z forward), and chooses the focal length so that the figure's 3-D
height spans ``U(scale)`` of the image height; the principal point is shifted so the
figure lies anywhere inside the image. The body is drawn as 3-D capsules (limbs, a
three-capsule torso, a head sphere with two eyes on its front) through a z-buffer:
each pixel shows the nearest capsule surface, shaded as a cylinder and textured
(shirt on torso and upper arms, trousers on the legs, skin on forearms and head,
each a random colour and pattern), over a random crop of a real photo (as the
detection sets). With probability ``occlusion`` a textured bar crosses the figure.

Ground truth
------------
For every image: the 2-D joints ``(J, 3)`` ``(x, y, v)`` in pixels (the pixel-centre
convention of :mod:`robopercept.nn.ops.boxes`: pixel ``(c, r)`` covers
``[c, c + 1) x [r, r + 1)``, so a point at the centre of pixel ``(c, r)`` is
``(c + 0.5, r + 0.5)``), with COCO's visibility ``v``: 2 where the joint is seen, 1
where another part (or the bar) hides it (the nearest surface at its pixel lies more
than the joint's own limb radius in front of it), 0 outside the image; the 3-D joints
in the camera frame (metres); the camera matrix; the tight box of the figure's visible
silhouette (``xyxy``) and its mask.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from robopercept._checks import (
    as_rng,
    check_choice,
    check_int,
    check_numeric,
    check_real,
    check_size,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.nn.coco.dataset import coco_from_dict
from robopercept.nn.data.textures import photo_background, random_texture
from robopercept.nn.detection.data import DetectionDataset, mask_to_box
from robopercept.nn.skeleton import MPII_16, Skeleton

__all__ = [
    "BONE_LENGTHS",
    "PoseDataset",
    "PoseSets",
    "pose_sets",
    "procedural_pose_scenes",
    "procedural_pose_set",
    "project_points",
    "random_poses_3d",
]

# joint indices of MPII_16
_R_ANK, _R_KNE, _R_HIP, _L_HIP, _L_KNE, _L_ANK, _PELV, _THOR, _NECK, _HEAD = range(10)
_R_WRI, _R_ELB, _R_SHO, _L_SHO, _L_ELB, _L_WRI = range(10, 16)

#: bone lengths (metres) of the 1.7 m figure, before the random scale and factors
BONE_LENGTHS = {
    "hip": 0.10,
    "thigh": 0.44,
    "shin": 0.42,
    "spine": 0.48,
    "neck": 0.10,
    "head": 0.22,
    "shoulder": 0.19,
    "upper_arm": 0.30,
    "forearm": 0.27,
}

#: the largest number of pixels a generator makes (2**28, 3 GiB float32)
MAX_PIXELS = 2**28


def _rx(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2
    )


def _ry(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2
    )


def _rz(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def _mv(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", r, v)


def _u(gen: np.random.Generator, n: int, lo_deg: float, hi_deg: float) -> np.ndarray:
    return np.deg2rad(gen.uniform(lo_deg, hi_deg, n))


def random_poses_3d(
    n: int,
    rng: int | np.random.Generator | None = None,
    *,
    scale: tuple[float, float] = (0.85, 1.15),
) -> np.ndarray:
    """Random 3-D poses of the procedural figure, in its own frame.

    Joint angles are drawn uniformly within the limits of the module's table; bones
    have the lengths of :data:`BONE_LENGTHS` times a body scale ``U(scale)`` and a
    per-bone factor ``U(0.92, 1.08)``. The frame: x to the figure's left, y up, z the
    way it faces, the pelvis at the origin.

    Parameters
    ----------
    n : int
        Number of poses (>= 1).
    rng : int, numpy.random.Generator or None
        Seed.
    scale : (float, float)
        Range of the body scale (within [0.3, 3]).

    Returns
    -------
    (n, 16, 3) float64 ndarray
        Joints in the :data:`~robopercept.nn.skeleton.MPII_16` order, metres.

    Examples
    --------
    >>> p = random_poses_3d(2, rng=0)
    >>> p.shape, p[:, 6].tolist()  # the pelvis at the origin
    ((2, 16, 3), [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    """
    n = check_int(n, "n", 1)
    lo, hi = _real_range(scale, "scale", 0.3, 3.0)
    gen = as_rng(rng)
    body = gen.uniform(lo, hi, n)
    f = {k: v * body * gen.uniform(0.92, 1.08, n) for k, v in BONE_LENGTHS.items()}
    down = np.tile([0.0, -1.0, 0.0], (n, 1))
    up = -down
    xaxis = np.tile([1.0, 0.0, 0.0], (n, 1))
    j = np.zeros((n, 16, 3))
    # torso: lean forward = rotation about x taking +y toward +z
    r_torso = _ry(_u(gen, n, -35, 35)) @ _rz(_u(gen, n, -15, 15)) @ _rx(_u(gen, n, -15, 35))
    j[:, _THOR] = _mv(r_torso, up) * f["spine"][:, None]
    r_head = r_torso @ _rx(_u(gen, n, -20, 35)) @ _rz(_u(gen, n, -20, 20))
    j[:, _NECK] = j[:, _THOR] + _mv(r_head, up) * f["neck"][:, None]
    j[:, _HEAD] = j[:, _NECK] + _mv(r_head, up) * f["head"][:, None]
    for side, hip, knee, ankle, sho, elb, wri in (
        (1.0, _L_HIP, _L_KNE, _L_ANK, _L_SHO, _L_ELB, _L_WRI),
        (-1.0, _R_HIP, _R_KNE, _R_ANK, _R_SHO, _R_ELB, _R_WRI),
    ):
        j[:, hip] = side * xaxis * f["hip"][:, None] + down * 0.05 * body[:, None]
        # thigh: abduction outward (about z), then flexion forward (about x toward +z)
        r_thigh = _rx(-_u(gen, n, -30, 100)) @ _rz(side * _u(gen, n, -10, 45))
        r_shin = r_thigh @ _rx(_u(gen, n, 0, 130))
        j[:, knee] = j[:, hip] + _mv(r_thigh, down) * f["thigh"][:, None]
        j[:, ankle] = j[:, knee] + _mv(r_shin, down) * f["shin"][:, None]
        j[:, sho] = j[:, _THOR] + _mv(r_torso, side * xaxis * f["shoulder"][:, None])
        j[:, sho] += _mv(r_torso, down) * 0.03 * body[:, None]
        r_arm = r_torso @ _ry(side * _u(gen, n, -100, 100)) @ _rz(side * _u(gen, n, 0, 170))
        r_fore = r_arm @ _ry(_u(gen, n, -90, 90)) @ _rx(-_u(gen, n, 0, 145))
        j[:, elb] = j[:, sho] + _mv(r_arm, down) * f["upper_arm"][:, None]
        j[:, wri] = j[:, elb] + _mv(r_fore, down) * f["forearm"][:, None]
    return j


def _real_range(value: Any, name: str, low: float, high: float) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(
            f"{name} must be (low, high), two numbers; got {plain_repr(value)}"
        ) from None
    if not (math.isfinite(a) and math.isfinite(b) and low <= a <= b <= high):
        raise InputError(f"{name} must satisfy {low} <= low <= high <= {high}; got {(a, b)}")
    return a, b


def project_points(points: npt.ArrayLike, camera_matrix: npt.ArrayLike) -> np.ndarray:
    r"""Pinhole projection of camera-frame points, pixel-centre convention.

    :math:`u = f_x X / Z + c_x`, :math:`v = f_y Y / Z + c_y` (OpenCV's
    ``projectPoints`` without distortion), for points ``(..., 3)`` and ``K`` ``(3, 3)``
    (or one per leading index, ``(..., 3, 3)``).

    Examples
    --------
    >>> project_points([[0.1, -0.2, 2.0]], [[100, 0, 32], [0, 100, 24], [0, 0, 1]]).tolist()
    [[37.0, 14.0]]
    """
    p = check_numeric(points, "points")
    k = check_numeric(camera_matrix, "camera_matrix")
    if p.ndim < 1 or p.shape[-1] != 3:
        raise InputError(f"points must be (..., 3) camera-frame points; got shape {p.shape}")
    if k.shape[-2:] != (3, 3):
        raise InputError(f"camera_matrix must be (3, 3); got shape {k.shape}")
    z = p[..., 2:3]
    if np.any(z <= 0):
        raise InputError("points must lie in front of the camera (Z > 0)")
    q = np.einsum("...ij,...nj->...ni", k, p) if k.ndim > 2 else p @ k.T
    return q[..., :2] / q[..., 2:3]


# ----------------------------------------------------------------------------- rendering

# capsules of the body: (joint a, joint b, radius in metres at body scale 1, material)
# materials: 0 shirt, 1 trousers, 2 skin
_CAPSULES = (
    (_R_HIP, _R_KNE, 0.075, 1),
    (_R_KNE, _R_ANK, 0.055, 1),
    (_L_HIP, _L_KNE, 0.075, 1),
    (_L_KNE, _L_ANK, 0.055, 1),
    (_R_SHO, _R_ELB, 0.050, 0),
    (_R_ELB, _R_WRI, 0.040, 2),
    (_L_SHO, _L_ELB, 0.050, 0),
    (_L_ELB, _L_WRI, 0.040, 2),
    (_PELV, _THOR, 0.130, 0),
    (_R_HIP, _R_SHO, 0.070, 0),
    (_L_HIP, _L_SHO, 0.070, 0),
    (_THOR, _NECK, 0.050, 2),
)
#: the head sphere's radius (metres at body scale 1), centred between the upper neck and
#: the head top (0.11 m from it), so the head top lies on the silhouette
_HEAD_RADIUS = 0.125


@dataclass(frozen=True)
class _Figure:
    joints: np.ndarray  # (J, 3) camera frame
    radii: float  # body scale
    facing: np.ndarray  # (3,) unit vector, camera frame, the way the figure faces


def _camera(gen: np.random.Generator, pose: np.ndarray, w: int, h: int, scale: tuple[float, float]):
    """Turn, view and frame one figure: camera-frame joints, K, facing direction."""
    yaw = np.deg2rad(gen.uniform(-75, 75))
    elev = np.deg2rad(gen.uniform(-10, 30))
    dist = gen.uniform(3.0, 6.0)
    # world = figure frame turned by yaw about y; camera on the +z side (the figure faces
    # +z, so the camera sees its front), raised by elev, looking at the figure's middle
    r_world_fig = _ry(np.array([yaw]))[0]
    world = pose @ r_world_fig.T
    centre = 0.5 * (world.max(0) + world.min(0))
    cam = centre + dist * np.array([0.0, np.sin(elev), np.cos(elev)])
    fwd = (centre - cam) / np.linalg.norm(centre - cam)
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    r_cam_world = np.stack([right, down, fwd])
    pts = (world - cam) @ r_cam_world.T
    facing = r_cam_world @ (r_world_fig @ np.array([0.0, 0.0, 1.0]))
    # focal: the projected height of the figure spans U(scale) of the image height
    u0 = pts[:, :2] / pts[:, 2:3]
    extent = max(u0[:, 1].max() - u0[:, 1].min(), (u0[:, 0].max() - u0[:, 0].min()) * h / w)
    focal = gen.uniform(*scale) * h / max(extent, 1e-6)
    u = u0 * focal
    margin = 0.15 * focal / float(pts[:, 2].mean())  # limb radii and the head around the joints
    lo, hi = u.min(0) - margin, u.max(0) + margin
    # principal point: the figure (with a margin for limb radii) inside the image when it fits
    cx_lo, cx_hi = -lo[0], w - hi[0]
    cy_lo, cy_hi = -lo[1], h - hi[1]
    cx = gen.uniform(min(cx_lo, cx_hi), max(cx_lo, cx_hi))
    cy = gen.uniform(min(cy_lo, cy_hi), max(cy_lo, cy_hi))
    k = np.array([[focal, 0.0, cx], [0.0, focal, cy], [0.0, 0.0, 1.0]])
    return pts, k, facing


def _segment_depth(
    px: np.ndarray, a2: np.ndarray, b2: np.ndarray, za: float, zb: float, ra: float, rb: float
):
    """For pixels ``px`` (P, 2): distance to the 2-D segment a2-b2, the depth of the
    capsule axis there, and the projected radius (all (P,))."""
    d = b2 - a2
    dd = float(d @ d)
    t = np.zeros(len(px)) if dd < 1e-12 else np.clip(((px - a2) @ d) / dd, 0.0, 1.0)
    close = a2 + t[:, None] * d
    dist = np.linalg.norm(px - close, axis=1)
    return dist, za + t * (zb - za), ra + t * (rb - ra), t


def _render(
    gen: np.random.Generator,
    canvas: np.ndarray,
    zbuf: np.ndarray,
    owner: np.ndarray,
    fig: _Figure,
    k: np.ndarray,
    person: int,
) -> None:
    """Draw one figure into ``canvas`` through the z-buffer ``zbuf``; ``owner`` records
    ``person * 64 + part`` of the nearest surface."""
    h, w = zbuf.shape
    jz = fig.joints[:, 2]
    j2 = fig.joints[:, :2] / jz[:, None] * k[0, 0] + k[:2, 2]
    f = k[0, 0]
    textures = [random_texture(gen, w, h) for _ in range(2)]
    skin = np.array(gen.uniform([0.45, 0.3, 0.2], [0.95, 0.8, 0.7]))
    parts = [*_CAPSULES, (_NECK, _HEAD, _HEAD_RADIUS, 3)]
    for pi, (a, b, radius, mat) in enumerate(parts):
        r3 = radius * fig.radii
        if mat == 3:  # the head: a sphere on the middle of neck-head top
            centre = 0.5 * (fig.joints[a] + fig.joints[b])
            c2 = centre[:2] / centre[2] * f + k[:2, 2]
            a2 = b2 = c2
            za = zb = float(centre[2])
            ra = rb = f * r3 / za
        else:
            a2, b2 = j2[a], j2[b]
            za, zb = float(jz[a]), float(jz[b])
            ra, rb = f * r3 / za, f * r3 / zb
        rmax = max(ra, rb)
        x0 = int(max(0, math.floor(min(a2[0], b2[0]) - rmax - 1)))
        x1 = int(min(w, math.ceil(max(a2[0], b2[0]) + rmax + 1)))
        y0 = int(max(0, math.floor(min(a2[1], b2[1]) - rmax - 1)))
        y1 = int(min(h, math.ceil(max(a2[1], b2[1]) + rmax + 1)))
        if x1 <= x0 or y1 <= y0:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1]
        px = np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], 1)
        dist, zc, rc, _t = _segment_depth(px, a2, b2, za, zb, ra, rb)
        inside = dist <= rc
        if not inside.any():
            continue
        rel = np.clip(dist / np.maximum(rc, 1e-9), 0.0, 1.0)
        bulge = np.sqrt(1.0 - rel**2)
        depth = zc - bulge * r3  # the surface in front of the axis
        sub_z = zbuf[y0:y1, x0:x1].reshape(-1)
        win = inside & (depth < sub_z)
        if not win.any():
            continue
        iy, ix = yy.ravel()[win], xx.ravel()[win]
        zbuf[iy, ix] = depth[win]
        owner[iy, ix] = person * 64 + pi
        shade = (0.55 + 0.45 * bulge[win])[:, None]
        if mat == 2 or mat == 3:
            colour = np.broadcast_to(skin, (int(win.sum()), 3))
        else:
            colour = textures[mat][iy, ix]
        canvas[iy, ix] = colour * shade
        if mat == 3:
            # two eyes on the face: points on the sphere towards the facing direction
            for side in (-1.0, 1.0):
                right = np.cross([0.0, -1.0, 0.0], fig.facing)
                right /= max(np.linalg.norm(right), 1e-9)
                eye = centre + r3 * (
                    0.8 * fig.facing + side * 0.35 * right + np.array([0, -0.15, 0])
                )
                if eye[2] >= centre[2]:  # on the far side of the head
                    continue
                e2 = eye[:2] / eye[2] * f + k[:2, 2]
                er = max(0.6, 0.16 * ra)
                m = (np.hypot(px[:, 0] - e2[0], px[:, 1] - e2[1]) <= er) & win
                canvas[yy.ravel()[m], xx.ravel()[m]] = 0.08


def _visibility(fig: _Figure, k: np.ndarray, zbuf: np.ndarray, w: int, h: int) -> np.ndarray:
    jz = fig.joints[:, 2]
    j2 = fig.joints[:, :2] / jz[:, None] * k[0, 0] + k[:2, 2]
    v = np.zeros(len(jz))
    for i, ((x, y), z) in enumerate(zip(j2, jz, strict=True)):
        if not (0 <= x < w and 0 <= y < h):
            continue
        c, r = int(x), int(y)
        # seen when nothing lies more than a limb radius (plus 2 cm) in front of the joint
        limit = z - (0.13 if i in (_PELV, _THOR) else 0.09) * fig.radii - 0.02
        v[i] = 2.0 if zbuf[r, c] >= limit else 1.0
    return np.concatenate([j2, v[:, None]], 1)


def _index(i: Any, n: int) -> int:
    if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
        raise InputError(f"index must be an integer; got {plain_repr(i)}")
    if not -n <= int(i) < n:
        raise InputError(f"index {int(i)} is out of range for {n} images")
    return int(i) % n


@dataclass(frozen=True, eq=False)
class PoseDataset:
    """Single-person pose data: images with their 2-D joints (top-down crops).

    Indexed like a torch data set: item ``i`` is ``(image, target)`` with ``image`` a
    float32 tensor ``(3, H, W)`` in [0, 1] and ``target`` a dict of tensors:
    ``"keypoints"`` ``(J, 3)`` float32 ``(x, y, v)``, ``"box"`` ``(4,)`` ``xyxy``, and
    ``"joints3d"`` ``(J, 3)`` (camera frame, metres; NaN when unknown).

    Attributes
    ----------
    images : (N, H, W, 3) float32 ndarray
    keypoints : (N, J, 3) float64 ndarray
        ``(x, y, v)`` in pixels, COCO's visibility (0 unlabelled, 1 hidden, 2 seen).
    boxes : (N, 4) float64 ndarray
        The person's box, ``xyxy``.
    skeleton : Skeleton
    joints3d : (N, J, 3) float64 ndarray
        Camera-frame joints in metres (NaN where not known).
    cameras : (N, 3, 3) float64 ndarray
        Camera matrices (NaN where not known).
    masks : (N, H, W) bool ndarray or None
        The person's visible silhouette.
    """

    images: np.ndarray
    keypoints: np.ndarray
    boxes: np.ndarray
    skeleton: Skeleton
    joints3d: np.ndarray
    cameras: np.ndarray
    masks: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.skeleton, Skeleton):
            raise InputError(f"skeleton must be a Skeleton; got {plain_repr(self.skeleton)}")
        images = check_numeric(self.images, "images").astype(np.float32)
        if images.ndim != 4 or images.shape[-1] != 3:
            raise InputError(f"images must be (N, H, W, 3); got shape {images.shape}")
        object.__setattr__(self, "images", images)
        for name in ("keypoints", "boxes", "joints3d", "cameras"):
            object.__setattr__(self, name, check_numeric(getattr(self, name), name))
        if self.masks is not None:
            masks = np.asarray(self.masks)
            if masks.dtype != np.bool_ or masks.shape != images.shape[:3]:
                raise InputError(
                    f"masks must be (N, H, W) bool like the images; got {plain_repr(self.masks)}"
                )
        n = len(images)
        j = self.skeleton.num_joints
        for name, arr, shape in (
            ("keypoints", self.keypoints, (n, j, 3)),
            ("boxes", self.boxes, (n, 4)),
            ("joints3d", self.joints3d, (n, j, 3)),
            ("cameras", self.cameras, (n, 3, 3)),
        ):
            if arr.shape != shape:
                raise InputError(f"{name} must have shape {shape}; got {arr.shape}")

    def __len__(self) -> int:
        return len(self.images)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        i = _index(i, len(self))
        image = torch.from_numpy(np.ascontiguousarray(self.images[i].transpose(2, 0, 1)))
        return image, {
            "keypoints": torch.from_numpy(self.keypoints[i].astype(np.float32)),
            "box": torch.from_numpy(self.boxes[i].astype(np.float32)),
            "joints3d": torch.from_numpy(self.joints3d[i].astype(np.float32)),
        }

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)``."""
        return int(self.images.shape[2]), int(self.images.shape[1])

    def subset(self, indices: npt.ArrayLike) -> PoseDataset:
        """The items at ``indices`` (a new data set sharing nothing mutable)."""
        raw = check_numeric(indices, "indices").ravel()
        if not np.all(np.isfinite(raw)) or np.any(raw != np.round(raw)):
            raise InputError(f"indices must be whole numbers; got {plain_repr(indices)}")
        idx = raw.astype(np.int64)
        if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
            raise InputError(f"indices must lie in [0, {len(self)}); got {idx.tolist()[:8]}")
        return PoseDataset(
            self.images[idx],
            self.keypoints[idx],
            self.boxes[idx],
            self.skeleton,
            self.joints3d[idx],
            self.cameras[idx],
            None if self.masks is None else self.masks[idx],
        )

    def areas(self) -> np.ndarray:
        """``(N,)`` the person's area: the silhouette's pixel count where masks are known
        (as COCO's ``area``, the segmentation's), else the box's ``w h``."""
        if self.masks is not None:
            return self.masks.reshape(len(self), -1).sum(1).astype(np.float64)
        b = self.boxes
        return (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])

    def to_coco(self) -> Any:
        """The ground truth as a COCO keypoint :class:`~robopercept.nn.coco.dataset.CocoDataset`:
        image ``i`` has id ``i + 1`` and one ``person`` annotation (id ``i + 1``) with
        its box (``xywh``), :meth:`areas`, ``keypoints`` (unlabelled ones ``0, 0, 0``)
        and ``num_keypoints``; the category carries the skeleton's names and 1-based
        links. Scored by :func:`~robopercept.nn.coco.evaluate.evaluate_detections` with
        ``iou_type="keypoints"`` and the skeleton's sigmas.

        Examples
        --------
        >>> ds = procedural_pose_set(2, (64, 64), rng=0)
        >>> c = ds.to_coco()
        >>> len(c), c.keypoints.shape
        (2, (2, 16, 3))
        """
        w, h = self.image_size
        areas = self.areas()
        anns = []
        for i in range(len(self)):
            kp = self.keypoints[i]
            b = self.boxes[i]
            anns.append(
                {
                    "id": i + 1,
                    "image_id": i + 1,
                    "category_id": 1,
                    "bbox": [b[0], b[1], b[2] - b[0], b[3] - b[1]],
                    "area": float(areas[i]),
                    "iscrowd": 0,
                    "keypoints": np.where(kp[:, 2:] > 0, kp, 0.0).ravel().tolist(),
                    "num_keypoints": int((kp[:, 2] > 0).sum()),
                }
            )
        return coco_from_dict(
            {
                "images": [
                    {"id": i + 1, "file_name": f"{i + 1:06d}.png", "width": w, "height": h}
                    for i in range(len(self))
                ],
                "categories": [
                    {
                        "id": 1,
                        "name": "person",
                        "keypoints": list(self.skeleton.joints),
                        "skeleton": [[a + 1, b + 1] for a, b in self.skeleton.links],
                    }
                ],
                "annotations": anns,
            }
        )

    def split(
        self,
        fractions: Sequence[float] = (0.8, 0.1, 0.1),
        rng: int | np.random.Generator | None = 0,
    ) -> tuple[PoseDataset, ...]:
        """A seeded random split into parts of the given fractions (summing to 1)."""
        fr = check_numeric(fractions, "fractions")
        if (
            fr.ndim != 1
            or fr.size < 1
            or not np.isfinite(fr).all()
            or np.any(fr < 0)
            or abs(fr.sum() - 1) > 1e-9
        ):
            raise InputError(f"fractions must be non-negative and sum to 1; got {fractions}")
        order = as_rng(rng).permutation(len(self))
        cuts = np.round(np.cumsum(fr)[:-1] * len(self)).astype(int)
        return tuple(self.subset(p) for p in np.split(order, cuts))


def procedural_pose_set(
    n_images: int,
    size: tuple[int, int] = (128, 128),
    rng: int | np.random.Generator | None = None,
    *,
    scale: tuple[float, float] = (0.65, 0.9),
    occlusion: float = 0.3,
) -> PoseDataset:
    """Procedural articulated figures over real photos, with exact 2-D and 3-D joints.

    See the module docstring for the figure, the camera and the rendering.

    Parameters
    ----------
    n_images : int
        Number of images (>= 1).
    size : (int, int)
        ``(width, height)``, each in [32, 1024].
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same set.
    scale : (float, float)
        Range of the figure's projected height as a fraction of the image height
        (within [0.2, 1.0]).
    occlusion : float
        Probability in [0, 1] of an occluding bar across the figure.

    Returns
    -------
    PoseDataset
        In the :data:`~robopercept.nn.skeleton.MPII_16` layout, with masks.

    Examples
    --------
    >>> ds = procedural_pose_set(2, (64, 64), rng=0)
    >>> ds.images.shape, ds.keypoints.shape, ds.skeleton.name
    ((2, 64, 64, 3), (2, 16, 3), 'mpii16')
    """
    w, h = check_size(size, "size", 32, 1024)
    n = check_int(n_images, "n_images", 1)
    if n * w * h > MAX_PIXELS:
        raise InputError(
            f"n_images x width x height must be at most {MAX_PIXELS} pixels; got {n * w * h}: "
            "make fewer or smaller images"
        )
    lo, hi = _real_range(scale, "scale", 0.2, 1.0)
    occlusion = check_real(occlusion, "occlusion", 0.0, 1.0)
    gen = as_rng(rng)
    poses = random_poses_3d(n, gen)
    images = np.empty((n, h, w, 3), np.float32)
    kps = np.empty((n, 16, 3))
    boxes = np.empty((n, 4))
    j3d = np.empty((n, 16, 3))
    cams = np.empty((n, 3, 3))
    masks = np.zeros((n, h, w), bool)
    for i in range(n):
        canvas, _info = photo_background(gen, w, h)
        pts, k, facing = _camera(gen, poses[i], w, h, (lo, hi))
        body = float(np.linalg.norm(poses[i][_THOR] - poses[i][_PELV]) / BONE_LENGTHS["spine"])
        fig = _Figure(pts, body, facing)
        zbuf = np.full((h, w), np.inf)
        owner = np.full((h, w), -1, np.int64)
        _render(gen, canvas, zbuf, owner, fig, k, 0)
        if gen.random() < occlusion:
            _occluder(gen, canvas, zbuf, owner, fig, k)
        kps[i] = _visibility(fig, k, zbuf, w, h)
        masks[i] = owner >= 0
        masks[i] &= owner < 64
        boxes[i] = mask_to_box(masks[i]) if masks[i].any() else (0, 0, 0, 0)
        images[i] = np.clip(canvas, 0, 1)
        j3d[i] = pts
        cams[i] = k
    return PoseDataset(images, kps, boxes, MPII_16, j3d, cams, masks)


def _occluder(
    gen: np.random.Generator,
    canvas: np.ndarray,
    zbuf: np.ndarray,
    owner: np.ndarray,
    fig: _Figure,
    k: np.ndarray,
) -> None:
    """A textured bar in front of the figure (nearer than all of it), across a joint."""
    h, w = zbuf.shape
    jz = fig.joints[:, 2]
    j2 = fig.joints[:, :2] / jz[:, None] * k[0, 0] + k[:2, 2]
    target = j2[int(gen.integers(len(j2)))]
    span = float(np.ptp(j2[:, 1])) + 1.0
    phi = gen.uniform(0, np.pi)
    length = gen.uniform(0.4, 0.9) * span
    thick = gen.uniform(0.05, 0.12) * span
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    dx, dy = xx - target[0], yy - target[1]
    qx = np.cos(phi) * dx + np.sin(phi) * dy
    qy = -np.sin(phi) * dx + np.cos(phi) * dy
    m = (np.abs(qx) <= length / 2) & (np.abs(qy) <= thick / 2)
    canvas[m] = random_texture(gen, w, h)[m]
    zbuf[m] = float(jz.min()) - 0.5
    owner[m] = 64  # not the person


def procedural_pose_scenes(
    n_images: int,
    size: tuple[int, int] = (192, 160),
    rng: int | np.random.Generator | None = None,
    *,
    people: tuple[int, int] = (1, 3),
    scale: tuple[float, float] = (0.35, 0.75),
    min_visible: float = 0.3,
) -> DetectionDataset:
    """Several procedural figures per image: the multi-person set of a keypoint detector.

    Each figure is posed, turned and framed as in :func:`procedural_pose_set` (its own
    camera: a height ``U(scale)`` of the image height and a random position), and all
    are drawn through one z-buffer, so nearer figures hide farther ones; a joint
    hidden by another figure gets ``v = 1``. A figure with less than ``min_visible`` of
    its silhouette seen is redrawn (20 tries, then left out).

    Parameters
    ----------
    n_images : int
    size : (int, int)
        ``(width, height)``, each in [32, 1024].
    rng : int, numpy.random.Generator or None
    people : (int, int)
        Inclusive range of figures per image (0 <= low <= high <= 10).
    scale : (float, float)
        Range of a figure's height over the image height (within [0.2, 1.0]).
    min_visible : float
        In (0, 1].

    Returns
    -------
    DetectionDataset
        One class, ``"person"``; boxes and masks of the visible silhouettes, keypoints
        ``(K, 16, 3)`` in the :data:`~robopercept.nn.skeleton.MPII_16` layout.

    Examples
    --------
    >>> ds = procedural_pose_scenes(2, (96, 80), rng=0)
    >>> ds.classes, ds.keypoints[0].shape[1:]
    (('person',), (16, 3))
    """
    w, h = check_size(size, "size", 32, 1024)
    n = check_int(n_images, "n_images", 1)
    if n * w * h > MAX_PIXELS:
        raise InputError(
            f"n_images x width x height must be at most {MAX_PIXELS} pixels; got {n * w * h}: "
            "make fewer or smaller images"
        )
    try:
        lo_p, hi_p = (check_int(v, "people", 0) for v in people)
    except (TypeError, ValueError):
        raise InputError(f"people must be (low, high) counts; got {plain_repr(people)}") from None
    if not lo_p <= hi_p <= 10:
        raise InputError(f"people must satisfy 0 <= low <= high <= 10; got {(lo_p, hi_p)}")
    s_lo, s_hi = _real_range(scale, "scale", 0.2, 1.0)
    min_visible = check_real(min_visible, "min_visible", 0.0, 1.0, low_inclusive=False)
    gen = as_rng(rng)
    images, boxes, labels, masks, keypoints = [], [], [], [], []
    for _ in range(n):
        canvas, _info = photo_background(gen, w, h)
        zbuf = np.full((h, w), np.inf)
        owner = np.full((h, w), -1, np.int64)
        placed: list[tuple[_Figure, np.ndarray, int, int]] = []
        for person in range(int(gen.integers(lo_p, hi_p + 1))):
            for _try in range(20):
                pose = random_poses_3d(1, gen)[0]
                pts, k, facing = _camera(gen, pose, w, h, (s_lo, s_hi))
                body = float(np.linalg.norm(pose[_THOR] - pose[_PELV]) / BONE_LENGTHS["spine"])
                fig = _Figure(pts, body, facing)
                state = gen.bit_generator.state
                alone = np.full((h, w), -1, np.int64)
                _render(gen, canvas.copy(), np.full((h, w), np.inf), alone, fig, k, person)
                gen.bit_generator.state = state  # the same textures when drawn for real
                c2, z2, o2 = canvas.copy(), zbuf.copy(), owner.copy()
                _render(gen, c2, z2, o2, fig, k, person)
                areas = [*[(q, a) for _f, _k, q, a in placed], (person, int((alone >= 0).sum()))]
                if areas[-1][1] > 0 and all(
                    (o2 // 64 == q).sum() >= min_visible * a for q, a in areas
                ):
                    canvas, zbuf, owner = c2, z2, o2
                    placed.append((fig, k, person, areas[-1][1]))
                    break
        kps, bxs, ms = [], [], []
        for fig, k, person, _area in placed:
            m = owner // 64 == person
            kps.append(_visibility(fig, k, zbuf, w, h))
            bxs.append(mask_to_box(m))
            ms.append(m)
        images.append(np.clip(canvas, 0, 1).astype(np.float32))
        keypoints.append(np.array(kps).reshape(len(kps), 16, 3))
        boxes.append(np.array(bxs).reshape(len(bxs), 4))
        masks.append(np.array(ms, dtype=bool).reshape(len(ms), h, w))
        labels.append(np.ones(len(kps), np.int64))
    return DetectionDataset(images, boxes, labels, ["person"], masks=masks, keypoints=keypoints)


@dataclass(frozen=True)
class PoseSets:
    """A built-in pose data set split three ways (train, validation, test)."""

    train: PoseDataset
    val: PoseDataset
    test: PoseDataset


#: the built-in data of :func:`pose_sets`
POSE_DATA = ("figures",)


def pose_sets(
    data: str = "figures",
    images: int = 2000,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    *,
    val_images: int | None = None,
    test_images: int | None = None,
) -> PoseSets:
    """The built-in single-person pose sets, as the CLI and the benchmarks make them.

    ``"figures"``: :func:`procedural_pose_set` with disjoint seeds, training ``seed``,
    validation ``1000 + seed``, test ``99`` (the same test figures for every seed);
    ``val_images`` and ``test_images`` default to a tenth of ``images`` (at least 1).

    Examples
    --------
    >>> s = pose_sets("figures", 10, (64, 64))
    >>> len(s.train), len(s.val), len(s.test)
    (10, 1, 1)
    """
    check_choice(data, "data", POSE_DATA)
    n = check_int(images, "images", 1)
    nv = max(1, n // 10) if val_images is None else check_int(val_images, "val_images", 1)
    nt = max(1, n // 10) if test_images is None else check_int(test_images, "test_images", 1)
    seed = check_int(seed, "seed", 0)
    return PoseSets(
        procedural_pose_set(n, size, seed),
        procedural_pose_set(nv, size, 1000 + seed),
        procedural_pose_set(nt, size, 99),
    )
