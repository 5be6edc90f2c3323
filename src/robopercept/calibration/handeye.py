r"""Hand-eye calibration: the camera's pose on a robot (or the robot's in front of a
camera) from robot poses and target observations, by solving :math:`AX = XB`.

Frames follow :mod:`robopercept.geometry.transforms` (``T_a_b`` maps b to a). The inputs
are the gripper pose in the robot base, :math:`G_i = T_{base,gripper}`, and the target's
pose seen by the camera, :math:`C_i = T_{camera,target}` (``cv2.calibrateHandEye``'s
``R_gripper2base`` and ``R_target2cam``).

- **Eye in hand** (camera on the gripper, target fixed): :math:`X = T_{gripper,camera}`.
  :math:`G_i X C_i = T_{base,target}` is the same for every i, so for two stations
  :math:`(G_j^{-1} G_i) X = X (C_j C_i^{-1})`, i.e. :math:`A X = X B`.
- **Eye to hand** (camera fixed, target on the gripper): :math:`X = T_{base,camera}`, and
  the same equations hold with :math:`G_i` replaced by :math:`G_i^{-1}`.

Rotation first, then translation from :math:`(R_A - I) t_X = R_X t_B - t_A` by linear
least squares over all pairs. The rotation by:

- ``"tsai"`` (Tsai & Lenz 1989): with modified Rodrigues vectors
  :math:`P = 2 \sin(\theta/2)\, n`, :math:`[P_A + P_B]_\times P' = P_B - P_A`, then
  :math:`P_X = 2 P' / \sqrt{1 + |P'|^2}`.
- ``"park"`` (Park & Martin 1994): the rotation axes-angles satisfy
  :math:`\alpha_i = R_X \beta_i` (:math:`\alpha = \log R_A`, :math:`\beta = \log R_B`),
  so :math:`R_X` is the orthogonal Procrustes solution :math:`U V^T` of
  :math:`\sum \alpha_i \beta_i^T = U S V^T`.
- ``"daniilidis"`` (1999): unit dual quaternions; :math:`a \check x = \check x b` is
  linear in the 8 entries of :math:`\check x`, rotation and translation together: the
  null space of the stacked :math:`6n \times 8` system is 2-D and the unit-norm and
  dual-orthogonality constraints pick the solution in it.

With ``refine`` (the default) Levenberg-Marquardt then minimizes, over X and the fixed
transform :math:`Y` (:math:`T_{base,target}`, or :math:`T_{gripper,target}` eye to hand),
:math:`\sum_i \|\log(Y^{-1} G_i X C_i)\|^2` with rotation errors scaled into lengths:
first by the typical camera-target distance, then, in a second pass, by the ratio of the
translation and rotation residual spreads (the maximum-likelihood weighting when the
noise levels are unknown).

Robot poses often come as x, y, z and roll, pitch, yaw; :func:`pose_from_xyz_rpy` builds
the matrix (extrinsic x-y-z angles, :math:`R = R_z(\gamma) R_y(\beta) R_x(\alpha)`, the
ROS/URDF and ``scipy`` ``"xyz"`` convention).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_file,
    check_magnitude,
    check_numeric,
    check_real,
)
from robopercept.calibration.ros import (
    quaternion_from_rotation,
    transform_stamped,
    write_ros_yaml,
)
from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.geometry.epipolar import skew
from robopercept.geometry.transforms import (
    check_transform,
    invert,
    nearest_rotation,
    rotation_from_rotvec,
    rotvec_from_rotation,
)

__all__ = [
    "DEFAULT_FRAMES",
    "HandEyeResult",
    "calibrate_hand_eye",
    "hand_eye_format",
    "hand_eye_report",
    "hand_eye_residuals",
    "pose_from_xyz_rpy",
    "read_xyz_rpy",
    "save_hand_eye",
    "xyz_rpy_from_pose",
]

Setup = Literal["eye_in_hand", "eye_to_hand"]
Method = Literal["tsai", "park", "daniilidis"]
SETUPS = ("eye_in_hand", "eye_to_hand")
METHODS = ("tsai", "park", "daniilidis")


@dataclass(frozen=True)
class HandEyeResult:
    """Result of :func:`calibrate_hand_eye`.

    Attributes
    ----------
    X : (4, 4) ndarray
        ``T_gripper_camera`` (eye in hand) or ``T_base_camera`` (eye to hand).
    Y : (4, 4) ndarray
        The transform that stays fixed: ``T_base_target`` (eye in hand) or
        ``T_gripper_target`` (eye to hand), the mean of :math:`G_i X C_i`.
    setup, method : str
    rotation_residuals : (P,) ndarray
        Per motion pair, the angle in degrees of :math:`(R_A R_X)^T R_X R_B`.
    translation_residuals : (P,) ndarray
        Per motion pair, :math:`\\|R_A t_X + t_A - R_X t_B - t_X\\|` (input units).
    """

    X: np.ndarray
    Y: np.ndarray
    setup: str
    method: str
    rotation_residuals: np.ndarray
    translation_residuals: np.ndarray

    @property
    def rotation_rms(self) -> float:
        """RMS of :attr:`rotation_residuals`, degrees."""
        return float(np.sqrt(np.mean(self.rotation_residuals**2)))

    @property
    def translation_rms(self) -> float:
        """RMS of :attr:`translation_residuals`, input units."""
        return float(np.sqrt(np.mean(self.translation_residuals**2)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "setup": self.setup,
            "method": self.method,
            "X": self.X.tolist(),
            "Y": self.Y.tolist(),
            "rotation_rms_deg": self.rotation_rms,
            "translation_rms": self.translation_rms,
            "rotation_residuals_deg": self.rotation_residuals.tolist(),
            "translation_residuals": self.translation_residuals.tolist(),
        }


#: ROS frame names of X by default: (parent, child) per setup. X maps the OpenCV camera
#: frame (z forward), which ROS calls an optical frame, into the gripper (ROS-Industrial's
#: ``tool0``) or the robot base (``base_link``)
DEFAULT_FRAMES: dict[str, tuple[str, str]] = {
    "eye_in_hand": ("tool0", "camera_optical_frame"),
    "eye_to_hand": ("base_link", "camera_optical_frame"),
}


def hand_eye_report(
    result: HandEyeResult,
    parent_frame: str | None = None,
    child_frame: str | None = None,
    *,
    metres_per_unit: float = 1.0,
) -> dict[str, Any]:
    r"""Everything a user needs of :math:`X`: the 4x4, position and quaternion, roll
    pitch yaw, and the ROS transform, JSON-ready.

    Parameters
    ----------
    result : HandEyeResult
    parent_frame, child_frame : str, optional
        The ROS frames of :math:`X = T_{parent,child}`; default
        :data:`DEFAULT_FRAMES` of the setup (``tool0`` or ``base_link``, and
        ``camera_optical_frame``).
    metres_per_unit : float
        Scale of the input translations to metres, applied to the ROS transform only
        (ROS lengths are metres): 0.001 when the robot poses were in millimetres.

    Returns
    -------
    dict
        :meth:`HandEyeResult.to_dict` plus ``xyz`` (input units), ``quaternion_xyzw``
        (ROS order, :math:`w \ge 0`), ``rpy_deg`` (:func:`xyz_rpy_from_pose`),
        ``parent_frame``, ``child_frame``, ``transform`` (the
        ``geometry_msgs/TransformStamped`` fields of
        :func:`~robopercept.calibration.transform_stamped`, metres) and
        ``static_transform_publisher``: the ROS 2 command that publishes it.

    Raises
    ------
    InputError
        ``result`` not a HandEyeResult, an empty frame name, or ``metres_per_unit``
        not a positive finite number.

    Examples
    --------
    >>> res = HandEyeResult(np.eye(4), np.eye(4), "eye_in_hand", "tsai", np.zeros(1),
    ...                     np.zeros(1))
    >>> rep = hand_eye_report(res)
    >>> rep["quaternion_xyzw"], rep["transform"]["header"]["frame_id"]
    ([0.0, 0.0, 0.0, 1.0], 'tool0')
    """
    if not isinstance(result, HandEyeResult):
        raise InputError(
            f"result must be a HandEyeResult (calibrate_hand_eye); got {type(result).__name__}"
        )
    scale = check_real(metres_per_unit, "metres_per_unit", 0.0, low_inclusive=False)
    default = DEFAULT_FRAMES.get(result.setup, ("base_link", "camera_optical_frame"))
    parent = default[0] if parent_frame is None else parent_frame
    child = default[1] if child_frame is None else child_frame
    xyz, rpy = xyz_rpy_from_pose(result.X)
    q = quaternion_from_rotation(result.X[:3, :3])
    scaled = result.X.copy()
    scaled[:3, 3] *= scale
    msg = transform_stamped(scaled, parent, child)
    t, r = msg["transform"]["translation"], msg["transform"]["rotation"]
    command = (
        "ros2 run tf2_ros static_transform_publisher "
        + " ".join(f"--{k} {t[k]!r}" for k in "xyz")
        + " "
        + " ".join(f"--q{k} {r[k]!r}" for k in "xyzw")
        + f" --frame-id {parent} --child-frame-id {child}"
    )
    out = result.to_dict()
    out.update(
        xyz=xyz.tolist(),
        quaternion_xyzw=q.tolist(),
        rpy_deg=rpy.tolist(),
        parent_frame=parent,
        child_frame=child,
        transform=msg,
        static_transform_publisher=command,
    )
    return out


def hand_eye_format(path: str | Path, format: str | None = None) -> str:
    """The format :func:`save_hand_eye` writes to ``path``: ``format`` if given (checked
    against the extension), else ``"json"`` for ``.json`` and ``"ros"`` for ``.yaml`` /
    ``.yml``.

    Raises
    ------
    InputError
        Another extension, another format, or one whose files have another extension.

    Examples
    --------
    >>> hand_eye_format("tf.yaml")
    'ros'
    """
    p = as_path(path, "path")
    by_ext = {".json": "json", ".yaml": "ros", ".yml": "ros"}.get(p.suffix.lower())
    fmt = by_ext if format is None else check_choice(format, "format", ("json", "ros"))
    if fmt is None or by_ext != fmt:
        raise InputError(
            f"hand-eye files are .json (format 'json') or .yaml / .yml (format 'ros'); "
            f"got {p.name!r}" + (f" with format {format!r}" if format is not None else "")
        )
    return fmt


def save_hand_eye(
    path: str | Path,
    result: HandEyeResult,
    format: str | None = None,
    *,
    parent_frame: str | None = None,
    child_frame: str | None = None,
    metres_per_unit: float = 1.0,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write a hand-eye result as JSON (:func:`hand_eye_report`) or as a ROS transform
    YAML (``geometry_msgs/TransformStamped`` fields, read back by
    :func:`~robopercept.calibration.read_transform`).

    Parameters
    ----------
    path : str or Path
        ``.json`` or ``.yaml`` / ``.yml`` (replaced if it exists).
    result : HandEyeResult
    format : {"json", "ros"}, optional
        Default by the extension: ``.json`` JSON, ``.yaml`` / ``.yml`` ROS.
    parent_frame, child_frame, metres_per_unit
        As :func:`hand_eye_report`.
    extra : mapping, optional
        More JSON entries (ignored by the ROS file).

    Returns
    -------
    dict
        The report (:func:`hand_eye_report` plus ``extra``), whichever format was
        written.

    Raises
    ------
    InputError
        As :func:`hand_eye_report`, an unknown format or one that does not match the
        extension, ``extra`` naming a report entry, or an unusable path.
    FileFormatError
        The file cannot be written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robopercept.calibration.ros import read_transform
    >>> res = HandEyeResult(np.eye(4), np.eye(4), "eye_to_hand", "tsai", np.zeros(1),
    ...                     np.zeros(1))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = save_hand_eye(pathlib.Path(d) / "x.yaml", res)
    ...     read_transform(pathlib.Path(d) / "x.yaml")[1:]
    ('base_link', 'camera_optical_frame')
    """
    p = as_path(path, "path")
    if p.is_dir():
        raise InputError(f"path {p} is a folder; give a file name such as {p / 'handeye.json'}")
    fmt = hand_eye_format(p, format)
    report = hand_eye_report(result, parent_frame, child_frame, metres_per_unit=metres_per_unit)
    if extra is not None and not isinstance(extra, Mapping):
        raise InputError(f"extra must be a mapping; got {type(extra).__name__}")
    clash = sorted(set(extra or {}) & set(report))
    if clash:
        raise InputError(f"extra names entries of the report itself: {', '.join(clash)}")
    report.update(extra or {})
    if fmt == "ros":
        write_ros_yaml(p, report["transform"])
        return report
    try:
        text = json.dumps(report, indent=2, allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise InputError(f"extra holds a value JSON cannot store ({exc})") from exc
    try:
        p.write_text(text)
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot write ({exc.strerror or exc})") from exc
    return report


# --------------------------------------------------------------------------- poses


def pose_from_xyz_rpy(
    xyz: npt.ArrayLike, rpy: npt.ArrayLike, *, degrees: bool = True
) -> np.ndarray:
    r"""4x4 pose from a position and roll, pitch, yaw.

    :math:`R = R_z(\text{yaw})\, R_y(\text{pitch})\, R_x(\text{roll})`: rotations about the
    fixed x, y, z axes in that order (``scipy.spatial.transform.Rotation.from_euler("xyz",
    ...)``, ROS ``rpy``, and the Rx Ry Rz of many robot controllers).

    Parameters
    ----------
    xyz : (3,) array_like
        Position, in the unit the result should have (mm stays mm).
    rpy : (3,) array_like
        Roll, pitch, yaw.
    degrees : bool
        Angles in degrees (default) or radians.

    Returns
    -------
    (4, 4) float64 ndarray

    Raises
    ------
    InputError
        ``xyz`` or ``rpy`` not 3 finite real numbers, or ``degrees`` not a bool.
    """
    t = check_numeric(xyz, "xyz").ravel()
    a = check_numeric(rpy, "rpy").ravel()
    if t.shape != (3,) or a.shape != (3,) or not (np.isfinite(t).all() and np.isfinite(a).all()):
        raise InputError(f"xyz and rpy must be 3 finite numbers each; got {t} and {a}")
    if check_bool(degrees, "degrees"):
        a = np.deg2rad(a)
    (cx, cy, cz), (sx, sy, sz) = np.cos(a), np.sin(a)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = rz @ ry @ rx
    T[:3, 3] = t
    return T


def xyz_rpy_from_pose(T: npt.ArrayLike, *, degrees: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`pose_from_xyz_rpy`: position and (roll, pitch, yaw) of a 4x4
    pose, pitch in [-90, 90] degrees (roll = atan2(R21, R22), pitch = -asin(R20),
    yaw = atan2(R10, R00))."""
    m = check_transform(T)
    R = m[:3, :3]
    rpy = np.array(
        [
            np.arctan2(R[2, 1], R[2, 2]),
            -np.arcsin(np.clip(R[2, 0], -1.0, 1.0)),
            np.arctan2(R[1, 0], R[0, 0]),
        ]
    )
    return m[:3, 3].copy(), np.rad2deg(rpy) if degrees else rpy


def read_xyz_rpy(path: str | Path, order: str = "rpy_xyz", *, degrees: bool = True) -> np.ndarray:
    """Read one robot pose of six numbers (any whitespace) into a 4x4 matrix.

    Parameters
    ----------
    path : str or Path
    order : {"rpy_xyz", "xyz_rpy"}
        ``"rpy_xyz"``: Rx Ry Rz then X Y Z (the Open3DV captures); ``"xyz_rpy"`` the other
        way round.
    degrees : bool

    Raises
    ------
    InputError
        ``path`` not a usable path, or an unknown ``order``.
    FileFormatError
        Missing, a folder, or not six numbers.
    """
    check_choice(order, "order", ("rpy_xyz", "xyz_rpy"))
    degrees = check_bool(degrees, "degrees")
    p = check_file(path, "a robot pose file (six numbers)")
    try:
        v = np.array(p.read_text().split(), dtype=np.float64)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise FileFormatError(f"{p}: not a pose of six numbers ({exc})") from exc
    if v.size != 6 or not np.isfinite(v).all():
        raise FileFormatError(f"{p}: a pose needs six finite numbers; found {v.size}")
    rpy, xyz = (v[:3], v[3:]) if order == "rpy_xyz" else (v[3:], v[:3])
    return pose_from_xyz_rpy(xyz, rpy, degrees=degrees)


def _stack(poses: npt.ArrayLike, name: str) -> np.ndarray:
    if isinstance(poses, np.ndarray) and poses.ndim == 3:
        poses = list(poses)
    if not isinstance(poses, Sequence | np.ndarray):
        raise InputError(f"{name} must be a list of 4x4 transforms")
    out = []
    for i, T in enumerate(poses):
        m = check_transform(T, f"{name}[{i}]")
        check_magnitude(m, f"{name}[{i}]", 1e150)  # the solvers multiply translations
        r = m[:3, :3]
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-5) or np.linalg.det(r) < 0:
            raise InputError(f"{name}[{i}] does not hold a rotation (orthonormal, det +1)")
        out.append(m)
    if not out:
        raise InputError(f"{name} must hold at least one 4x4 transform; got none")
    return np.array(out)


# --------------------------------------------------------------------------- solvers


def _motions(G: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All pairs i < j: ``A = G_j^-1 G_i``, ``B = C_j C_i^-1``."""
    i, j = np.triu_indices(len(G), 1)
    Ginv = np.array([invert(g) for g in G])
    Cinv = np.array([invert(c) for c in C])
    return Ginv[j] @ G[i], C[j] @ Cinv[i]


def _check_axes(A: np.ndarray) -> None:
    """At least two motions must turn about non-parallel axes."""
    r = np.array([rotvec_from_rotation(a[:3, :3]) for a in A])
    ang = np.linalg.norm(r, axis=1)
    big = ang > np.deg2rad(0.5)
    if big.sum() < 2:
        raise DegenerateError(
            "the robot barely rotates between stations (under 0.5 degrees): rotate the "
            "gripper about at least two different axes"
        )
    s = np.linalg.svd(r[big] / ang[big, None], compute_uv=False)
    if s[1] < 0.02 * s[0]:
        raise DegenerateError(
            "every motion rotates about the same (parallel) axis, which leaves the "
            "translation along that axis unknown: rotate the gripper about at least two "
            "different axes"
        )


def _translation(A: np.ndarray, B: np.ndarray, Rx: np.ndarray) -> np.ndarray:
    lhs = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (B[:, :3, 3] @ Rx.T - A[:, :3, 3]).ravel()
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]


def _tsai(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    def modified(R: np.ndarray) -> np.ndarray:
        v = rotvec_from_rotation(R)
        th = np.linalg.norm(v)
        return np.zeros(3) if th == 0 else 2 * np.sin(th / 2) * v / th

    pa = np.array([modified(a[:3, :3]) for a in A])
    pb = np.array([modified(b[:3, :3]) for b in B])
    lhs = np.concatenate([skew(x) for x in pa + pb])
    p1 = np.linalg.lstsq(lhs, (pb - pa).ravel(), rcond=None)[0]
    p = 2 * p1 / np.sqrt(1 + p1 @ p1)
    n2 = p @ p
    return (1 - n2 / 2) * np.eye(3) + 0.5 * (np.outer(p, p) + np.sqrt(4 - n2) * skew(p))


def _park(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    al = np.array([rotvec_from_rotation(a[:3, :3]) for a in A])
    be = np.array([rotvec_from_rotation(b[:3, :3]) for b in B])
    return nearest_rotation(al.T @ be)


def _quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z), w >= 0."""
    v = rotvec_from_rotation(R)
    th = np.linalg.norm(v)
    axis = v / th if th > 0 else np.zeros(3)
    return np.r_[np.cos(th / 2), np.sin(th / 2) * axis]


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.r_[p[0] * q[0] - p[1:] @ q[1:], p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:])]


def _dual(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q = _quaternion(T[:3, :3])
    return q, 0.5 * _qmul(np.r_[0.0, T[:3, 3]], q)


def _daniilidis(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    rows = []
    for a, b in zip(A, B, strict=True):
        qa, da = _dual(a)
        qb, db = _dual(b)
        s = np.zeros((6, 8))
        s[:3, 0] = qa[1:] - qb[1:]
        s[:3, 1:4] = skew(qa[1:] + qb[1:])
        s[3:, 0] = da[1:] - db[1:]
        s[3:, 1:4] = skew(da[1:] + db[1:])
        s[3:, 4] = qa[1:] - qb[1:]
        s[3:, 5:8] = skew(qa[1:] + qb[1:])
        rows.append(s)
    _, _, vt = np.linalg.svd(np.concatenate(rows))
    u1, v1 = vt[-2, :4], vt[-2, 4:]
    u2, v2 = vt[-1, :4], vt[-1, 4:]
    # lambda1 q1 + lambda2 q2 with |q| = 1 and q . q' = 0
    a, b, c = u1 @ v1, u1 @ v2 + u2 @ v1, u2 @ v2
    roots = np.roots([a, b, c]) if abs(a) > 1e-15 else np.array([-c / b])
    roots = roots[np.isreal(roots)].real
    if roots.size == 0:
        raise DegenerateError("the dual-quaternion system has no real solution: noisy data")
    val = [(s * s * (u1 @ u1) + 2 * s * (u1 @ u2) + u2 @ u2, s) for s in roots]
    best, s = max(val)
    l2 = 1.0 / np.sqrt(best)
    q = s * l2 * vt[-2] + l2 * vt[-1]
    qr, qd = q[:4], q[4:]
    w, x, y, z = qr
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    t = 2 * _qmul(qd, qr * np.r_[1, -1, -1, -1])[1:]
    X = np.eye(4)
    X[:3, :3] = nearest_rotation(R)
    X[:3, 3] = t
    return X


def _logs(R: np.ndarray) -> np.ndarray:
    """Rotation vectors of ``(N, 3, 3)`` rotations at once (falls back to
    :func:`rotvec_from_rotation` near 0 and pi, where the batch formula loses digits)."""
    v = 0.5 * np.stack(
        [R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1
    )
    c = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    s = np.linalg.norm(v, axis=1)
    out = v * (np.arctan2(s, c) / np.where(s > 0, s, 1.0))[:, None]
    for k in np.flatnonzero(s <= 1e-6):
        out[k] = rotvec_from_rotation(R[k])
    return out


def _mean_pose(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = nearest_rotation(T[:, :3, :3].sum(axis=0))
    out[:3, 3] = T[:, :3, 3].mean(axis=0)
    return out


def _refine(G: np.ndarray, C: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from scipy.optimize import least_squares

    def pose(p: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = rotation_from_rotvec(p[:3])
        T[:3, 3] = p[3:]
        return T

    def parts(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        E = invert(pose(p[6:])) @ G @ pose(p[:6]) @ C
        return _logs(E[:, :3, :3]), E[:, :3, 3]

    Y = _mean_pose(G @ X @ C)
    p = np.r_[rotvec_from_rotation(X[:3, :3]), X[:3, 3], rotvec_from_rotation(Y[:3, :3]), Y[:3, 3]]
    # rotation residuals (rad) weighted into lengths: first by the camera-target distance
    # (a rotation error moves the target by about that much), then by the ratio of the
    # residual spreads themselves (the maximum-likelihood weight for unknown noise)
    scale = float(np.median(np.linalg.norm(C[:, :3, 3], axis=1))) or 1.0
    for _ in range(2):

        def fun(q: np.ndarray, s: float = scale) -> np.ndarray:
            rv, tr = parts(q)
            return np.c_[rv * s, tr].ravel()

        # (bounded: valid stations converge in a few steps)
        sol = least_squares(fun, p, method="lm", x_scale="jac", max_nfev=200)
        if not np.isfinite(sol.x).all() or sol.cost > 0.5 * (fun(p) ** 2).sum():
            break
        p = sol.x
        rv, tr = parts(p)
        r_rms, t_rms = np.sqrt(np.mean(rv**2)), np.sqrt(np.mean(tr**2))
        if not (r_rms > 1e-12 and t_rms > 1e-12):
            break
        scale = float(t_rms / r_rms)
    return pose(p[:6]), pose(p[6:])


def hand_eye_residuals(
    X: npt.ArrayLike,
    T_base_gripper: npt.ArrayLike,
    T_camera_target: npt.ArrayLike,
    setup: Setup = "eye_in_hand",
) -> tuple[np.ndarray, np.ndarray]:
    """How well X satisfies :math:`A X = X B` over all pairs of stations.

    Returns
    -------
    rotation_deg, translation : (P,) ndarray
        Angle of :math:`(R_A R_X)^T R_X R_B` in degrees and
        :math:`\\|R_A t_X + t_A - R_X t_B - t_X\\|`, for each of the P = n(n-1)/2 pairs.

    Raises
    ------
    InputError
        Poses that are not rigid 4x4 transforms (translations within 1e150), fewer
        than 2 stations, or counts that differ.
    """
    check_choice(setup, "setup", SETUPS)
    G = _stack(T_base_gripper, "T_base_gripper")
    C = _stack(T_camera_target, "T_camera_target")
    if len(G) != len(C) or len(G) < 2:
        raise InputError(
            f"{len(G)} robot poses and {len(C)} target poses: give one target pose per "
            "robot station, in the same order, at least 2 stations"
        )
    if setup == "eye_to_hand":
        G = np.array([invert(g) for g in G])
    Xm = check_transform(X, "X")
    A, B = _motions(G, C)
    AX, XB = A @ Xm, Xm @ B
    rot = np.array(
        [
            np.linalg.norm(rotvec_from_rotation(p[:3, :3].T @ q[:3, :3]))
            for p, q in zip(AX, XB, strict=True)
        ]
    )
    return np.rad2deg(rot), np.linalg.norm(AX[:, :3, 3] - XB[:, :3, 3], axis=1)


def calibrate_hand_eye(
    T_base_gripper: npt.ArrayLike,
    T_camera_target: npt.ArrayLike,
    setup: Setup = "eye_in_hand",
    method: Method = "tsai",
    *,
    refine: bool = True,
) -> HandEyeResult:
    """Solve :math:`AX = XB` for the camera-robot transform.

    Parameters
    ----------
    T_base_gripper : list of (4, 4) array_like
        Gripper pose in the robot base at each station (from the robot controller; see
        :func:`pose_from_xyz_rpy`).
    T_camera_target : list of (4, 4) array_like
        Target pose in the camera at the same stations (e.g. ``CalibrationResult.poses``).
    setup : {"eye_in_hand", "eye_to_hand"}
    method : {"tsai", "park", "daniilidis"}
        Closed-form start (see the module docstring).
    refine : bool
        Levenberg-Marquardt over X and the fixed transform Y afterwards.

    Returns
    -------
    HandEyeResult

    Raises
    ------
    InputError
        Fewer than 3 stations, or counts that differ.
    DegenerateError
        Motions that all rotate about parallel axes (or hardly rotate).
    """
    check_choice(setup, "setup", SETUPS)
    check_choice(method, "method", METHODS)
    refine = check_bool(refine, "refine")
    G = _stack(T_base_gripper, "T_base_gripper")
    C = _stack(T_camera_target, "T_camera_target")
    if len(G) != len(C):
        raise InputError(
            f"{len(G)} robot poses but {len(C)} target poses: give one target pose per "
            "robot station, in the same order"
        )
    if len(G) < 3:
        raise InputError(
            f"hand-eye calibration needs at least 3 stations; got {len(G)}: move the robot "
            "to more poses"
        )
    Gs = np.array([invert(g) for g in G]) if setup == "eye_to_hand" else G
    A, B = _motions(Gs, C)
    _check_axes(A)
    if method == "daniilidis":
        X = _daniilidis(A, B)
    else:
        Rx = _tsai(A, B) if method == "tsai" else _park(A, B)
        X = np.eye(4)
        X[:3, :3] = Rx
        X[:3, 3] = _translation(A, B, Rx)
    if refine:
        X, Y = _refine(Gs, C, X)
    else:
        Y = _mean_pose(Gs @ X @ C)
    rot, trans = hand_eye_residuals(X, T_base_gripper, T_camera_target, setup)
    return HandEyeResult(X, Y, setup, method, rot, trans)
