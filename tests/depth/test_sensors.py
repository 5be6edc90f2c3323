"""Active sensor models: time of flight (pulse, phase, unwrapping) and active stereo."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.depth.sensors import (
    D435,
    SPEED_OF_LIGHT,
    ActiveStereoSensor,
    focal_from_fov,
    tof_ambiguity_range,
    tof_phase,
    tof_phase_distance,
    tof_pulse_distance,
    tof_pulse_time,
    tof_unwrap,
)
from robopercept.errors import InputError


def test_pulse():
    assert tof_pulse_distance(10e-9) == pytest.approx(1.49896229)  # 10 ns: 1.5 m
    assert tof_pulse_time(1.0) == pytest.approx(6.671281903963e-9)
    d = np.array([0.3, 2.0, 40.0])
    assert np.allclose(tof_pulse_distance(tof_pulse_time(d)), d)
    # a millimetre of depth is 6.7 picoseconds of round trip
    assert tof_pulse_time(1e-3) == pytest.approx(6.67e-12, rel=1e-3)
    with pytest.raises(InputError):
        tof_pulse_distance(-1.0)


def test_phase_and_ambiguity():
    f = 20e6
    assert tof_ambiguity_range(f) == pytest.approx(SPEED_OF_LIGHT / 4e7)  # 7.49 m
    assert tof_phase_distance(np.pi, f) == pytest.approx(SPEED_OF_LIGHT / 8e7)  # half range
    d = np.array([0.5, 3.0, 7.0])
    assert np.allclose(tof_phase_distance(tof_phase(d, f), f), d)
    # beyond the range the distance aliases: 10 m reads 10 - 7.49 m
    r = tof_ambiguity_range(f)
    assert tof_phase_distance(tof_phase(10.0, f), f) == pytest.approx(10.0 - r)
    with pytest.raises(InputError):
        tof_ambiguity_range(0.0)


def test_two_frequencies_unwrap():
    """20 and 25 MHz: gcd 5 MHz, unambiguous to 30 m; each alone wraps at 7.5 / 6 m."""
    f1, f2 = 20e6, 25e6
    d = np.array([0.4, 6.5, 9.9, 17.3, 29.0])
    got = tof_unwrap(tof_phase(d, f1), f1, tof_phase(d, f2), f2, max_distance=29.9)
    assert np.allclose(got, d, atol=1e-9)
    noisy = tof_unwrap(tof_phase(d, f1) + 0.02, f1, tof_phase(d, f2) - 0.02, f2, 29.9)
    assert np.abs(noisy - d).max() < 0.05


def test_active_stereo_error_grows_with_distance_squared():
    f = focal_from_fov(848, 87.0)
    assert f == pytest.approx(424 / np.tan(np.radians(43.5)))
    assert D435.focal == pytest.approx(f)
    e1, e2 = D435.depth_rms_error([1.0, 2.0])
    assert e1 == pytest.approx(0.08 / (f * 0.05))  # about 3.6 mm at 1 m
    assert e2 == pytest.approx(4 * e1)
    assert D435.min_depth == pytest.approx(f * 0.05 / 126)
    assert D435.disparity(D435.min_depth) == pytest.approx(126)
    wide = ActiveStereoSensor(baseline=0.1, width=848, hfov_deg=87.0)
    assert wide.depth_rms_error(2.0) == pytest.approx(D435.depth_rms_error(2.0) / 2)
    with pytest.raises(InputError, match=r"hfov_deg must be in \(0, 180\)"):
        focal_from_fov(640, 180)


# issue 25: scalars checked for type and finiteness, the unwrapping bounded
@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: tof_ambiguity_range(None), "modulation_frequency must be a real number"),
        (lambda: tof_phase(1.0, 1 + 1j), "modulation_frequency must be a real number"),
        (lambda: tof_phase_distance(0.5, np.inf), "modulation_frequency must be finite"),
        (lambda: tof_pulse_distance(["a"]), "round_trip_time must hold real numbers"),
        (lambda: tof_pulse_distance(-1.0), "round_trip_time must be >= 0"),
        (lambda: tof_unwrap(0.1, 1 + 1j, 0.2, 25e6, 30.0), "f1 must be a real number"),
        (lambda: tof_unwrap(np.zeros(0), 20e6, np.zeros((2, 1)), 25e6, 30.0), "same shape"),
        (
            lambda: tof_unwrap([0.1, 0.2], 20e6, [0.2, 0.1], 25e6, 3.7e8),
            "lower max_distance or raise f1",
        ),
        (lambda: tof_unwrap(0.1, 2.0**63, 0.2, 25e6, 30.0), "more than 16777216 candidates"),
        (lambda: focal_from_fov([1, 2], 87.0), "width must be a real number"),
        (lambda: focal_from_fov(640, None), "hfov_deg must be a real number"),
        (lambda: ActiveStereoSensor(baseline=None, width=848, hfov_deg=87.0), "baseline"),
        (lambda: ActiveStereoSensor(0.05, 848.5, 87.0), "width must be an integer"),
        (lambda: ActiveStereoSensor(0.05, 848, 87.0, max_disparity=0), "max_disparity"),
        (lambda: D435.disparity([["a"]]), "depth must hold real numbers"),
    ],
)
def test_bad_arguments_give_input_errors(call, words):
    with pytest.raises(InputError, match=words):
        call()


def test_unwrap_of_single_phases_and_a_numpy_frequency():
    f1, f2 = 20e6, 25e6
    got = tof_unwrap(tof_phase(17.3, f1), np.float32(f1), tof_phase(17.3, f2), f2, 29.9)
    assert got.shape == () and float(got) == pytest.approx(17.3, abs=1e-6)
