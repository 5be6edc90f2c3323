"""Rodrigues (one vector and stacks) and the 3x3 matrix check: hand cases, parity with
cv2.Rodrigues and SciPy, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robopercept.errors import InputError
from robopercept.geometry import nearest_rotation, rotation_from_rotvec, rotvec_from_rotation, se3
from robopercept.geometry.transforms import check_matrix3


class TestRotationFromRotvec:
    def test_hand_case(self):
        # a quarter turn about z takes x to y
        R = rotation_from_rotvec([0.0, 0.0, np.pi / 2])
        np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
        np.testing.assert_array_equal(rotation_from_rotvec(np.zeros(3)), np.eye(3))

    def test_matches_opencv_and_scipy(self):
        # float64 evaluations of the same formula: agreement to rounding
        rng = np.random.default_rng(0)
        r = rng.normal(size=(20, 3))
        ours = rotation_from_rotvec(r)
        assert ours.shape == (20, 3, 3)
        np.testing.assert_allclose(ours, Rotation.from_rotvec(r).as_matrix(), atol=1e-14)
        for v, R in zip(r, ours, strict=True):
            np.testing.assert_allclose(R, cv2.Rodrigues(v)[0], atol=1e-14)

    def test_stack_equals_one_at_a_time_and_shapes(self):
        rng = np.random.default_rng(1)
        r = rng.normal(size=(2, 4, 3))
        stack = rotation_from_rotvec(r)
        assert stack.shape == (2, 4, 3, 3)
        for idx in np.ndindex(2, 4):
            np.testing.assert_array_equal(stack[idx], rotation_from_rotvec(r[idx]))
        assert rotation_from_rotvec(r[0, :1]).shape == (1, 3, 3)
        np.testing.assert_array_equal(rotation_from_rotvec(r[0, 0][:, None]), stack[0, 0])

    def test_small_angle_first_order_and_round_trip(self):
        r = np.array([1e-13, -2e-13, 3e-13])
        R = rotation_from_rotvec(r)
        np.testing.assert_allclose(R - np.eye(3), [[0, -3e-13, -2e-13], [3e-13, 0, -1e-13],
                                                   [2e-13, 1e-13, 0]], atol=1e-25)  # fmt: skip
        rng = np.random.default_rng(2)
        for v in rng.normal(size=(10, 3)):
            v *= min(1.0, 3.0 / np.linalg.norm(v))  # angles below pi
            np.testing.assert_allclose(rotvec_from_rotation(rotation_from_rotvec(v)), v,
                                       atol=1e-12)  # fmt: skip

    def test_bad_input(self):
        with pytest.raises(InputError, match=r"\(\.\.\., 3\)"):
            rotation_from_rotvec(np.zeros(4))
        with pytest.raises(InputError, match="rotvec"):
            rotation_from_rotvec(np.zeros((5, 2)))


class TestCheckMatrix3:
    def test_returns_float64(self):
        m = check_matrix3([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "K")
        assert m.dtype == np.float64
        np.testing.assert_array_equal(m, np.eye(3))

    @pytest.mark.parametrize("bad", [np.eye(4), np.full((3, 3), np.nan), np.zeros(9)])
    def test_bad_input(self, bad):
        with pytest.raises(InputError, match="F must be a finite 3x3 matrix"):
            check_matrix3(bad, "F")


# issue 25: hostile scalars and arrays (strings, complex, object arrays, wrong shapes,
# singular matrices) gave NumPy's ValueError/LinAlgError; each is now an InputError that
# names the argument, and valid edge values still work
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: check_matrix3(np.eye(3, dtype=complex), "K"), "K must hold real numbers"),
        (lambda: check_matrix3(np.array([["a"] * 3] * 3), "K"), "K must hold real numbers"),
        (lambda: check_matrix3(np.full((3, 3), None), "K"), "K must"),
        (lambda: check_matrix3([[1, 2], [3]], "K"), "K must be a numeric array"),
        (lambda: check_matrix3(np.ones((3, 3)), "K", invertible=True), "K is singular"),
        (lambda: nearest_rotation(np.float64(1.0)), "M must be a finite 3x3"),
        (lambda: nearest_rotation(np.ones((4, 3))), "M must be a finite 3x3"),
        (lambda: nearest_rotation(np.full((3, 3), np.inf, dtype=np.complex64)), "M must hold"),
        (lambda: rotation_from_rotvec("abc"), "rotvec must hold real numbers"),
        (lambda: se3(translation=[1.0, np.nan, 0.0]), "translation must be 3 finite"),
    ],
)
def test_issue25_hostile_matrices_are_input_errors(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_nearest_rotation_still_works_on_valid_and_extreme_scales():
    R = rotation_from_rotvec([0.1, -0.2, 0.3])
    np.testing.assert_allclose(nearest_rotation(R + 1e-9), R, atol=1e-8)
    # a scaled rotation (entries near 1e300) gives the rotation, not NaN
    np.testing.assert_allclose(nearest_rotation(1e300 * R), R, atol=1e-12)
    assert check_matrix3(np.diag([500.0, 500.0, 1.0]), "K", invertible=True).dtype == np.float64
