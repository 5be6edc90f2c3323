r"""Optical-flow ground truth: Middlebury ``.flo`` files and the endpoint error.

**The .flo format** (Baker et al., "A Database and Evaluation Methodology for Optical
Flow", IJCV 2011; the ``flowIO.cpp`` of the Middlebury flow page, which
``cv2.readOpticalFlow`` / ``cv2.writeOpticalFlow`` follow), all little-endian:

==========  ==========  ====================================================
bytes       type        content
==========  ==========  ====================================================
0-3         float32     the tag 202021.25, whose bytes spell ``PIEH``
4-7         int32       width :math:`W`
8-11        int32       height :math:`H`
12-         float32     :math:`H \times W \times 2` values, row-major, ``(u, v)``
                        interleaved per pixel
==========  ==========  ====================================================

so a file is exactly :math:`12 + 8 W H` bytes. A component of magnitude at least
:math:`10^9` (or NaN) marks a pixel whose flow is unknown (Middlebury's
``UNKNOWN_FLOW_THRESH``; RubberWhale stores :math:`1.67 \cdot 10^9` there, and
``flowIO.cpp`` writes :math:`10^{10}`).

**Endpoint error** (EPE) of an estimate :math:`(u, v)` against the truth
:math:`(u_t, v_t)`:

.. math::

    \mathrm{EPE} = \sqrt{(u - u_t)^2 + (v - v_t)^2},

averaged over the pixels (or points) that have both an estimate and a known truth;
the share of those with :math:`\mathrm{EPE} > 1` and :math:`> 3` pixels is
Middlebury's robustness statistic R1.0 / R3.0 (KITTI's outlier rate uses 3 px).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_extension, check_file, check_numeric
from robopercept.errors import DegenerateError, FileFormatError, InputError

__all__ = [
    "FLO_TAG",
    "UNKNOWN_FLOW",
    "UNKNOWN_FLOW_THRESHOLD",
    "EndpointError",
    "endpoint_error",
    "known_flow",
    "read_flo",
    "write_flo",
]

#: the first four bytes of a .flo file as a float32 (its bytes spell ``PIEH``)
FLO_TAG = 202021.25
#: a flow component at least this large (in magnitude) is unknown (Middlebury)
UNKNOWN_FLOW_THRESHOLD = 1e9
#: what :func:`write_flo` writes for an unknown (NaN) component, as ``flowIO.cpp``
UNKNOWN_FLOW = 1e10
#: the largest side :func:`read_flo` accepts (``flowIO.cpp`` refuses 100000 and more)
MAX_FLO_SIDE = 99999


def read_flo(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a Middlebury ``.flo`` optical-flow file (see the module docstring).

    Parameters
    ----------
    path : path-like
        The file (any extension: the tag identifies the format).

    Returns
    -------
    (H, W, 2) float32 ndarray
        ``(u, v)`` per pixel, exactly as stored (as ``cv2.readOpticalFlow``): unknown
        pixels keep their huge values; :func:`known_flow` finds them.

    Raises
    ------
    FileFormatError
        No such file, a folder, a wrong tag, a width or height outside 1..99999, or a
        file whose size is not ``12 + 8 W H`` bytes (truncated or with trailing data).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "f.flo"
    >>> _ = write_flo(path, np.dstack([np.full((2, 3), 1.5), np.zeros((2, 3))]))
    >>> flow = read_flo(path)
    >>> flow.shape, flow.dtype, flow[0, 0].tolist()
    ((2, 3, 2), dtype('float32'), [1.5, 0.0])
    """
    p = check_file(path, "a Middlebury .flo file")
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(12)
        if len(head) < 12:
            raise FileFormatError(
                f"{p}: {len(head)} bytes, too short for a .flo header (12 bytes: the tag "
                "PIEH, width, height); the file is truncated or not a .flo file"
            )
        tag = float(np.frombuffer(head[:4], "<f4")[0])
        if tag != FLO_TAG:
            raise FileFormatError(
                f"{p}: not a Middlebury .flo file: the first 4 bytes are {head[:4]!r}, "
                f"expected b'PIEH' (the float {FLO_TAG})"
            )
        w, h = (int(v) for v in np.frombuffer(head[4:12], "<i4"))
        if not (1 <= w <= MAX_FLO_SIDE and 1 <= h <= MAX_FLO_SIDE):
            raise FileFormatError(
                f"{p}: the header says {w}x{h} pixels; a .flo image has a width and height "
                f"in 1..{MAX_FLO_SIDE} (a corrupt header)"
            )
        expected = 12 + 8 * w * h
        if size != expected:
            raise FileFormatError(
                f"{p}: a {w}x{h} .flo file has {expected} bytes (12 + 8 x width x height); "
                f"this one has {size}: it is {'truncated' if size < expected else 'too long'}"
            )
        data = np.frombuffer(fh.read(8 * w * h), "<f4")
    if data.size != 2 * w * h:  # (the file changed while it was read)
        raise FileFormatError(f"{p}: the flow values end early ({data.size} of {2 * w * h})")
    return data.reshape(h, w, 2).astype(np.float32)


def write_flo(path: str | os.PathLike[str], flow: npt.ArrayLike) -> Path:
    """Write a flow field as a Middlebury ``.flo`` file (``cv2.writeOpticalFlow``).

    Parameters
    ----------
    path : path-like
        Output file; its extension must be ``.flo``. Written atomically.
    flow : (H, W, 2) array_like
        ``(u, v)`` per pixel, stored as float32; NaN components are written as
        :data:`UNKNOWN_FLOW` (:math:`10^{10}`, unknown).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InputError
        Not ``(H, W, 2)`` real numbers, a side over 99999, or another extension.
    WriteError
        The file could not be written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "f.flo"
    >>> write_flo(path, np.zeros((4, 5, 2))).stat().st_size  # 12 + 8 * 4 * 5
    172
    """
    from robopercept.fileio import atomic_write

    p = check_extension(path, (".flo",), "a Middlebury flow file")
    f = check_numeric(flow, "flow")
    if f.ndim != 3 or f.shape[2] != 2 or f.shape[0] < 1 or f.shape[1] < 1:
        raise InputError(f"flow must be (H, W, 2) (u, v per pixel); got shape {f.shape}")
    h, w = f.shape[:2]
    if max(h, w) > MAX_FLO_SIDE:
        raise InputError(f"flow's width and height must be at most {MAX_FLO_SIDE}; got {w}x{h}")
    with np.errstate(over="ignore", invalid="ignore"):
        values = np.where(np.isnan(f), UNKNOWN_FLOW, f).astype("<f4")
    head = np.array([FLO_TAG], "<f4").tobytes() + np.array([w, h], "<i4").tobytes()
    return atomic_write(p, head + np.ascontiguousarray(values).tobytes())


def known_flow(flow: npt.ArrayLike) -> np.ndarray:
    """Where a flow field (``(..., 2)``) is known: both components finite and of
    magnitude below :data:`UNKNOWN_FLOW_THRESHOLD` (:math:`10^9`, Middlebury's rule).

    Examples
    --------
    >>> known_flow(np.array([[0.5, -2.0], [1.7e9, 1.7e9], [np.nan, 0.0]])).tolist()
    [True, False, False]
    """
    f = check_numeric(flow, "flow")
    if f.ndim < 1 or f.shape[-1] != 2:
        raise InputError(f"flow must be (..., 2) (u, v); got shape {f.shape}")
    with np.errstate(invalid="ignore"):
        return (np.abs(f) < UNKNOWN_FLOW_THRESHOLD).all(axis=-1)


@dataclass(frozen=True)
class EndpointError:
    """What :func:`endpoint_error` measured.

    Attributes
    ----------
    mean, median : float
        Endpoint error in pixels over the evaluated vectors.
    over_1, over_3 : float
        Fractions (0-1) of the evaluated vectors with an error above 1 and 3 pixels.
    evaluated : int
        Vectors with an estimate and a known truth.
    unknown_truth : int
        Vectors skipped because the truth there is unknown.
    no_estimate : int
        Vectors with a known truth but no estimate (NaN: a failed track).
    errors : ndarray
        The error of every vector, the shape of the estimate without its last axis;
        NaN where not evaluated.
    """

    mean: float
    median: float
    over_1: float
    over_3: float
    evaluated: int
    unknown_truth: int
    no_estimate: int
    errors: np.ndarray = field(repr=False)

    def to_dict(self) -> dict[str, float | int]:
        """The scalar fields (fractions as given), for JSON."""
        return {
            "epe_mean": self.mean,
            "epe_median": self.median,
            "over_1": self.over_1,
            "over_3": self.over_3,
            "evaluated": self.evaluated,
            "unknown_truth": self.unknown_truth,
            "no_estimate": self.no_estimate,
        }


def endpoint_error(
    flow: npt.ArrayLike, truth: npt.ArrayLike, points: npt.ArrayLike | None = None
) -> EndpointError:
    r"""Endpoint error of a dense or sparse flow estimate against ground truth.

    :math:`\mathrm{EPE} = \lVert (u, v) - (u_t, v_t) \rVert_2` per vector (the module
    docstring), summarized over the vectors that have an estimate (finite) and a known
    truth (:func:`known_flow`: components below :math:`10^9`, as Middlebury).

    Parameters
    ----------
    flow : (H, W, 2) or (N, 2) array_like
        A dense field of the size of ``truth`` (without ``points``), or one vector per
        point (with ``points``); NaN where there is no estimate.
    truth : (H, W, 2) array_like
        The ground truth, e.g. from :func:`read_flo`.
    points : (N, 2) array_like, optional
        Positions ``(x, y)`` of sparse vectors (the start of each track); each is
        compared with the truth at its nearest pixel (``round``). Points off the
        truth's pixels count as unknown truth.

    Returns
    -------
    EndpointError

    Raises
    ------
    InputError
        Shapes that do not fit (the message says which).
    DegenerateError
        No vector has both an estimate and a known truth.

    Examples
    --------
    A 1 x 2 field: one pixel off by (3, 4) (EPE 5), one exact; a third, unknown truth.

    >>> truth = np.array([[[1.0, 0.0], [0.0, 0.0], [2e9, 2e9]]])
    >>> flow = np.array([[[4.0, 4.0], [0.0, 0.0], [1.0, 1.0]]])
    >>> e = endpoint_error(flow, truth)
    >>> e.mean, e.over_1, e.over_3, e.evaluated, e.unknown_truth
    (2.5, 0.5, 0.5, 2, 1)
    """
    t = check_numeric(truth, "truth")
    if t.ndim != 3 or t.shape[2] != 2:
        raise InputError(f"truth must be an (H, W, 2) flow field; got shape {t.shape}")
    f = check_numeric(flow, "flow").astype(np.float64)
    t = t.astype(np.float64)
    if points is None:
        if f.shape != t.shape:
            raise InputError(
                f"a dense flow must have the truth's shape {t.shape}; got {f.shape} (for "
                "vectors at points, pass points=(N, 2) positions)"
            )
        ref = t
        inside = np.ones(f.shape[:2], dtype=bool)
    else:
        p = check_numeric(points, "points")
        if p.size == 0:
            p = p.reshape(0, 2)
        if p.ndim != 2 or p.shape[1] != 2:
            raise InputError(f"points must be (N, 2) (x, y); got shape {p.shape}")
        if f.shape != p.shape:
            raise InputError(
                f"sparse flow must be one (u, v) per point, shape {p.shape}; got {f.shape}"
            )
        h, w = t.shape[:2]
        with np.errstate(invalid="ignore"):
            xi, yi = np.rint(p[:, 0]), np.rint(p[:, 1])
            inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        ref = np.full(p.shape, np.nan)
        ref[inside] = t[yi[inside].astype(np.int64), xi[inside].astype(np.int64)]
    known = inside & known_flow(ref)
    estimated = np.isfinite(f).all(axis=-1)
    use = known & estimated
    n = int(use.sum())
    if n == 0:
        raise DegenerateError(
            f"no vector has both an estimate and a known truth ({int(estimated.sum())} "
            f"estimated, {int(known.sum())} with known truth): check that the flow and "
            "the truth belong to the same pair of images"
        )
    errors = np.full(use.shape, np.nan)
    with np.errstate(over="ignore"):
        d = f[use] - ref[use]
        errors[use] = np.hypot(d[:, 0], d[:, 1])
    e = errors[use]
    return EndpointError(
        mean=float(e.mean()),
        median=float(np.median(e)),
        over_1=float((e > 1.0).mean()),
        over_3=float((e > 3.0).mean()),
        evaluated=n,
        unknown_truth=int((~known).sum()),
        no_estimate=int((known & ~estimated).sum()),
        errors=errors,
    )
