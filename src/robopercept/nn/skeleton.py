r"""Skeletons: the joints of a pose, the links drawn between them, the left/right pairs a
horizontal flip swaps, and the per-joint OKS constants.

NumPy only (no torch). A :class:`Skeleton` is the one description of a keypoint layout
that the pose readers, the metrics, the networks (flip test) and the pictures share.

Presets
-------
* :data:`COCO_17`: the 17 person keypoints of COCO (nose, eyes, ears, shoulders, elbows,
  wrists, hips, knees, ankles), the 19 links of COCO's ``skeleton`` field (converted
  to 0-based) and COCO's per-keypoint sigmas
  ``[.26, .25, .25, .35, .35, .79, .79, .72, .72, .62, .62, 1.07, 1.07, .87, .87, .89,
  .89] / 10`` (``pycocotools.cocoeval.Params.kpt_oks_sigmas``).
* :data:`MPII_16`: the 16 joints of MPII Human Pose in the order of its annotation
  files (mmpose's ``mpii`` layout: right ankle, right knee, right hip, left hip, left
  knee, left ankle, pelvis, thorax, upper neck, head top, right wrist, right elbow,
  right shoulder, left shoulder, left elbow, left wrist), its 15 links (a tree rooted at
  the pelvis) and mmpose's MPII sigmas. The procedural figures of
  :mod:`robopercept.nn.pose.data` use this layout.

The OKS of a predicted pose :math:`\hat p` against ground truth :math:`p` with object
area :math:`s` is :math:`\sum_i \exp(-d_i^2 / (2 s k_i^2)) / n` over the :math:`n`
labelled joints, :math:`k_i = 2 \sigma_i` (COCO's definition); the sigmas live here so
that every OKS in the project reads the same constants.

Examples
--------
>>> MPII_16.num_joints, MPII_16.index("pelvis"), int(MPII_16.parents("pelvis")[7])
(16, 6, 6)
>>> COCO_17.flip_permutation()[:5].tolist()
[0, 2, 1, 4, 3]
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_int, plain_repr
from robopercept.errors import InputError

__all__ = ["COCO_17", "MPII_16", "Skeleton", "skeleton_from_coco_category"]


def _pairs(value: Any, name: str, n: int) -> tuple[tuple[int, int], ...]:
    try:
        arr = np.asarray(value, dtype=np.int64).reshape(-1, 2) if len(value) else np.zeros((0, 2))
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{name} must be a sequence of (i, j) joint-index pairs; got {plain_repr(value)}"
        ) from exc
    arr = arr.astype(np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise InputError(f"{name} must index joints 0..{n - 1}; got {arr.tolist()}")
    if np.any(arr[:, 0] == arr[:, 1]):
        raise InputError(f"{name} must join two different joints; got {arr.tolist()}")
    return tuple((int(a), int(b)) for a, b in arr)


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A keypoint layout: joint names, links, flip pairs and OKS sigmas.

    Parameters
    ----------
    name : str
        A short name (``"coco17"``, ``"mpii16"``).
    joints : sequence of str
        The joint names, in the order of the keypoint arrays.
    links : sequence of (int, int)
        Pairs of 0-based joint indices drawn as limbs (and, when they form a tree, the
        edges of the pictorial-structures model).
    flip_pairs : sequence of (int, int)
        Left/right pairs that a horizontal flip of the image swaps.
    sigmas : (J,) array_like, optional
        Per-joint OKS sigmas (COCO's ``kpt_oks_sigmas``); default 0.05 for every joint.

    Examples
    --------
    >>> s = Skeleton("arm", ["shoulder", "elbow", "wrist"], [(0, 1), (1, 2)], [])
    >>> s.parents(root=0).tolist(), s.sigmas.tolist()
    ([-1, 0, 1], [0.05, 0.05, 0.05])
    """

    name: str
    joints: tuple[str, ...]
    links: tuple[tuple[int, int], ...]
    flip_pairs: tuple[tuple[int, int], ...]
    sigmas: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __init__(
        self,
        name: str,
        joints: Sequence[str],
        links: Sequence[Sequence[int]],
        flip_pairs: Sequence[Sequence[int]],
        sigmas: npt.ArrayLike | None = None,
    ) -> None:
        if not isinstance(name, str) or not name:
            raise InputError(f"name must be a non-empty string; got {plain_repr(name)}")
        if isinstance(joints, str) or not all(isinstance(j, str) for j in joints):
            raise InputError(f"joints must be a sequence of names; got {plain_repr(joints)}")
        names = tuple(joints)
        if not names:
            raise InputError("joints must name at least one joint; got an empty sequence")
        if len(set(names)) != len(names):
            raise InputError(f"joints must be distinct names; got {list(names)}")
        n = len(names)
        flips = _pairs(flip_pairs, "flip_pairs", n)
        used = [j for p in flips for j in p]
        if len(set(used)) != len(used):
            raise InputError(f"flip_pairs must use each joint at most once; got {list(flips)}")
        if sigmas is None:
            sig = np.full(n, 0.05)
        else:
            sig = np.asarray(sigmas, dtype=np.float64).ravel()
            if sig.shape != (n,) or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
                raise InputError(
                    f"sigmas must be {n} positive numbers, one per joint; got {plain_repr(sigmas)}"
                )
        sig = sig.copy()
        sig.setflags(write=False)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "joints", names)
        object.__setattr__(self, "links", _pairs(links, "links", n))
        object.__setattr__(self, "flip_pairs", flips)
        object.__setattr__(self, "sigmas", sig)

    @property
    def num_joints(self) -> int:
        """The number of joints ``J``."""
        return len(self.joints)

    def index(self, joint: str) -> int:
        """The index of the joint called ``joint``."""
        try:
            return self.joints.index(joint)
        except ValueError:
            raise InputError(
                f"{self.name} has no joint {joint!r}; its joints are {list(self.joints)}"
            ) from None

    def flip_permutation(self) -> np.ndarray:
        """``(J,)`` int64: the joint order after a horizontal flip (``perm[i]`` is the joint
        whose flipped image is joint ``i``): each flip pair swapped, others fixed."""
        perm = np.arange(self.num_joints, dtype=np.int64)
        for a, b in self.flip_pairs:
            perm[a], perm[b] = b, a
        return perm

    def parents(self, root: int | str | None = None) -> np.ndarray:
        """``(J,)`` int64: each joint's parent in the tree that the links form, rooted at
        ``root`` (a name or an index; default the joint of most links), ``-1`` at the root.

        Raises
        ------
        InputError
            If the links do not form a spanning tree (J - 1 links, all joints connected).
        """
        n = self.num_joints
        if len(self.links) != n - 1:
            raise InputError(
                f"{self.name}'s links do not form a tree: {len(self.links)} links for {n} "
                f"joints (a tree has {n - 1})"
            )
        adj: list[list[int]] = [[] for _ in range(n)]
        for a, b in self.links:
            adj[a].append(b)
            adj[b].append(a)
        if root is None:
            r = int(np.argmax([len(a) for a in adj]))
        elif isinstance(root, str):
            r = self.index(root)
        else:
            r = check_int(root, "root")
            if not 0 <= r < n:
                raise InputError(f"root must be a joint index 0..{n - 1}; got {root}")
        parent = np.full(n, -2, dtype=np.int64)
        parent[r] = -1
        stack = [r]
        while stack:
            u = stack.pop()
            for v in adj[u]:
                if parent[v] == -2:
                    parent[v] = u
                    stack.append(v)
        if np.any(parent == -2):
            missing = [self.joints[i] for i in np.flatnonzero(parent == -2)]
            raise InputError(f"{self.name}'s links do not reach joints {missing}: not a tree")
        return parent

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (``name``, ``joints``, ``links``, ``flip_pairs``, ``sigmas``)."""
        return {
            "name": self.name,
            "joints": list(self.joints),
            "links": [list(p) for p in self.links],
            "flip_pairs": [list(p) for p in self.flip_pairs],
            "sigmas": self.sigmas.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Skeleton:
        """The inverse of :meth:`to_dict`."""
        if not isinstance(data, Mapping) or "joints" not in data:
            raise InputError(f"a skeleton dict needs 'joints'; got {plain_repr(data)}")
        return cls(
            str(data.get("name", "skeleton")),
            list(data["joints"]),
            data.get("links", []),
            data.get("flip_pairs", []),
            data.get("sigmas"),
        )

    def __repr__(self) -> str:
        return f"Skeleton({self.name!r}, {self.num_joints} joints, {len(self.links)} links)"


def _flip_pairs_by_name(names: Sequence[str]) -> list[tuple[int, int]]:
    """Pairs ``left_X``/``right_X`` (or ``l_X``/``r_X``) of a name list."""
    pairs = []
    index = {n: i for i, n in enumerate(names)}
    for i, n in enumerate(names):
        for left, right in (("left_", "right_"), ("l_", "r_")):
            if n.startswith(left) and right + n[len(left) :] in index:
                pairs.append((i, index[right + n[len(left) :]]))
    return pairs


def skeleton_from_coco_category(category: Mapping[str, Any], name: str = "coco") -> Skeleton:
    """The skeleton of a COCO keypoint category (its ``keypoints`` names and 1-based
    ``skeleton`` links); flip pairs from the ``left_``/``right_`` names; COCO's sigmas
    when the names are COCO's 17, else 0.05 each.

    Examples
    --------
    >>> cat = {"id": 1, "name": "person", "keypoints": ["a", "left_b", "right_b"],
    ...        "skeleton": [[1, 2], [1, 3]]}
    >>> s = skeleton_from_coco_category(cat)
    >>> s.links, s.flip_pairs
    (((0, 1), (0, 2)), ((1, 2),))
    """
    if not isinstance(category, Mapping) or not isinstance(category.get("keypoints"), list):
        raise InputError(
            "a COCO keypoint category needs a 'keypoints' list of names; got "
            f"{plain_repr(category)}"
        )
    names = [str(k) for k in category["keypoints"]]
    links = [(int(a) - 1, int(b) - 1) for a, b in category.get("skeleton", [])]
    sigmas = COCO_17.sigmas if tuple(names) == COCO_17.joints else None
    return Skeleton(name, names, links, _flip_pairs_by_name(names), sigmas)


_COCO_NAMES = (
    "nose",
    "left_eye",
    "right_eye",
    "left_ear",
    "right_ear",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
)
_COCO_SKELETON_1BASED = (
    (16, 14), (14, 12), (17, 15), (15, 13), (12, 13), (6, 12), (7, 13), (6, 7), (6, 8),
    (7, 9), (8, 10), (9, 11), (2, 3), (1, 2), (1, 3), (2, 4), (3, 5), (4, 6), (5, 7),
)  # fmt: skip

#: COCO's 17 person keypoints, links and sigmas (pycocotools' ``kpt_oks_sigmas``)
COCO_17 = Skeleton(
    "coco17",
    _COCO_NAMES,
    [(a - 1, b - 1) for a, b in _COCO_SKELETON_1BASED],
    _flip_pairs_by_name(_COCO_NAMES),
    np.array(
        [0.26, 0.25, 0.25, 0.35, 0.35, 0.79, 0.79, 0.72, 0.72, 0.62, 0.62, 1.07, 1.07, 0.87,
         0.87, 0.89, 0.89]
    ) / 10.0,
)  # fmt: skip

_MPII_NAMES = (
    "right_ankle",
    "right_knee",
    "right_hip",
    "left_hip",
    "left_knee",
    "left_ankle",
    "pelvis",
    "thorax",
    "upper_neck",
    "head_top",
    "right_wrist",
    "right_elbow",
    "right_shoulder",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
)

#: MPII Human Pose's 16 joints (mmpose order), a tree of 15 links rooted at the pelvis,
#: and mmpose's MPII sigmas
MPII_16 = Skeleton(
    "mpii16",
    _MPII_NAMES,
    [(0, 1), (1, 2), (2, 6), (6, 3), (3, 4), (4, 5), (6, 7), (7, 8), (8, 9), (7, 12),
     (12, 11), (11, 10), (7, 13), (13, 14), (14, 15)],
    _flip_pairs_by_name(_MPII_NAMES),
    [0.089, 0.083, 0.107, 0.107, 0.083, 0.089, 0.026, 0.026, 0.026, 0.026, 0.062, 0.072,
     0.179, 0.179, 0.072, 0.062],
)  # fmt: skip
