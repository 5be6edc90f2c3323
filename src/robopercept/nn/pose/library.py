r"""Lifting 2-D poses to 3-D by matching against a library of projected 3-D poses, and
the library the ``robopercept nn pose --lift3d`` command matches against.

Poses, views and the 2-D normalization are those of :mod:`robopercept.nn.pose.views`.

Lifting by matching (the course's recipe)
-----------------------------------------
:class:`PoseLibrary` projects every library pose from ``views_per_pose`` random views,
normalizes each projection and keeps the pairs (normalized 2-D pose, rooted camera-frame
3-D pose). :meth:`PoseLibrary.lift` normalizes a query the same way, finds the nearest
library 2-D pose (Euclidean distance between the flattened ``(2J,)`` vectors,
:class:`scipy.spatial.cKDTree`) and returns its 3-D pose, or the mean of the ``k``
nearest. A query with missing joints is matched on its visible joints only: the library
poses are normalized again over the same joints and searched by brute force.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from robopercept._checks import check_choice, check_int, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.pose.data import random_poses_3d
from robopercept.nn.pose.views import (
    CENTERS,
    DEFAULT_ELEVATION,
    PELVIS,
    check_keypoints2d,
    check_scales,
    check_seed,
    normalize_joints,
    random_views,
    visibility_mask,
)
from robopercept.nn.skeleton import MPII_16, Skeleton

__all__ = ["PoseLibrary", "default_pose_library"]


# ============================================================================ matching


class PoseLibrary:
    r"""Lift 2-D poses to 3-D by matching against a library of projected 3-D poses.

    The library holds, for every pose of ``poses3d`` seen from ``views_per_pose``
    random views (:func:`~robopercept.nn.pose.views.random_views`), the pair
    (normalized 2-D projection, :func:`~robopercept.nn.pose.views.normalize_pose2d`; the
    3-D pose in that camera's frame, relative to the root). :meth:`lift` returns the 3-D
    pose of the nearest 2-D pose (or the mean of the ``k`` nearest).

    The 3-D output is root-relative (its depth is relative to the root joint, the
    distance to the camera is not recovered) and at the library's scale (metres of the
    library poses, whatever the size of the person in the image).

    Parameters
    ----------
    poses3d : (N, J, 3) array_like
        Library poses in their own frame (x left, y up, z facing; metres).
    views_per_pose : int
        Random views of each pose (>= 1); the library has ``N * views_per_pose``
        entries.
    rng : int, numpy.random.Generator or None
        Seed of the views.
    elevation, distance : (float, float)
        Ranges of the views, as :func:`~robopercept.nn.pose.views.random_views` (radians, metres).
    center : {"root", "mean"}
        The 2-D normalization's centre.
    root : int
        The root joint (the pelvis, 6, for :data:`~robopercept.nn.skeleton.MPII_16`).
    k : int
        Default number of nearest entries averaged by :meth:`lift`.

    Attributes
    ----------
    keypoints2d : (M, J, 2) ndarray
        Normalized 2-D poses.
    joints3d : (M, J, 3) ndarray
        Their rooted camera-frame 3-D poses.
    pose_index : (M,) ndarray
        The library pose of each entry.

    Raises
    ------
    InputError
        Empty or NaN poses, bad parameters.
    DegenerateError
        A pose whose projection collapses to a point.

    Examples
    --------
    >>> from robopercept.nn.pose.data import random_poses_3d
    >>> lib = PoseLibrary(random_poses_3d(50, rng=0), views_per_pose=4, rng=0)
    >>> len(lib), lib.lift(lib.keypoints2d[:2] * 100 + 7).shape
    (200, (2, 16, 3))
    """

    def __init__(
        self,
        poses3d: npt.ArrayLike,
        *,
        views_per_pose: int = 16,
        rng: int | np.random.Generator | None = 0,
        elevation: tuple[float, float] = DEFAULT_ELEVATION,
        distance: tuple[float, float] = (3.0, 6.0),
        center: str = "root",
        root: int = PELVIS,
        k: int = 1,
    ) -> None:
        self.center = check_choice(center, "center", CENTERS)
        self.k = check_int(k, "k", 1)
        views = random_views(
            poses3d, views_per_pose, rng, elevation=elevation, distance=distance, root=root
        )
        self.root = int(root)
        norm, s = normalize_joints(views.keypoints2d, None, self.center, self.root)
        check_scales(s, "library views")
        self.keypoints2d = norm
        self.joints3d = views.rooted(self.root)
        self.pose_index = views.pose_index
        if self.k > len(norm):
            raise InputError(f"k must be at most the library size, {len(norm)}; got {self.k}")
        self._tree = cKDTree(norm.reshape(len(norm), -1))

    def __len__(self) -> int:
        return len(self.keypoints2d)

    @property
    def num_joints(self) -> int:
        """J, the joints of each pose."""
        return int(self.keypoints2d.shape[1])

    def lift(
        self,
        keypoints2d: npt.ArrayLike,
        visible: npt.ArrayLike | None = None,
        *,
        k: int | None = None,
    ) -> np.ndarray:
        r"""The 3-D poses of the nearest library 2-D poses.

        Each query is normalized (:func:`~.views.normalize_pose2d`, the library's ``center``
        and ``root``) and compared with every library entry by the Euclidean distance
        of the flattened normalized joints; with joints missing, over the visible
        joints only, both sides normalized over them. The ``k`` nearest entries' 3-D
        poses are averaged.

        Parameters
        ----------
        keypoints2d : (J, 2) or (M, J, 2) array_like
            Detected image joints (pixels: translation and scale do not matter).
        visible : (J,) or (M, J) array_like, optional
            Nonzero where the joint was detected; default all. Missing joints may hold
            NaN.
        k : int, optional
            Entries averaged (default the library's ``k``).

        Returns
        -------
        (J, 3) or (M, J, 3) ndarray
            Root-relative joints in the camera frame, at the library's scale (metres).

        Raises
        ------
        InputError
            Wrong joint count or shape, NaN/inf at a visible joint (mark it missing in
            ``visible``), ``k`` beyond the library size.
        DegenerateError
            A query with fewer than 2 visible joints, or all at one point.

        Examples
        --------
        >>> from robopercept.nn.pose.data import random_poses_3d
        >>> lib = PoseLibrary(random_poses_3d(20, rng=1), views_per_pose=2, rng=0)
        >>> q = lib.keypoints2d[5] * 40 + [320, 240]  # an entry, moved and scaled
        >>> bool(np.allclose(lib.lift(q), lib.joints3d[5]))
        True
        """
        kp, single = check_keypoints2d(keypoints2d)
        if kp.shape[1] != self.num_joints:
            raise InputError(
                f"keypoints2d must have the library's {self.num_joints} joints; got "
                f"{kp.shape[1]} (shape {kp.shape})"
            )
        kk = self.k if k is None else check_int(k, "k", 1)
        if kk > len(self):
            raise InputError(f"k must be at most the library size, {len(self)}; got {kk}")
        mask = visibility_mask(visible, kp, single)
        kp = np.where(mask[..., None], kp, 0.0)
        index = np.empty((len(kp), kk), np.int64)
        full = mask.all(1)
        if full.any():
            q, s = normalize_joints(kp[full], None, self.center, self.root)
            check_scales(s, "query pose(s)")
            _, idx = self._tree.query(q.reshape(len(q), -1), k=kk)
            index[full] = np.asarray(idx).reshape(len(q), kk)
        rows = np.flatnonzero(~full)
        if rows.size:
            patterns, inverse = np.unique(mask[rows], axis=0, return_inverse=True)
            for p, pattern in enumerate(patterns):
                group = rows[inverse.ravel() == p]
                index[group] = self._masked(kp[group], pattern, kk)
        out = self.joints3d[index].mean(1)
        return out[0] if single else out

    def _masked(self, kp: np.ndarray, pattern: np.ndarray, k: int) -> np.ndarray:
        """Nearest entries (Q, k) over the joints of ``pattern`` (brute force)."""
        qmask = np.broadcast_to(pattern, kp.shape[:2])
        q, s = normalize_joints(kp, qmask, self.center, self.root)
        check_scales(s, "query pose(s)")
        lmask = np.broadcast_to(pattern, self.keypoints2d.shape[:2])
        lib, _ = normalize_joints(self.keypoints2d, lmask, self.center, self.root)
        qv = q[:, pattern].reshape(len(q), -1)
        lv = lib[:, pattern].reshape(len(lib), -1)
        l2 = (lv**2).sum(1)
        out = np.empty((len(qv), k), np.int64)
        step = max(1, 2**22 // len(lv))
        for a in range(0, len(qv), step):
            qa = qv[a : a + step]
            d2 = (qa**2).sum(1)[:, None] + l2[None] - 2.0 * qa @ lv.T
            if k < len(lv):
                cand = np.argpartition(d2, k - 1, axis=1)[:, :k]
            else:
                cand = np.broadcast_to(np.arange(len(lv)), d2.shape)
            dc = np.take_along_axis(d2, cand, 1)
            order = np.lexsort((cand, dc), axis=-1)
            out[a : a + step] = np.take_along_axis(cand, order, 1)[:, :k]
        return out


def default_pose_library(
    skeleton: Skeleton | None = None,
    *,
    poses: int = 2000,
    views_per_pose: int = 16,
    k: int = 5,
    rng: int | None = 0,
) -> PoseLibrary:
    """The library the ``robopercept nn pose --lift3d`` command matches against:
    ``poses`` random poses of the procedural figure
    (:func:`~robopercept.nn.pose.data.random_poses_3d`, seeded) seen from
    ``views_per_pose`` random views, the mean of the ``k`` nearest returned.

    Parameters
    ----------
    skeleton : Skeleton, optional
        The layout of the 2-D poses to lift; it must be
        :data:`~robopercept.nn.skeleton.MPII_16`'s (the figure's).
    poses, views_per_pose, k : int
    rng : int or None

    Raises
    ------
    InputError
        Another layout than MPII's 16 joints.

    Examples
    --------
    >>> lib = default_pose_library(poses=20, views_per_pose=2)
    >>> len(lib), lib.num_joints
    (40, 16)
    """
    if skeleton is not None and (
        not isinstance(skeleton, Skeleton) or skeleton.joints != MPII_16.joints
    ):
        raise InputError(
            "the pose library holds the procedural figure's 3-D poses in MPII's 16-joint "
            f"layout; got {plain_repr(skeleton)}: lift poses of a model trained on MPII's "
            "joints (robopercept nn pose train --data figures)"
        )
    n = check_int(poses, "poses", 1)
    views = check_int(views_per_pose, "views_per_pose", 1)
    # each library entry: 16 joints in 3-D (the pose) and 2-D (its view), float64
    check_allocation(
        n * views * MPII_16.num_joints * 5,
        8,
        f"a library of {n} poses x {views} views",
        "lower poses or views_per_pose (the default library: 2000 x 16)",
    )
    seed = check_seed(rng, "rng")
    return PoseLibrary(random_poses_3d(n, rng=seed), views_per_pose=views_per_pose, rng=seed, k=k)
