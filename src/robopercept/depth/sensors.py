r"""Active depth sensors as models: time of flight (pulsed and continuous-wave) and
active stereo (structured light: a projected pattern gives texture to match).

**Pulsed time of flight** measures the round trip of a light pulse:
:math:`d = c\,t / 2`. A 1 mm depth step is 6.7 ps of time.

**Continuous-wave time of flight** measures the phase :math:`\varphi` of a modulation
at :math:`f_{mod}` that has gone out and back:

.. math::

    d = \frac{c\,\varphi}{4 \pi f_{mod}}, \qquad
    d_{max} = \frac{c}{2 f_{mod}} \ \text{(the ambiguity range)},

beyond which the phase wraps and distances alias (a target at
:math:`d + k\,d_{max}` reads :math:`d`). Two modulation frequencies extend the range
to that of their greatest common divisor.

**Active stereo** (the RealSense D435: two IR cameras 50 mm apart and a projector of a
random dot pattern) triangulates like passive stereo, :math:`z = f B / d`, so its error
grows with the square of the distance. Intel's figure of merit is the depth RMS error

.. math::

    \sigma_z = \frac{z^2\, s}{f B}, \qquad f = \frac{W / 2}{\tan(\mathrm{HFOV} / 2)},

with :math:`s` the subpixel accuracy of the matcher (about 0.08 px on a well-textured
wall). Passive stereo needs scene texture; active stereo brings its own pattern (which
fades in sunlight, where the passive part takes over). Time of flight needs no
texture but suffers from multipath and from dark or specular surfaces. Reflective
sensors (all of these) see the first surface; transmissive ones (X-ray CT) see through.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_int, check_numeric, check_real
from robopercept.errors import InputError

__all__ = [
    "D435",
    "SPEED_OF_LIGHT",
    "ActiveStereoSensor",
    "focal_from_fov",
    "tof_ambiguity_range",
    "tof_phase",
    "tof_phase_distance",
    "tof_pulse_distance",
    "tof_pulse_time",
    "tof_unwrap",
]

SPEED_OF_LIGHT = 299_792_458.0  # m/s


#: most distance candidates (phases x wraps) :func:`tof_unwrap` compares (in blocks of
#: 2**20, so memory stays small; this bounds the time, about two seconds)
MAX_CANDIDATES = 1 << 24


def _positive(value: float, name: str) -> float:
    """``value`` as a float after checking that it is one finite real number > 0."""
    return check_real(value, name, 0.0, low_inclusive=False)


def tof_pulse_distance(round_trip_time: npt.ArrayLike) -> np.ndarray:
    """Distance :math:`c t / 2` (m) of a pulse back after ``round_trip_time`` seconds."""
    t = check_numeric(round_trip_time, "round_trip_time")
    with np.errstate(invalid="ignore"):
        if (t < 0).any():
            raise InputError("round_trip_time must be >= 0 seconds")
    return SPEED_OF_LIGHT * t / 2.0


def tof_pulse_time(distance: npt.ArrayLike) -> np.ndarray:
    """Round-trip time :math:`2 d / c` (s) of a pulse to ``distance`` metres."""
    return 2.0 * check_numeric(distance, "distance") / SPEED_OF_LIGHT


def tof_ambiguity_range(modulation_frequency: float) -> float:
    """:math:`c / (2 f_{mod})` (m): beyond it the phase wraps."""
    return SPEED_OF_LIGHT / (2.0 * _positive(modulation_frequency, "modulation_frequency"))


def tof_phase(distance: npt.ArrayLike, modulation_frequency: float) -> np.ndarray:
    r"""Measured phase :math:`4 \pi f_{mod} d / c \bmod 2\pi` of a target at ``distance``."""
    f = _positive(modulation_frequency, "modulation_frequency")
    d = check_numeric(distance, "distance")
    return np.mod(4.0 * np.pi * f * d / SPEED_OF_LIGHT, 2.0 * np.pi)


def tof_phase_distance(phase: npt.ArrayLike, modulation_frequency: float) -> np.ndarray:
    r"""Distance :math:`c \varphi / (4 \pi f_{mod})` (m) in :math:`[0, d_{max})` of a
    phase (wrapped into :math:`[0, 2\pi)` first)."""
    f = _positive(modulation_frequency, "modulation_frequency")
    phi = np.mod(check_numeric(phase, "phase"), 2.0 * np.pi)
    return SPEED_OF_LIGHT * phi / (4.0 * np.pi * f)


def tof_unwrap(
    phase1: npt.ArrayLike, f1: float, phase2: npt.ArrayLike, f2: float, max_distance: float
) -> np.ndarray:
    r"""Distance from two phases at two modulation frequencies, up to ``max_distance``.

    Each candidate :math:`d_1 + k\,d_{max,1}` of the first frequency is compared with the
    phase it would give at the second; the candidate whose predicted phase is closest
    (on the circle) wins. Unambiguous up to the range of the frequencies' greatest
    common divisor, :math:`c / (2 \gcd(f_1, f_2))`.

    ``phase1`` and ``phase2`` must have the same shape; the number of candidates,
    ``phase1.size * (max_distance / d_max,1 + 1)``, is bounded by
    :data:`MAX_CANDIDATES`.
    """
    r1 = SPEED_OF_LIGHT / (2.0 * _positive(f1, "f1"))
    _positive(f2, "f2")
    dmax = _positive(max_distance, "max_distance")
    ph1, ph2 = check_numeric(phase1, "phase1"), check_numeric(phase2, "phase2")
    if ph1.shape != ph2.shape:
        raise InputError(
            f"phase1 and phase2 must have the same shape (one pair of phases per pixel); "
            f"got {ph1.shape} and {ph2.shape}"
        )
    wraps = dmax / r1 + 1.0
    if wraps * max(ph1.size, 1) > MAX_CANDIDATES:
        raise InputError(
            f"max_distance {dmax:g} m spans {wraps:.3g} ambiguity ranges of f1 ({r1:.3g} m) "
            f"for {ph1.size} phases, more than {MAX_CANDIDATES} candidates to compare: "
            "lower max_distance or raise f1"
        )
    d1 = tof_phase_distance(ph1, f1)
    p2 = np.mod(ph2, 2.0 * np.pi)[..., None]
    n_wraps = int(np.ceil(dmax / r1)) + 1
    # candidates in blocks of wraps, at most 2**20 values at a time: the first best one
    # wins (as argmin over all of them would pick)
    best, out = np.full(d1.shape, np.inf), d1.copy()
    step = max(1, (1 << 20) // max(d1.size, 1))
    for k0 in range(0, n_wraps, step):
        cand = d1[..., None] + np.arange(k0, min(k0 + step, n_wraps)) * r1
        err = np.abs(np.angle(np.exp(1j * (tof_phase(cand, f2) - p2))))
        err = np.where(cand <= dmax + r1 * 1e-9, err, np.inf)
        i = np.argmin(err, axis=-1)[..., None]
        e = np.take_along_axis(err, i, axis=-1)[..., 0]
        better = e < best
        best = np.where(better, e, best)
        out = np.where(better, np.take_along_axis(cand, i, axis=-1)[..., 0], out)
    return out


def focal_from_fov(width: int, hfov_deg: float) -> float:
    r"""Focal length in pixels of a camera ``width`` pixels wide with a horizontal field
    of view of ``hfov_deg``: :math:`f = (W / 2) / \tan(\mathrm{HFOV} / 2)`."""
    h = check_real(hfov_deg, "hfov_deg", 0.0, 180.0, low_inclusive=False, high_inclusive=False)
    return 0.5 * _positive(width, "width") / np.tan(np.radians(h) / 2.0)


@dataclass(frozen=True)
class ActiveStereoSensor:
    """An active (or passive) stereo depth camera.

    Attributes
    ----------
    baseline : float
        Metres between the two cameras.
    width : int
        Pixels across the depth image.
    hfov_deg : float
        Horizontal field of view of the depth image.
    subpixel : float
        RMS subpixel accuracy of the matching, in pixels.
    max_disparity : int
        Largest disparity searched (sets the nearest measurable depth).
    """

    baseline: float
    width: int
    hfov_deg: float
    subpixel: float = 0.08
    max_disparity: int = 126

    def __post_init__(self) -> None:
        object.__setattr__(self, "baseline", _positive(self.baseline, "baseline"))
        object.__setattr__(self, "width", check_int(self.width, "width", 1))
        object.__setattr__(
            self,
            "hfov_deg",
            check_real(self.hfov_deg, "hfov_deg", 0.0, 180.0, low_inclusive=False,
                       high_inclusive=False),
        )  # fmt: skip
        object.__setattr__(self, "subpixel", check_real(self.subpixel, "subpixel", 0.0))
        object.__setattr__(self, "max_disparity", check_int(self.max_disparity, "max_disparity", 1))

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        return focal_from_fov(self.width, self.hfov_deg)

    def depth_rms_error(self, depth: npt.ArrayLike) -> np.ndarray:
        r"""Intel's depth RMS error :math:`z^2 s / (f B)` (m) at ``depth`` metres."""
        z = check_numeric(depth, "depth")
        return z * z * self.subpixel / (self.focal * self.baseline)

    @property
    def min_depth(self) -> float:
        """Nearest depth in range: :math:`f B / d_{max}` (m)."""
        return self.focal * self.baseline / self.max_disparity

    def disparity(self, depth: npt.ArrayLike) -> np.ndarray:
        """Disparity :math:`f B / z` (px) of a point at ``depth`` metres."""
        with np.errstate(divide="ignore"):
            return self.focal * self.baseline / check_numeric(depth, "depth")


# Intel RealSense D435 at its recommended 848 x 480 depth mode: 50 mm baseline, 87 deg
# horizontal field of view (datasheet), 0.08 px subpixel (Intel's tuning paper's
# typical value) and 126 disparities (its default search range at this resolution).
D435 = ActiveStereoSensor(
    baseline=0.050, width=848, hfov_deg=87.0, subpixel=0.08, max_disparity=126
)
