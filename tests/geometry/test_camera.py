"""Camera projection and SE(3): librealsense parity for every model, OpenCV parity for
Brown-Conrady, round trips, hand cases."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robopercept.errors import InputError
from robopercept.geometry import (
    MODELS,
    CameraIntrinsics,
    apply,
    compose,
    deproject,
    distort,
    invert,
    project,
    rotation_from_rotvec,
    se3,
    undistort,
    undistort_points,
)
from robopercept.geometry.camera import (
    check_distortion,
    compiled_params,
    distort_point,
    lens_model_code,
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


def _distort_reference(x, y, c, modified):
    # the NumPy reference of the compiled lens model (the formulas of the module docstring)
    k1, k2, p1, p2, k3 = c
    r2 = x * x + y * y
    f = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    if modified:
        x, y = x * f, y * f
        return x + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y + 2 * p2 * x * y + p1 * (
            r2 + 2 * y * y
        )
    return (
        x * f + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
        y * f + 2 * p2 * x * y + p1 * (r2 + 2 * y * y),
    )


class TestDistort:
    def test_hand_case(self):
        # k1 only: x_d = x (1 + k1 r^2); p1 only: x_d = x + 2 p1 x y, y_d = y + p1 (r^2 + 2 y^2)
        xd, yd = distort(0.2, 0.1, (0.5, 0.0, 0.0, 0.0, 0.0))
        np.testing.assert_allclose([xd, yd], [0.2 * 1.025, 0.1 * 1.025], rtol=1e-15)
        xd, yd = distort(0.2, 0.1, (0.0, 0.0, 0.01, 0.0, 0.0))
        np.testing.assert_allclose([xd, yd], [0.2 + 0.0004, 0.1 + 0.01 * 0.07], rtol=1e-15)
        assert distort(0.3, -0.2, COEFFS, "none") == (0.3, -0.2)
        xd, yd = distort(np.zeros((3, 1)), np.full(4, 0.1), COEFFS)  # broadcast together
        assert xd.shape == yd.shape == (3, 4)

    @pytest.mark.parametrize("model", MODELS)
    def test_compiled_matches_numpy_reference(self, model):
        # exact: the kernel evaluates the same operations in the same order
        rng = np.random.default_rng(5)
        x, y = rng.normal(0, 0.4, (2, 7, 9))
        xd, yd = distort(x, y, COEFFS, model)
        assert xd.shape == yd.shape == (7, 9)
        if model == "none":
            ref = (x, y)
        else:
            ref = _distort_reference(x, y, COEFFS, model != "brown_conrady")
        np.testing.assert_array_equal(xd, ref[0])
        np.testing.assert_array_equal(yd, ref[1])
        code = lens_model_code(model)
        c = np.array(COEFFS)
        assert distort_point(x[0, 0], y[0, 0], c, code) == (xd[0, 0], yd[0, 0])

    def test_matches_opencv_project_points(self):
        # cv2.projectPoints with K = I gives the distorted normalized coordinates; both
        # evaluate the same polynomial in float64
        rng = np.random.default_rng(6)
        x, y = rng.uniform(-0.6, 0.6, (2, 200))
        ref, _ = cv2.projectPoints(
            np.column_stack([x, y, np.ones_like(x)]), np.zeros(3), np.zeros(3), np.eye(3),
            np.array(COEFFS),
        )  # fmt: skip
        xd, yd = distort(x, y, COEFFS)
        np.testing.assert_allclose(np.column_stack([xd, yd]), ref[:, 0], atol=1e-13)

    @pytest.mark.parametrize("model", ["brown_conrady", "inverse_brown_conrady"])
    def test_undistort_round_trip(self, model):
        rng = np.random.default_rng(7)
        c = (0.05, -0.02, 0.001, 0.0005, 0.0)
        x, y = rng.uniform(-0.5, 0.5, (2, 100))
        xu, yu = undistort(*distort(x, y, c, model), c, model)
        np.testing.assert_allclose(xu, x, atol=1e-9)
        np.testing.assert_allclose(yu, y, atol=1e-9)
        xn, yn = undistort(x, y, c, "none")
        np.testing.assert_array_equal(xn, x)
        np.testing.assert_array_equal(yn, y)

    def test_undistort_points_matches_opencv(self):
        # the same 5 fixed-point rounds as cv2.undistortPoints, the same float64
        # operations: equal to rounding (OpenCV ignores a skew K[0, 1], so none here)
        rng = np.random.default_rng(8)
        K = np.array([[600.0, 0.0, 321.0], [0.0, 605.0, 239.0], [0.0, 0.0, 1.0]])
        px = rng.uniform(0, 640, (200, 2))
        ref = cv2.undistortPoints(px[:, None], K, np.array(COEFFS))[:, 0]
        np.testing.assert_allclose(undistort_points(px, K, COEFFS), ref, atol=1e-12)
        K0 = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
        np.testing.assert_allclose(undistort_points([[370.0, 140.0]], K0), [[0.1, -0.2]])
        # skew: x = (u - cx - s y) / fx, exact without distortion
        Ks = [[500.0, 2.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
        np.testing.assert_allclose(
            undistort_points([[370.0, 140.0]], Ks), [[(50.0 + 2.0 * 0.2) / 500.0, -0.2]]
        )

    def test_check_distortion_and_compiled_params(self):
        np.testing.assert_array_equal(check_distortion(None), np.zeros(5))
        np.testing.assert_array_equal(check_distortion([[1, 2, 3, 4]]), [1, 2, 3, 4, 0])
        k, code, c = compiled_params(camera("inverse_brown_conrady"))
        np.testing.assert_array_equal(k, [640.5, 641.25, 637.2, 361.9])
        assert code == lens_model_code("modified_brown_conrady") == 2
        np.testing.assert_array_equal(c, COEFFS)
        assert [lens_model_code(m) for m in ("none", "brown_conrady")] == [0, 1]

    @pytest.mark.parametrize(
        ("call", "match"),
        [
            (lambda: distort(0.1, 0.1, COEFFS, "fisheye"), "model must be one of 'none'"),
            (lambda: lens_model_code("kannala_brandt"), "brown_conrady"),
            (lambda: undistort(0.1, 0.1, COEFFS, "fisheye"), "model must be one of"),
            (lambda: undistort(0.1, 0.1, COEFFS, "modified_brown_conrady"), "forward-only"),
            (lambda: distort(0.1, 0.1, (1.0, 2.0)), "5 numbers"),
            (lambda: undistort(0.1, 0.1, (1.0, 2.0, 3.0, 4.0)), "5 numbers"),
            (lambda: check_distortion([1.0, 2.0, 3.0]), "4 or 5 coefficients"),
            (lambda: check_distortion([np.nan] * 5, "D1"), "D1"),
            (lambda: undistort_points(np.zeros((3, 3)), np.eye(3)), r"\(N, 2\)"),
            (lambda: undistort_points(np.zeros((3, 2)), np.eye(2)), "3x3"),
        ],
    )
    def test_bad_input(self, call, match):
        with pytest.raises(InputError, match=match):
            call()
