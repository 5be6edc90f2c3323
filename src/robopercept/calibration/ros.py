r"""ROS file formats: ``sensor_msgs/CameraInfo`` YAML and transforms with quaternions.

**camera_info YAML**, as ``camera_calibration_parsers`` writes it (and
``camera_info_manager`` reads it; the ``camera_calibration`` node saves one per camera)::

    image_width: 640
    image_height: 480
    camera_name: camera
    camera_matrix:
      rows: 3
      cols: 3
      data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]
    distortion_model: plumb_bob
    distortion_coefficients:
      rows: 1
      cols: 5
      data: [k1, k2, p1, p2, k3]
    rectification_matrix:
      rows: 3
      cols: 3
      data: [...]
    projection_matrix:
      rows: 3
      cols: 4
      data: [...]

``plumb_bob`` is OpenCV's five-coefficient radial-tangential model, the one robopercept
uses. The rectification matrix R turns the camera frame into the rectified one (the
identity for one camera) and the projection matrix
:math:`P = \begin{bmatrix} f_x' & 0 & c_x' & T_x \\ 0 & f_y' & c_y' & T_y \\ 0 & 0 & 1 & 0
\end{bmatrix}` projects rectified points; :math:`T_x = -f_x' B` for the right camera of a
stereo pair with baseline B (``cv2.stereoRectify``'s ``P2``), 0 otherwise.

**Transforms** follow ``geometry_msgs/TransformStamped``: ``header.frame_id`` is the
parent frame, ``child_frame_id`` the child, and ``transform`` holds the translation
``{x, y, z}`` and the rotation as a unit quaternion ``{x, y, z, w}`` (ROS order, scalar
last) of :math:`T_{parent,child}`, which maps child-frame points into the parent frame
(``T_a_b`` of :mod:`robopercept.geometry.transforms`). The quaternion of a rotation
matrix R is Shepperd's: from the largest of :math:`1 + \operatorname{tr} R` and
:math:`1 + 2 R_{ii} - \operatorname{tr} R`, with :math:`w \ge 0` (as
``scipy.spatial.transform.Rotation.as_quat(canonical=True)``).

Both are written as plain YAML (block mappings, flow sequences), read back by
:func:`~robopercept.calibration.load_calibration`, :func:`read_transform` and any YAML
reader.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import as_path, check_numeric, check_text, plain_repr
from robopercept.calibration.filestorage import read_opencv_storage
from robopercept.errors import FileFormatError, InputError
from robopercept.geometry.camera import check_distortion
from robopercept.geometry.transforms import check_matrix3, check_transform, nearest_rotation

__all__ = [
    "camera_info",
    "quaternion_from_rotation",
    "read_transform",
    "rotation_from_quaternion",
    "transform_stamped",
    "write_ros_yaml",
]

_PLAIN = re.compile(r"[A-Za-z_/][A-Za-z0-9_./-]*\Z")
_RESERVED = {"true", "false", "yes", "no", "on", "off", "null", "~", "y", "n"}


# --------------------------------------------------------------------------- rotations


def quaternion_from_rotation(R: npt.ArrayLike) -> np.ndarray:
    r"""Unit quaternion ``(x, y, z, w)`` (ROS order, scalar last, :math:`w \ge 0`) of a
    rotation matrix.

    Shepperd's method: with :math:`t = \operatorname{tr} R`, if :math:`t` is the largest
    of :math:`t, R_{00}, R_{11}, R_{22}` then :math:`w = \tfrac12\sqrt{1 + t}` and
    :math:`(x, y, z) = (R_{21} - R_{12}, R_{02} - R_{20}, R_{10} - R_{01}) / (4 w)`;
    otherwise the same from the largest diagonal entry. Matches
    ``scipy.spatial.transform.Rotation.from_matrix(R).as_quat(canonical=True)``.

    Parameters
    ----------
    R : (3, 3) array_like
        A rotation matrix (made exactly orthonormal first, by SVD).

    Returns
    -------
    (4,) ndarray
        ``x, y, z, w``.

    Raises
    ------
    InputError
        Not a finite 3x3 matrix.

    Examples
    --------
    >>> R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    >>> np.round(quaternion_from_rotation(R), 6)
    array([0.      , 0.      , 0.707107, 0.707107])
    """
    m = nearest_rotation(check_matrix3(R, "R"))
    t = np.trace(m)
    k = int(np.argmax([t, m[0, 0], m[1, 1], m[2, 2]]))
    if k == 0:
        w = 0.5 * math.sqrt(max(1.0 + t, 0.0))
        q = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1], 0.0]) / (4 * w)
        q[3] = w
    else:
        i = k - 1
        j, m2 = (i + 1) % 3, (i + 2) % 3
        v = 0.5 * math.sqrt(max(1.0 + 2 * m[i, i] - t, 0.0))
        q = np.empty(4)
        q[i] = v
        q[j] = (m[j, i] + m[i, j]) / (4 * v)
        q[m2] = (m[m2, i] + m[i, m2]) / (4 * v)
        q[3] = (m[m2, j] - m[j, m2]) / (4 * v)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def rotation_from_quaternion(q: npt.ArrayLike) -> np.ndarray:
    r"""Rotation matrix of a quaternion ``(x, y, z, w)`` (ROS order), normalized first.

    .. math::

        R = \begin{bmatrix}
        1 - 2(y^2 + z^2) & 2(xy - zw) & 2(xz + yw) \\
        2(xy + zw) & 1 - 2(x^2 + z^2) & 2(yz - xw) \\
        2(xz - yw) & 2(yz + xw) & 1 - 2(x^2 + y^2)
        \end{bmatrix}

    Parameters
    ----------
    q : (4,) array_like
        ``x, y, z, w``; any nonzero length.

    Returns
    -------
    (3, 3) ndarray

    Raises
    ------
    InputError
        Not 4 finite numbers, or all zero.

    Examples
    --------
    >>> rotation_from_quaternion([0, 0, 0, 1])
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    """
    v = check_numeric(q, "q").astype(np.float64).reshape(-1)
    if v.size != 4 or not np.isfinite(v).all():
        raise InputError(f"q must be 4 finite numbers (x, y, z, w); got {plain_repr(q)[:60]}")
    n = np.linalg.norm(v)
    if not n > 1e-12:
        raise InputError("q is zero: a rotation quaternion has length 1 (identity: 0 0 0 1)")
    x, y, z, w = v / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


# --------------------------------------------------------------------------- messages


def _frame(value: Any, name: str) -> str:
    text = check_text(value, name)
    if not text or any(c in text for c in "\n\r\t"):
        raise InputError(f"{name} must be a frame name such as 'base_link'; got {text!r}")
    return text


def transform_stamped(T: npt.ArrayLike, parent_frame: str, child_frame: str) -> dict[str, Any]:
    r"""A 4x4 transform :math:`T_{parent,child}` as a ``geometry_msgs/TransformStamped``
    dictionary (without the time stamp).

    Parameters
    ----------
    T : (4, 4) array_like
        Maps child-frame points into the parent frame; its rotation is made exactly
        orthonormal.
    parent_frame, child_frame : str
        ``header.frame_id`` and ``child_frame_id``.

    Returns
    -------
    dict
        ``{"header": {"frame_id": parent}, "child_frame_id": child, "transform":
        {"translation": {"x", "y", "z"}, "rotation": {"x", "y", "z", "w"}}}``, floats.

    Raises
    ------
    InputError
        ``T`` not a finite 4x4 rigid transform, or an empty frame name.

    Examples
    --------
    >>> msg = transform_stamped(np.eye(4), "tool0", "camera_optical_frame")
    >>> msg["transform"]["rotation"]
    {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}
    """
    m = check_transform(T, "T")
    parent = _frame(parent_frame, "parent_frame")
    child = _frame(child_frame, "child_frame")
    q = quaternion_from_rotation(m[:3, :3])
    t = m[:3, 3]
    return {
        "header": {"frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": float(t[0]), "y": float(t[1]), "z": float(t[2])},
            "rotation": {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])},
        },
    }


def read_transform(path: str | Path) -> tuple[np.ndarray, str, str]:
    """Read a transform YAML or JSON file written from :func:`transform_stamped`
    (``geometry_msgs/TransformStamped`` fields).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    T : (4, 4) ndarray
        :math:`T_{parent,child}`.
    parent_frame, child_frame : str

    Raises
    ------
    FileFormatError
        Unreadable, or ``header.frame_id``, ``child_frame_id``,
        ``transform.translation.{x,y,z}`` or ``transform.rotation.{x,y,z,w}`` missing
        or not numbers, or a zero quaternion.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> T = np.eye(4); T[:3, 3] = [0.1, 0.0, 0.5]
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = write_ros_yaml(pathlib.Path(d) / "x.yaml", transform_stamped(T, "a", "b"))
    ...     back, parent, child = read_transform(p)
    >>> back[:3, 3], parent, child
    (array([0.1, 0. , 0.5]), 'a', 'b')
    """
    data = read_opencv_storage(path)
    try:
        parent = data["header"]["frame_id"]
        child = data["child_frame_id"]
        tr = data["transform"]
        t = [tr["translation"][k] for k in "xyz"]
        q = [tr["rotation"][k] for k in "xyzw"]
        if not all(isinstance(v, str) for v in (parent, child)):
            raise TypeError("frame names must be strings")
        vals = np.array(
            [v if not isinstance(v, bool) and isinstance(v, (int, float)) else np.nan
             for v in t + q], dtype=np.float64,
        )  # fmt: skip
        if not np.isfinite(vals).all():
            raise ValueError("translation and rotation must be finite numbers")
        R = rotation_from_quaternion(vals[3:])
    except (KeyError, TypeError, ValueError, OverflowError, InputError) as exc:
        raise FileFormatError(
            f"{path}: not a transform (header.frame_id, child_frame_id, "
            f"transform.translation x y z, transform.rotation x y z w): {exc}"
        ) from exc
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = vals[:3]
    return T, parent, child


def camera_info(
    K: npt.ArrayLike,
    dist: npt.ArrayLike | None,
    image_size: tuple[int, int],
    *,
    camera_name: str = "camera",
    R: npt.ArrayLike | None = None,
    P: npt.ArrayLike | None = None,
) -> dict[str, Any]:
    """A ``sensor_msgs/CameraInfo`` calibration as ``camera_calibration_parsers``
    writes it in YAML (the keys and order of the module docstring).

    Parameters
    ----------
    K : (3, 3) array_like
        Camera matrix.
    dist : array_like or None
        ``(k1, k2, p1, p2[, k3])`` (None: no distortion), written as five.
    image_size : (int, int)
        ``(width, height)``.
    camera_name : str
    R : (3, 3) array_like, optional
        Rectification rotation (default the identity: one camera).
    P : (3, 4) array_like, optional
        Projection matrix (default ``[K | 0]``: the undistorted image keeps ``K``).

    Returns
    -------
    dict
        ``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``,
        ``distortion_model`` (``plumb_bob``), ``distortion_coefficients``,
        ``rectification_matrix``, ``projection_matrix``; matrices as ``{rows, cols,
        data}`` with ``data`` a list of floats, row-major.

    Raises
    ------
    InputError
        Matrices that are not finite of the shapes above, distortion that is not 4 or 5
        finite numbers, a size that is not two positive integers, an empty name.

    Examples
    --------
    >>> info = camera_info(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), None,
    ...                    (640, 480))
    >>> info["projection_matrix"]["data"][:4], info["distortion_model"]
    ([500.0, 0.0, 320.0, 0.0], 'plumb_bob')
    """
    k = check_matrix3(K, "K", invertible=True)
    d = check_distortion(dist, "dist")
    if not (
        isinstance(image_size, (tuple, list))
        and len(image_size) == 2
        and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0
                for v in image_size)
    ):  # fmt: skip
        raise InputError(
            f"image_size must be (width, height), two positive integers; got "
            f"{plain_repr(image_size)}"
        )
    name = _frame(camera_name, "camera_name")
    r = np.eye(3) if R is None else check_matrix3(R, "R")
    if P is None:
        p = np.c_[k, np.zeros(3)]
    else:
        p = check_numeric(P, "P").astype(np.float64)
        if p.shape != (3, 4) or not np.isfinite(p).all():
            raise InputError(f"P must be a finite 3x4 projection matrix; got shape {p.shape}")

    def mat(a: np.ndarray) -> dict[str, Any]:
        a = np.atleast_2d(a)
        return {"rows": a.shape[0], "cols": a.shape[1], "data": [float(v) for v in a.ravel()]}

    return {
        "image_width": int(image_size[0]),
        "image_height": int(image_size[1]),
        "camera_name": name,
        "camera_matrix": mat(k),
        "distortion_model": "plumb_bob",
        "distortion_coefficients": mat(np.r_[d, np.zeros(5)][:5].reshape(1, 5)),
        "rectification_matrix": mat(r),
        "projection_matrix": mat(p),
    }


# --------------------------------------------------------------------------- YAML


def write_ros_yaml(path: str | Path, data: Mapping[str, Any]) -> Path:
    """Write nested mappings of numbers and strings as plain YAML, the way
    ``camera_calibration_parsers`` and ``ros2 topic echo`` print messages: block
    mappings indented by two spaces, lists as flow sequences ``[1.0, 2.0]``, floats in
    their shortest exact form, strings plain when YAML reads them back as the same
    string (``base_link``, ``narrow_stereo/left``), else double-quoted.

    Parameters
    ----------
    path : str or Path
        The ``.yaml`` file to write (replaced if it exists).
    data : mapping
        Values: mappings, lists of numbers or strings, int, float, bool, str.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Another value type (None, arrays: convert with ``.tolist()``), a key that is not
        a non-empty string, a path that is not usable or a folder.
    FileFormatError
        The file cannot be written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = write_ros_yaml(pathlib.Path(d) / "a.yaml", {"m": {"rows": 1, "data": [0.5, 2.0]}})
    ...     print(p.read_text(), end="")
    m:
      rows: 1
      data: [0.5, 2.0]
    """
    if not isinstance(data, Mapping):
        raise InputError(f"data must be a mapping; got {type(data).__name__}")
    p = as_path(path, "path")
    if p.is_dir():
        raise InputError(f"path {p} is a folder; give a file name such as {p / 'camera.yaml'}")
    lines: list[str] = []
    _yaml_mapping(lines, data, "", "data")
    try:
        p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot write ({exc.strerror or exc})") from exc
    return p


def _yaml_mapping(lines: list[str], data: Mapping[str, Any], pad: str, where: str) -> None:
    for key, value in data.items():
        if not (isinstance(key, str) and key and _PLAIN.match(key)):
            raise InputError(f"{where}: keys must be plain names; got {plain_repr(key)}")
        if isinstance(value, Mapping):
            lines.append(f"{pad}{key}:" if value else f"{pad}{key}: {{}}")
            _yaml_mapping(lines, value, pad + "  ", f"{where}[{key!r}]")
        elif isinstance(value, (list, tuple)):
            items = ", ".join(_yaml_scalar(v, f"{where}[{key!r}]") for v in value)
            lines.append(f"{pad}{key}: [{items}]")
        else:
            lines.append(f"{pad}{key}: {_yaml_scalar(value, f'{where}[{key!r}]')}")


def _yaml_scalar(value: Any, where: str) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isnan(v):
            return ".nan"
        if math.isinf(v):
            return ".inf" if v > 0 else "-.inf"
        return repr(v)
    if isinstance(value, str):
        if _PLAIN.match(value) and value.lower() not in _RESERVED:
            return value
        return json.dumps(value, ensure_ascii=False)
    raise InputError(
        f"{where}: YAML values here are numbers, strings, lists and mappings; got "
        f"{type(value).__name__} {plain_repr(value)[:60]}"
    )
