"""Camera projection and SE(3): librealsense parity for every model, OpenCV parity for
Brown-Conrady, round trips, hand cases."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robopercept.errors import InputError
from robopercept.geometry import (
    CameraIntrinsics,
    apply,
    compose,
    deproject,
    invert,
    project,
    rotation_from_rotvec,
    se3,
)

rs = pytest.importorskip("pyrealsense2")

COEFFS = (0.12, -0.21, 0.0015, -0.0008, 0.05)
RS_MODELS = {
    "none": "none",
    "brown_conrady": "brown_conrady",
    "modified_brown_conrady": "modified_brown_conrady",
    "inverse_brown_conrady": "inverse_brown_conrady",
}


def rs_intrinsics(k: CameraIntrinsics):
    i = rs.intrinsics()
    i.width, i.height = k.width, k.height
    i.fx, i.fy, i.ppx, i.ppy = k.fx, k.fy, k.cx, k.cy
    i.model = getattr(rs.distortion, RS_MODELS[k.model])
    i.coeffs = list(k.coeffs)
    return i


def camera(model):
    return CameraIntrinsics(1280, 720, 640.5, 641.25, 637.2, 361.9, model, COEFFS)


@pytest.mark.parametrize("model", list(RS_MODELS))
def test_matches_librealsense(model):
    rng = np.random.default_rng(0)
    k = camera(model)
    ri = rs_intrinsics(k)
    pts = np.column_stack(
        [rng.uniform(-0.8, 0.8, 300), rng.uniform(-0.5, 0.5, 300), rng.uniform(0.3, 3, 300)]
    )
    ours = project(pts, k)
    ref = np.array([rs.rs2_project_point_to_pixel(ri, p.tolist()) for p in pts])
    inside = (ref[:, 0] >= 0) & (ref[:, 0] < 1280) & (ref[:, 1] >= 0) & (ref[:, 1] < 720)
    # librealsense evaluates the lens polynomial in float32 (relative rounding ~2e-7 of
    # the normalized coordinate, up to ~1.6e-4 px at the corners of a 1280-px image with
    # these strong coefficients); we evaluate in float64. Inside the image the two agree
    # to 2e-4 px, and to 1e-4 px without distortion
    tol = 1e-4 if model == "none" else 2e-4
    np.testing.assert_allclose(ours[inside], ref[inside], atol=tol)
    assert inside.mean() > 0.8
    if model == "modified_brown_conrady":
        with pytest.raises(InputError, match="forward-only"):
            deproject(ours, 1.0, k)
        return
    pix = np.column_stack([rng.uniform(0, 1280, 300), rng.uniform(0, 720, 300)])
    depth = rng.uniform(0.3, 3.0, 300)
    ours = deproject(pix, depth, k)
    ref = np.array(
        [
            rs.rs2_deproject_pixel_to_point(ri, p.tolist(), float(d))
            for p, d in zip(pix, depth, strict=True)
        ]
    )
    np.testing.assert_allclose(ours, ref, atol=1e-6)


@pytest.mark.parametrize("model", ["none", "brown_conrady", "inverse_brown_conrady"])
def test_round_trip(model):
    rng = np.random.default_rng(1)
    k = CameraIntrinsics(
        848, 480, 420.0, 421.0, 424.0, 240.0, model, (0.05, -0.02, 0.001, 0.0005, 0.0)
    )
    pix = np.column_stack([rng.uniform(0, 848, 500), rng.uniform(0, 480, 500)])
    back = project(deproject(pix, 1.7, k), k)
    np.testing.assert_allclose(back, pix, atol=1e-6)


def test_brown_conrady_projection_matches_opencv():
    rng = np.random.default_rng(2)
    k = camera("brown_conrady")
    pts = np.column_stack(
        [rng.uniform(-0.5, 0.5, 100), rng.uniform(-0.3, 0.3, 100), rng.uniform(0.5, 2, 100)]
    )
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k.K, np.array(COEFFS))
    np.testing.assert_allclose(project(pts, k), ref[:, 0], atol=1e-9)


def test_pinhole_hand_case_and_shapes():
    k = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    np.testing.assert_allclose(project([0.1, -0.2, 2.0], k), [345.0, 190.0])
    np.testing.assert_allclose(deproject([345.0, 190.0], 2.0, k), [0.1, -0.2, 2.0])
    grid = np.zeros((4, 5, 2))
    assert deproject(grid, np.ones((4, 5)), k).shape == (4, 5, 3)
    assert np.isnan(project([0.0, 0.0, -1.0], k)).all()  # behind the camera
    np.testing.assert_allclose(k.K, [[500, 0, 320], [0, 500, 240], [0, 0, 1]])
    half = k.scaled(320, 240)
    assert (half.fx, half.cx) == (250.0, 159.75)


def test_se3_helpers():
    rng = np.random.default_rng(3)
    R = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    np.testing.assert_allclose(rotation_from_rotvec([0.3, -0.2, 0.5]), R, atol=1e-12)
    T_ab = se3(R, [1, 2, 3])
    T_bc = se3([0.0, 0.4, 0.0], [0, -1, 0.5])
    p = rng.normal(size=(10, 3))
    np.testing.assert_allclose(apply(compose(T_ab, T_bc), p), apply(T_ab, apply(T_bc, p)))
    np.testing.assert_allclose(apply(invert(T_ab), apply(T_ab, p)), p, atol=1e-12)
    np.testing.assert_allclose(invert(T_ab), np.linalg.inv(T_ab), atol=1e-12)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: CameraIntrinsics(0, 480, 1, 1, 0, 0), "width"),
        (lambda: CameraIntrinsics(640, 480, -1, 1, 0, 0), "fx"),
        (lambda: CameraIntrinsics(640, 480, 1, 1, 0, 0, "fisheye"), "model"),
        (lambda: CameraIntrinsics(640, 480, 1, 1, 0, 0, "none", (1, 2)), "coeffs"),
        (lambda: project(np.zeros((3, 2)), camera("none")), "shape"),
        (lambda: se3(np.ones((3, 3))), "orthonormal"),
        (lambda: invert(np.ones((4, 4))), "last row"),
        (lambda: CameraIntrinsics.from_matrix(np.ones((3, 3)), 10, 10), "K must be"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()
