r"""Multi-object tracking by detection: one Kalman filter per track, Hungarian
association, track life cycle (as SORT, Bewley et al. 2016).

Each track's state is its box centre, size and their velocities,
:math:`x = [c_x, c_y, w, h, \dot c_x, \dot c_y, \dot w, \dot h]`, under a constant
velocity model (:func:`robopercept.tracking.constant_velocity`, one frame per step);
the measurement is the detected box :math:`z = [c_x, c_y, w, h]`. Every
:meth:`MultiObjectTracker.update` does

1. **predict** every track one frame ahead;
2. **match**: a cost between every track and detection, ``"iou"`` (:math:`1 -
   \mathrm{IoU}` of the predicted and detected boxes), ``"mahalanobis"`` (the squared
   Mahalanobis distance :math:`y^T S^{-1} y` of the innovation) or ``"euclidean"``
   (centre distance in pixels); pairs beyond the ``gate`` (IoU below it, distance above
   it, or a different class) are forbidden, non-finite costs too, and
   ``scipy.optimize.linear_sum_assignment`` picks the cheapest one-to-one assignment
   of the rest;
3. **update** matched tracks with their detection; start a *tentative* track for every
   unmatched detection.

A track is *confirmed* after ``min_hits`` matches (the first frames confirm at once, as
SORT, so tracks exist from the start); a tentative track that misses a frame is
dropped (most clutter does); a confirmed track that misses *coasts* on its prediction
for up to ``max_age`` frames, then dies. Identities are never reused.

Splits, merges and look-alikes: association is one to one, so when two objects merge
into one detection one track takes it and the other coasts (and dies if the merge
lasts longer than ``max_age``); when they split again, the coasting track takes the
detection its prediction fits best, or a new track (a new identity) starts. Identical
looking objects are told apart only by motion: the gate and the prediction keep
identities while objects stay separable; when they cross closely, identities can swap
(appearance features would be needed there).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from robopercept._checks import (
    check_bool,
    check_choice,
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.geometry.boxes import box_iou_matrix
from robopercept.tracking.kalman import KalmanFilter, constant_velocity

__all__ = ["MultiObjectTracker", "Track"]

_FORBIDDEN = 1e9


@dataclass(frozen=True)
class Track:
    """A track as reported by :meth:`MultiObjectTracker.update`.

    Attributes
    ----------
    id : int
        Identity, unique over the tracker's life.
    box : (4,) ndarray
        ``x, y, w, h`` from the filtered state.
    velocity : (2,) ndarray
        Centre velocity in pixels per frame.
    detection : int
        Index of the detection it took this frame, -1 when coasting.
    label : numpy scalar or None
        Class of its detections (None when no classes are given).
    score : float
        Score of the detection it took (NaN when coasting or without scores).
    state : str
        ``"tentative"``, ``"confirmed"`` or ``"coasting"``.
    hits, age, misses : int
        Matches so far, frames since it started, frames since its last match.
    """

    id: int
    box: np.ndarray
    velocity: np.ndarray
    detection: int
    label: np.generic | None
    score: float
    state: str
    hits: int
    age: int
    misses: int


class _Live:
    """Internal mutable track."""

    __slots__ = ("age", "confirmed", "hits", "id", "kf", "label", "misses", "score")

    def __init__(self, tid: int, kf: KalmanFilter, label: np.generic | None, score: float) -> None:
        self.id, self.kf, self.label, self.score = tid, kf, label, score
        self.hits, self.age, self.misses, self.confirmed = 1, 1, 0, False


def _xywh_to_z(boxes: np.ndarray) -> np.ndarray:
    return np.c_[boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3] / 2, boxes[:, 2:4]]


def _z_to_xywh(z: np.ndarray) -> np.ndarray:
    w, h = np.maximum(z[..., 2], 0.0), np.maximum(z[..., 3], 0.0)
    return np.stack([z[..., 0] - w / 2, z[..., 1] - h / 2, w, h], axis=-1)


def _labels(classes: npt.ArrayLike) -> list:
    """``classes`` as a flat list of hashable labels (numbers or strings)."""
    try:
        arr = np.asarray(classes)
    except (TypeError, ValueError) as exc:  # ragged
        raise InputError(
            f"classes must be one label per detection; got {plain_repr(classes)[:60]} ({exc})"
        ) from None
    if arr.dtype.kind not in "biufUS":
        raise InputError(
            f"classes must be numbers or strings, one per detection; got dtype {arr.dtype}"
        )
    return list(arr.ravel())


class MultiObjectTracker:
    """Track boxes over frames (see the module docstring).

    Parameters
    ----------
    motion_model : {"constant_velocity"}
    cost : {"iou", "mahalanobis", "euclidean"}
    gate : float, optional
        ``iou``: the least IoU to match (default 0.3); ``mahalanobis``: the largest
        squared distance (default 13.28, the 99 % chi-square quantile for 4 dof);
        ``euclidean``: the largest centre distance in pixels (default 50).
    min_hits : int
        Matches that confirm a track.
    max_age : int
        Frames a confirmed track coasts without a match before it dies.
    process_noise, measurement_noise : float
        Variance of the per-frame acceleration (px^2 / frame^4) and of the detected
        centre and size (px^2).
    report_coasting : bool
        Also report confirmed tracks that coast this frame (``detection == -1``).
    """

    def __init__(
        self,
        motion_model: str = "constant_velocity",
        cost: str = "iou",
        gate: float | None = None,
        min_hits: int = 3,
        max_age: int = 5,
        *,
        process_noise: float = 1.0,
        measurement_noise: float = 4.0,
        report_coasting: bool = False,
    ) -> None:
        check_choice(motion_model, "motion_model", ("constant_velocity",))
        self.cost = check_choice(cost, "cost", ("iou", "mahalanobis", "euclidean"))
        defaults = {"iou": 0.3, "mahalanobis": 13.28, "euclidean": 50.0}
        high = 1.0 if cost == "iou" else None  # an IoU is at most 1
        self.gate = check_real(
            defaults[cost] if gate is None else gate, "gate", 0.0, high, low_inclusive=False
        )
        self.min_hits = check_int(min_hits, "min_hits", 0)
        self.max_age = check_int(max_age, "max_age", 0)
        # the bounds of constant_velocity, named as here
        self.process_noise = check_real(process_noise, "process_noise", 0.0, 1e100)
        self.measurement_noise = check_real(
            measurement_noise, "measurement_noise", 0.0, 1e100, low_inclusive=False
        )
        self.report_coasting = check_bool(report_coasting, "report_coasting")
        proto = constant_velocity(4, 1.0, process_noise, measurement_noise)
        self._A, self._Q, self._H, self._R = proto.A, proto.Q, proto.H, proto.R
        self._ids = itertools.count(1)
        self._tracks: list[_Live] = []
        self.frame = 0

    @property
    def tracks(self) -> list[Track]:
        """Every live track (tentative, confirmed and coasting) after the last update."""
        return [self._report(t, -1) for t in self._tracks]

    def _new(self, z: np.ndarray, label: np.generic | None, score: float) -> _Live:
        P = np.diag([1.0, 1.0, 1.0, 1.0, 100.0, 100.0, 100.0, 100.0]) * self.measurement_noise
        kf = KalmanFilter(8, 4, x=np.r_[z, 0, 0, 0, 0], P=P, A=self._A, Q=self._Q,
                          H=self._H, R=self._R)  # fmt: skip
        return _Live(next(self._ids), kf, label, score)

    def _report(self, t: _Live, det: int, box: np.ndarray | None = None) -> Track:
        state = "tentative" if not t.confirmed else ("confirmed" if t.misses == 0 else "coasting")
        x = t.kf.x
        box = _z_to_xywh(x[:4]) if box is None else box
        score = t.score if det >= 0 else float("nan")
        velocity = x[4:6].copy()
        return Track(t.id, box, velocity, det, t.label, score, state, t.hits, t.age, t.misses)

    def update(
        self,
        detections: npt.ArrayLike,
        scores: npt.ArrayLike | None = None,
        classes: npt.ArrayLike | None = None,
    ) -> list[Track]:
        """Advance one frame with this frame's detections ``(N, 4)`` ``x, y, w, h``.

        Returns the confirmed tracks matched this frame (and, with
        ``report_coasting``, the coasting ones), each naming its detection.
        """
        boxes = check_numeric(detections, "detections")
        if boxes.size == 0:
            boxes = np.zeros((0, 4))
        if boxes.ndim != 2 or boxes.shape[1] != 4:
            raise InputError(f"detections must be (N, 4) x, y, w, h; got shape {boxes.shape}")
        if not np.isfinite(boxes).all():
            raise InputError(f"frame {self.frame}: detections contain NaN or inf; drop them")
        check_magnitude(boxes, "detections", 1e150)  # squared in the costs and the filter
        if (boxes[:, 2:] < 0).any():
            raise InputError(f"frame {self.frame}: detections have negative width or height")
        n = boxes.shape[0]
        sc = np.full(n, np.nan) if scores is None else check_numeric(scores, "scores")
        if sc.shape != (n,):
            raise InputError(f"scores must have one value per detection ({n}); got {sc.shape}")
        labels = [None] * n if classes is None else _labels(classes)
        if len(labels) != n:
            raise InputError(f"classes must have one value per detection ({n}); got {len(labels)}")
        self.frame += 1
        z = _xywh_to_z(boxes)
        tracks = self._tracks
        m = len(tracks)
        # 1. predict, all tracks at once: x = A x, P = A P A^T + Q
        if m:
            X = np.stack([t.kf.x for t in tracks]) @ self._A.T
            P = self._A @ np.stack([t.kf.P for t in tracks]) @ self._A.T + self._Q
        else:
            X, P = np.zeros((0, 8)), np.zeros((0, 8, 8))
        # 2. match
        rows = cols = np.zeros(0, dtype=np.int64)
        if m and n:
            cost = self._cost(X, P, z, boxes)
            if classes is not None:
                same = np.array([[t.label == lab for lab in labels] for t in tracks])
                cost = np.where(same, cost, _FORBIDDEN)
            cost = np.where(np.isfinite(cost), cost, _FORBIDDEN)
            rows, cols = linear_sum_assignment(cost)
            ok = cost[rows, cols] < _FORBIDDEN
            rows, cols = rows[ok], cols[ok]
        # 3. update the matched tracks (batched Kalman update, Joseph form)
        if rows.size:
            H, R = self._H, self._R
            Pm = P[rows]
            y = z[cols] - X[rows] @ H.T
            S = H @ Pm @ H.T + R
            K = np.linalg.solve(S, H @ Pm).transpose(0, 2, 1)  # P H^T S^-1 (S symmetric)
            X[rows] = X[rows] + np.einsum("kij,kj->ki", K, y)
            ikh = np.eye(8) - K @ H
            P[rows] = ikh @ Pm @ ikh.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
        matched = dict(zip(rows.tolist(), cols.tolist(), strict=True))
        out_boxes = _z_to_xywh(X[:, :4])
        survivors: list[_Live] = []
        out: list[Track] = []
        for k, t in enumerate(tracks):
            t.kf.x, t.kf.P = X[k], P[k]
            t.age += 1
            det = matched.get(k, -1)
            if det >= 0:
                t.hits += 1
                t.misses = 0
                t.score = float(sc[det])
                t.label = labels[det]
                if t.hits >= self.min_hits or self.frame <= self.min_hits:
                    t.confirmed = True
            else:
                t.misses += 1
                if not t.confirmed or t.misses > self.max_age:
                    continue  # tentative tracks die at their first miss; old ones too
            survivors.append(t)
            if t.confirmed and (det >= 0 or self.report_coasting):
                out.append(self._report(t, det, out_boxes[k]))
        taken = set(matched.values())
        for j in range(n):
            if j not in taken:
                t = self._new(z[j], labels[j], float(sc[j]))
                if self.min_hits <= 1 or self.frame <= self.min_hits:
                    t.confirmed = True
                    out.append(self._report(t, j))
                survivors.append(t)
        self._tracks = survivors
        return out

    def _cost(self, X: np.ndarray, P: np.ndarray, z: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        if self.cost == "iou":
            iou = box_iou_matrix(_z_to_xywh(X[:, :4]), boxes)
            return np.where(iou >= self.gate, 1.0 - iou, _FORBIDDEN)
        if self.cost == "euclidean":
            d = np.linalg.norm(X[:, None, :2] - z[None, :, :2], axis=2)
            return np.where(d <= self.gate, d, _FORBIDDEN)
        H, R = self._H, self._R
        S = H @ P @ H.T + R  # (m, 4, 4)
        y = z[None, :, :] - (X @ H.T)[:, None, :]  # (m, n, 4)
        d2 = np.einsum("mni,mni->mn", y, np.linalg.solve(S[:, None], y[..., None])[..., 0])
        return np.where(d2 <= self.gate, d2, _FORBIDDEN)
