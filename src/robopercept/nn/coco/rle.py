r"""COCO run-length encoded masks: the format of ``pycocotools.mask``, in NumPy.

A COCO mask of ``h x w`` pixels is read in column-major order (down the first column,
then the next: pixel :math:`(y, x)` is element :math:`x h + y`) and stored as the
lengths of its alternating runs, starting with a run of zeros (of length 0 when the
first pixel is set):

.. math:: \texttt{counts} = [z_0, o_0, z_1, o_1, \ldots], \qquad
          \sum \texttt{counts} = h w .

An *uncompressed* RLE is ``{"size": [h, w], "counts": [int, ...]}``; a *compressed* one
(COCO's JSON files and results) has ``counts`` as an ASCII string: each count
:math:`c_i` (for :math:`i > 2`, the difference :math:`c_i - c_{i-2}`, which is small)
is written as a signed little-endian number in groups of 5 bits, each group a
character :math:`48 + g`, bit 5 (``0x20``) set on every group but the last, bit 4
(``0x10``) of the last group being the sign.

Functions (each named after its ``pycocotools.mask`` counterpart, and tested equal to
it on random masks, empty and full ones included):

* :func:`rle_encode` (``encode``), :func:`rle_decode` (``decode``);
* :func:`rle_area` (``area``), :func:`rle_to_bbox` (``toBbox``);
* :func:`rle_iou` (``iou`` on masks, with COCO's crowd rule);
* :func:`rle_merge` (``merge``: union or intersection);
* :func:`polygon_to_rle` (``frPyObjects`` on a polygon, COCO's rasterization) and
  :func:`annotation_to_rle` (a ``segmentation`` field of any of COCO's three forms).

NumPy only (no torch).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_bool, check_int, plain_repr
from robopercept.errors import InputError

__all__ = [
    "annotation_to_rle",
    "polygon_to_rle",
    "rle_area",
    "rle_counts",
    "rle_decode",
    "rle_encode",
    "rle_from_counts",
    "rle_iou",
    "rle_merge",
    "rle_to_bbox",
]

#: pixels of the largest mask accepted (h w), as pycocotools' 32-bit run lengths allow
MAX_PIXELS = 2**32 - 1
#: 5-bit groups of the longest number in a compressed counts string (2^32 takes 7)
_MAX_GROUPS = 13
#: coordinates of a polygon beyond this many pixels are refused (COCO's rasterization
#: works on int64 at 5x: far below its range; areas lose precision beyond it)
MAX_COORDINATE = 1e15
#: points of the longest polygon outline traced (on COCO's 5x grid): 4 M px of outline,
#: 10 times the border of a 100k x 100k image; it bounds the time (about 1 s), while the
#: memory is bounded by tracing each edge in pieces
MAX_TRACE = 2 * 10**7


def _runs(flat: np.ndarray) -> np.ndarray:
    """Run lengths of a flat 0/1 array, starting with the zeros (COCO's convention)."""
    n = flat.size
    if n == 0:
        return np.zeros(1, np.int64)
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate(([0], edges, [n]))
    runs = np.diff(bounds)
    if flat[0]:
        runs = np.concatenate(([0], runs))
    return runs.astype(np.int64)


def _compress(counts: np.ndarray) -> str:
    """COCO's string form of run lengths (``rleToString``)."""
    out = []
    c = [int(v) for v in counts]
    for i, x in enumerate(c):
        if i > 2:
            x -= c[i - 2]
        more = True
        while more:
            g = x & 0x1F
            x >>= 5
            more = x != -1 if g & 0x10 else x != 0
            if more:
                g |= 0x20
            out.append(chr(g + 48))
    return "".join(out)


def _decompress(s: str, where: str) -> np.ndarray:
    """Run lengths of COCO's string form (``rleFrString``), vectorized.

    Each number is a little-endian run of 5-bit groups (``c - 48``; bit 0x20: another
    group follows; bit 0x10 of the last group: negative, sign-extended), and from the
    third number on each is a difference to the number two before it: the runs at odd
    places are the cumulative sum of the odd numbers, those at even places from the
    third on of the even numbers. A string with anything unusual (a character outside
    ``'0'``..``'o'``, a number cut short or of 12 groups or more, a run beyond
    :data:`MAX_PIXELS`) goes to :func:`_decompress_loop`, which names the first
    problem exactly as a character-by-character reading meets it.
    """
    codes = np.frombuffer(s.encode("utf-32-le"), "<u4").astype(np.int64) - 48
    if codes.size == 0:
        return np.zeros(0, np.int64)
    if codes.min() < 0 or codes.max() >= 64 or codes[-1] & 0x20:
        return _decompress_loop(s, where)
    ends = np.flatnonzero((codes & 0x20) == 0)
    starts = np.concatenate(([0], ends[:-1] + 1))
    lengths = ends - starts + 1
    if lengths.max() >= 12:  # 5 x 12 bits and more do not fit int64 after the shift
        return _decompress_loop(s, where)
    place = np.arange(codes.size) - np.repeat(starts, lengths)
    x = np.add.reduceat((codes & 0x1F) << (5 * place), starts)
    x -= np.where(codes[ends] & 0x10, np.left_shift(1, 5 * lengths), 0)
    counts = x.copy()
    counts[1::2] = np.cumsum(x[1::2])
    counts[2::2] = np.cumsum(x[2::2])
    if np.abs(counts).max() > MAX_PIXELS:
        return _decompress_loop(s, where)
    return counts


def _decompress_loop(s: str, where: str) -> np.ndarray:
    """:func:`_decompress` character by character (``rleFrString`` as written), with
    an :class:`InputError` for the first problem met."""
    counts: list[int] = []
    p, n = 0, len(s)
    while p < n:
        x, k, more = 0, 0, True
        while more:
            if p >= n:
                raise InputError(f"{where}: the counts string ends inside a number")
            c = ord(s[p]) - 48
            if not 0 <= c < 64:
                raise InputError(
                    f"{where}: {s[p]!r} is not a character of COCO's compressed counts "
                    "(codes 48 to 111)"
                )
            x |= (c & 0x1F) << (5 * k)
            more = bool(c & 0x20)
            p += 1
            k += 1
            if more and k >= _MAX_GROUPS:
                raise InputError(
                    f"{where}: a number of the counts string runs over {_MAX_GROUPS} "
                    "characters: no mask of at most 2^32 - 1 pixels has such a run"
                )
            if not more and c & 0x10:
                x |= -1 << (5 * k)
        if len(counts) > 2:
            x += counts[-2]
        if abs(x) > MAX_PIXELS:
            raise InputError(
                f"{where}: a run of {x} pixels in the counts string; a mask has at most "
                "2^32 - 1 pixels"
            )
        counts.append(x)
    return np.asarray(counts, np.int64)


def _size(value: Any, where: str) -> tuple[int, int]:
    """``[h, w]`` (a list, tuple or 1-D array of two integers >= 0) as ints;
    :class:`InputError` for anything else (a single number, None, a 0-d array)."""
    if isinstance(value, np.ndarray):
        value = value.tolist() if value.ndim == 1 else None
    if (
        not isinstance(value, (list, tuple))
        or len(value) != 2
        or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in value)
        or min(value) < 0
    ):
        raise InputError(f"{where}: size must be [height, width], two integers >= 0")
    h, w = int(value[0]), int(value[1])
    if h * w > MAX_PIXELS:
        raise InputError(f"{where}: a {h} x {w} mask has more than 2^32 - 1 pixels")
    return h, w


def _rle_list(value: Any, name: str) -> list[Any]:
    """``value`` as a list of RLE dicts (each checked where it is used)."""
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
        raise InputError(
            f"{name} must be a list of COCO RLE dicts ({{'size': [h, w], 'counts': ...}}); "
            f"got {plain_repr(value)}"
        )
    return list(value)


def rle_counts(rle: Mapping[str, Any], name: str = "rle") -> tuple[tuple[int, int], np.ndarray]:
    """The ``(h, w)`` and the run lengths of an RLE, compressed or not, checked.

    Parameters
    ----------
    rle : mapping
        ``{"size": [h, w], "counts": str | bytes | list of int}``.
    name : str
        What to call it in errors.

    Returns
    -------
    (h, w), counts : tuple of int, ndarray of int64

    Raises
    ------
    InputError
        A missing key, a bad size, negative runs, or runs that do not add up to
        :math:`h w`.
    """
    if not isinstance(rle, Mapping) or "size" not in rle or "counts" not in rle:
        raise InputError(
            f"{name} must be a COCO RLE, a dict with 'size' ([h, w]) and 'counts'; got "
            f"{plain_repr(rle)}"
        )
    h, w = _size(rle["size"], name)
    counts = rle["counts"]
    if isinstance(counts, bytes):
        counts = counts.decode("ascii", errors="replace")
    if isinstance(counts, str):
        runs = _decompress(counts, name)
    else:
        try:
            runs = np.asarray(counts)
        except (TypeError, ValueError):
            runs = np.asarray([None])
        if runs.ndim != 1 or (runs.size and runs.dtype.kind not in "iu"):
            raise InputError(
                f"{name}['counts'] must be COCO's compressed string or a list of integers"
            )
        runs = runs.astype(np.int64)
    if runs.size and (int(runs.min()) < 0 or int(runs.max()) > h * w):  # the sum could wrap
        bad = int(runs.min()) if int(runs.min()) < 0 else int(runs.max())
        raise InputError(
            f"{name}: the runs must be >= 0 and add up to h * w = {h * w} pixels; one is {bad}"
        )
    if int(runs.sum()) != h * w:
        raise InputError(
            f"{name}: the runs must be >= 0 and add up to h * w = {h * w} pixels; they add "
            f"up to {int(runs.sum())}"
        )
    return (h, w), runs


def rle_from_counts(counts: npt.ArrayLike, size: tuple[int, int]) -> dict[str, Any]:
    """The compressed RLE of uncompressed run lengths (``frPyObjects`` on an
    uncompressed RLE).

    Parameters
    ----------
    counts : array-like of int
        Alternating run lengths, zeros first, adding up to :math:`h w`.
    size : (int, int)
        ``(h, w)``.

    Returns
    -------
    dict
        ``{"size": [h, w], "counts": str}``.

    Raises
    ------
    InputError
        ``size`` not two integers >= 0 (a single number, None), ``counts`` not
        integers, negative runs, or runs that do not add up to :math:`h w`.

    Examples
    --------
    >>> rle_from_counts([1, 3], (2, 2))
    {'size': [2, 2], 'counts': '13'}
    >>> rle_from_counts([4], 4)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: counts: size must be [height, width], two integers >= 0
    """
    (h, w), runs = rle_counts({"size": size, "counts": counts}, "counts")
    return {"size": [h, w], "counts": _compress(runs)}


def rle_encode(mask: npt.ArrayLike) -> dict[str, Any] | list[dict[str, Any]]:
    """Run-length encode a binary mask (``pycocotools.mask.encode``).

    Parameters
    ----------
    mask : array-like, shape (h, w) or (h, w, n)
        Nonzero pixels are set (pycocotools requires uint8; any numeric or boolean
        dtype is taken here).

    Returns
    -------
    dict or list of dict
        ``{"size": [h, w], "counts": str}`` (pycocotools gives ``bytes``; a ``str``
        goes into JSON as it is); a list of ``n`` of them for a ``(h, w, n)`` stack.

    Examples
    --------
    >>> m = np.array([[0, 1], [1, 1]], np.uint8)   # column-major: 0, 1, 1, 1
    >>> rle_encode(m)   # runs 1, 3
    {'size': [2, 2], 'counts': '13'}
    >>> rle_encode(1 - m)   # 1, 0, 0, 0: runs 0, 1, 3
    {'size': [2, 2], 'counts': '013'}
    """
    m = np.asarray(mask)
    if m.ndim not in (2, 3) or m.dtype.kind not in "biuf":
        raise InputError(
            f"mask must be a numeric (h, w) or (h, w, n) array; got {plain_repr(mask)}"
        )
    if m.dtype.kind == "f" and not np.isfinite(m).all():
        raise InputError("mask has NaN or infinite values")
    h, w = m.shape[:2]
    _size([h, w], "mask")
    if m.ndim == 3:
        return [_encode2(m[:, :, i], h, w) for i in range(m.shape[2])]
    return _encode2(m, h, w)


def _encode2(m: np.ndarray, h: int, w: int) -> dict[str, Any]:
    flat = (m != 0).ravel(order="F")
    return {"size": [h, w], "counts": _compress(_runs(flat))}


def rle_decode(rle: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> np.ndarray:
    """The binary mask of an RLE (``pycocotools.mask.decode``).

    Parameters
    ----------
    rle : dict or list of dict
        Compressed or uncompressed.

    Returns
    -------
    ndarray of uint8, shape (h, w), or (h, w, n) for a list
    """
    if isinstance(rle, Mapping):
        return _decode1(rle, "rle")
    items = _rle_list(rle, "rle")
    if not items:
        raise InputError("rle is an empty list: no mask to decode")
    masks = [_decode1(r, f"rle[{i}]") for i, r in enumerate(items)]
    if len({m.shape for m in masks}) != 1:
        raise InputError("the RLEs of a list must all have the same size to be stacked")
    return np.stack(masks, axis=2)


def _decode1(rle: Mapping[str, Any], name: str) -> np.ndarray:
    (h, w), runs = rle_counts(rle, name)
    values = np.arange(runs.size, dtype=np.uint8) & 1
    flat = np.repeat(values, runs)
    return np.ascontiguousarray(flat.reshape(w, h).T)


def rle_area(rle: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> int | np.ndarray:
    """Set pixels of an RLE, the sum of its odd runs (``pycocotools.mask.area``).

    Returns
    -------
    int, or ndarray of int64 for a list
    """
    if isinstance(rle, Mapping):
        return int(rle_counts(rle)[1][1::2].sum())
    items = _rle_list(rle, "rle")
    return np.asarray(
        [int(rle_counts(r, f"rle[{i}]")[1][1::2].sum()) for i, r in enumerate(items)], np.int64
    )


def rle_to_bbox(rle: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> np.ndarray:
    """The tight ``[x, y, w, h]`` box of an RLE's set pixels (``toBbox``), ``[0, 0, 0,
    0]`` for an empty mask.

    A run that spans columns covers every row between them in the box (pycocotools'
    rule, exact since the run passes through whole columns). Pixels are unit squares:
    a single pixel at :math:`(y, x)` gives ``[x, y, 1, 1]``.

    Returns
    -------
    ndarray of float64, shape (4,) or (n, 4) for a list
    """
    if isinstance(rle, Mapping):
        return _bbox1(*rle_counts(rle))
    items = _rle_list(rle, "rle")
    return np.asarray(
        [_bbox1(*rle_counts(r, f"rle[{i}]")) for i, r in enumerate(items)], np.float64
    ).reshape(-1, 4)


def _bbox1(size: tuple[int, int], runs: np.ndarray) -> np.ndarray:
    h, _ = size
    m = (runs.size // 2) * 2
    if m == 0:
        return np.zeros(4)
    cc = np.cumsum(runs[:m])
    j = np.arange(m)
    t = cc - (j % 2)  # first pixel of each run of ones, then its last pixel
    y, x = t % h, t // h
    ys, ye = int(y.min()), int(y.max())
    if (x[0::2] < x[1::2]).any():  # a run through several columns
        ys, ye = 0, h - 1
    return np.array([x.min(), ys, x.max() - x.min() + 1, ye - ys + 1], np.float64)


def _flat_masks(rles: Sequence[Mapping[str, Any]], name: str) -> tuple[tuple[int, int], list]:
    out, sizes = [], set()
    for i, r in enumerate(rles):
        size, runs = rle_counts(r, f"{name}[{i}]")
        sizes.add(size)
        out.append(np.repeat(np.arange(runs.size, dtype=np.uint8) & 1, runs).astype(bool))
    if len(sizes) > 1:
        raise InputError(f"the masks of {name} differ in size: {sorted(sizes)}")
    return (sizes.pop() if sizes else (0, 0)), out


def rle_iou(
    dt: Sequence[Mapping[str, Any]],
    gt: Sequence[Mapping[str, Any]],
    iscrowd: Sequence[bool] | npt.ArrayLike | None = None,
) -> np.ndarray:
    r"""Mask IoU of every detection with every ground truth (``pycocotools.mask.iou``
    on RLEs).

    .. math:: \mathrm{IoU}(d, g) = \frac{|d \cap g|}{|d \cup g|}, \quad
              \text{or } \frac{|d \cap g|}{|d|} \text{ when } g \text{ is a crowd region},

    and 0 where :math:`d \cap g` is empty.

    Parameters
    ----------
    dt, gt : sequences of RLE dicts
        All of one size.
    iscrowd : sequence of bool, optional
        One per ground truth (all False when omitted).

    Returns
    -------
    ndarray of float64, shape (len(dt), len(gt))

    Raises
    ------
    InputError
        Masks of different sizes (pycocotools returns -1 there), or ``iscrowd`` of the
        wrong length.
    """
    dt, gt = _rle_list(dt, "dt"), _rle_list(gt, "gt")
    try:
        crowd = np.zeros(len(gt), bool) if iscrowd is None else np.asarray(iscrowd)
    except (TypeError, ValueError):  # ragged lists
        crowd = np.zeros(0, object)
    if (
        crowd.shape != (len(gt),)
        or crowd.dtype.kind not in "biu"
        or not np.isin(crowd, (0, 1)).all()
    ):
        raise InputError(
            f"iscrowd must hold one 0/1 flag per ground truth ({len(gt)}); got "
            f"{plain_repr(iscrowd)}"
        )
    crowd = crowd.astype(bool)
    if not dt or not gt:
        return np.zeros((len(dt), len(gt)))
    sd, d = _flat_masks(dt, "dt")
    sg, g = _flat_masks(gt, "gt")
    if sd != sg:
        raise InputError(f"dt masks are {sd[0]} x {sd[1]} and gt masks {sg[0]} x {sg[1]}")
    dm = np.stack(d).astype(np.float64)
    gm = np.stack(g).astype(np.float64)
    inter = dm @ gm.T  # exact: counts below 2^53
    ad, ag = dm.sum(1), gm.sum(1)
    union = np.where(crowd[None, :], ad[:, None], ad[:, None] + ag[None, :] - inter)
    return np.where(inter > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def rle_merge(rles: Sequence[Mapping[str, Any]], intersect: bool = False) -> dict[str, Any]:
    """Union (or intersection) of RLEs of one size (``pycocotools.mask.merge``).

    Returns
    -------
    dict
        The compressed RLE.
    """
    intersect = check_bool(intersect, "intersect")
    rles = _rle_list(rles, "rles")
    if not rles:
        raise InputError("rle_merge needs at least one RLE")
    (h, w), flats = _flat_masks(rles, "rles")
    out = flats[0].copy()
    for f in flats[1:]:
        out = out & f if intersect else out | f
    return {"size": [h, w], "counts": _compress(_runs(out))}


def polygon_to_rle(polygon: npt.ArrayLike, height: int, width: int) -> dict[str, Any]:
    r"""Rasterize a polygon ``[x0, y0, x1, y1, ...]`` into a compressed RLE, as COCO
    does (``pycocotools.mask.frPyObjects([polygon], h, w)[0]``).

    COCO's rule: the vertices are scaled by 5 and rounded, each edge is traced on that
    grid (a point per step along its longer axis), and wherever the trace crosses a
    pixel column :math:`x` (at :math:`5 (x + \tfrac12)` on the fine grid) its row
    :math:`y_d = (v + \tfrac12)/5 - \tfrac12`, clamped to :math:`[0, h]`, is rounded up
    to mark where a run starts or ends in that column. The crossings sorted in
    column-major order are the run boundaries. A pixel is set when its centre is
    inside the polygon, up to the rounding on the fine grid.

    Parameters
    ----------
    polygon : array-like of float, shape (2 k,), k >= 3
        Image coordinates, the pixel :math:`(y, x)` covering
        :math:`[x, x + 1) \times [y, y + 1)`.
    height, width : int

    Returns
    -------
    dict
        ``{"size": [height, width], "counts": str}``.

    Raises
    ------
    InputError
        An odd number of coordinates, fewer than 3 points, or non-finite values.
    """
    h = check_int(height, "height", 0)
    w = check_int(width, "width", 0)
    _size([h, w], "polygon")
    xy = np.asarray(polygon, dtype=np.float64).ravel() if _numeric(polygon) else None
    if xy is None or xy.size % 2 or xy.size < 6 or not np.isfinite(xy).all():
        raise InputError(
            "a polygon must be [x0, y0, x1, y1, ...] with at least 3 points (6 finite "
            f"numbers); got {plain_repr(polygon)}"
        )
    if np.abs(xy).max() > MAX_COORDINATE:
        raise InputError(
            f"a polygon's coordinates must stay within {MAX_COORDINATE:.0e} pixels; got "
            f"{np.abs(xy).max():.3g} in {plain_repr(polygon)}: clip it to the {h} x {w} image"
        )
    # the outline is traced at 5x: refuse one whose trace would take seconds
    fine = np.rint(5.0 * xy)
    steps = np.maximum(
        np.abs(np.diff(fine[0::2], append=fine[0])), np.abs(np.diff(fine[1::2], append=fine[1]))
    )
    if steps.sum() > MAX_TRACE:
        raise InputError(
            f"the polygon's outline is {steps.sum() / 5:.3g} px long, over "
            f"{MAX_TRACE // 5} px: its points lie far outside the {h} x {w} image (clip "
            "them to it first)"
        )
    return {"size": [h, w], "counts": _compress(_polygon_runs(xy, h, w))}


def _numeric(value: Any) -> bool:
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        return False
    return a.dtype.kind in "iuf"


def _polygon_runs(xy: np.ndarray, h: int, w: int) -> np.ndarray:
    scale = 5.0
    k = xy.size // 2
    # round half up as C's (int)(v + .5), truncating toward zero
    x = np.trunc(scale * xy[0::2] + 0.5).astype(np.int64)
    y = np.trunc(scale * xy[1::2] + 0.5).astype(np.int64)
    x, y = np.append(x, x[0]), np.append(y, y[0])
    # Each edge is traced from vertex j to vertex j + 1, so consecutive edges meet in
    # one repeated point and every column crossing lies inside one edge: the edges are
    # traced one at a time, in pieces of _TRACE_PIECE points, keeping only the crossings
    # (at most one per image column per edge). Memory stays O(k w) however far outside
    # the image the points lie.
    found = [
        _edge_crossings(int(x[j]), int(x[j + 1]), int(y[j]), int(y[j + 1]), h, w) for j in range(k)
    ]
    a = np.sort(np.concatenate([*found, np.array([h * w], np.int64)]))
    a = np.diff(a, prepend=0)
    # zero-length runs are dropped by joining the runs around them
    runs: list[int] = [int(a[0])]
    i = 1
    while i < a.size:
        if a[i] > 0:
            runs.append(int(a[i]))
            i += 1
        else:
            i += 1
            if i < a.size:
                runs[-1] += int(a[i])
                i += 1
    return np.asarray(runs, np.int64)


#: points of an edge's trace held at once by _edge_crossings
_TRACE_PIECE = 1 << 16


def _edge_crossings(xs: int, xe: int, ys: int, ye: int, h: int, w: int) -> np.ndarray:
    """Run boundaries ``column h + row`` where one traced edge crosses a pixel column."""
    scale = 5.0
    dx, dy = abs(xe - xs), abs(ys - ye)
    flip = (dx >= dy and xs > xe) or (dx < dy and ys > ye)
    if flip:
        xs, xe, ys, ye = xe, xs, ye, ys
    n = max(dx, dy)
    out = []
    for lo in range(0, n, _TRACE_PIECE):
        # points lo .. hi of the trace, the first one shared with the previous piece
        t = np.arange(lo, min(lo + _TRACE_PIECE, n) + 1)
        t = n - t if flip else t
        if dx >= dy:
            s = (ye - ys) / dx if dx else 0.0
            u = t + xs
            v = np.trunc(ys + s * t + 0.5).astype(np.int64)
        else:
            s = (xe - xs) / dy
            v = t + ys
            u = np.trunc(xs + s * t + 0.5).astype(np.int64)
        # where the trace moves to another fine column: the pixel column it crosses
        c = np.flatnonzero(u[1:] != u[:-1]) + 1
        xd = np.where(u[c] < u[c - 1], u[c], u[c] - 1).astype(np.float64)
        xd = (xd + 0.5) / scale - 0.5
        keep = (np.floor(xd) == xd) & (xd >= 0) & (xd <= w - 1)
        c, xd = c[keep], xd[keep]
        yd = np.where(v[c] < v[c - 1], v[c], v[c - 1]).astype(np.float64)
        yd = (yd + 0.5) / scale - 0.5
        yd = np.ceil(np.clip(yd, 0, h))
        out.append((xd * h + yd).astype(np.int64))
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def annotation_to_rle(segmentation: Any, height: int, width: int) -> dict[str, Any]:
    """The compressed RLE of a COCO annotation's ``segmentation`` (``annToRLE``).

    Parameters
    ----------
    segmentation : list of polygons, uncompressed RLE or compressed RLE
        A list of polygons is the union of their masks (``merge`` of ``frPyObjects``).
    height, width : int
        The image's size, used by polygons (an RLE carries its own and must match).

    Returns
    -------
    dict
        ``{"size": [height, width], "counts": str}``.
    """
    h = check_int(height, "height", 0)
    w = check_int(width, "width", 0)
    if isinstance(segmentation, Mapping):
        (rh, rw), runs = rle_counts(segmentation, "segmentation")
        if (rh, rw) != (h, w):
            raise InputError(f"the segmentation's RLE is {rh} x {rw} but the image is {h} x {w}")
        return {"size": [h, w], "counts": _compress(runs)}
    if not isinstance(segmentation, (list, tuple)) or not segmentation:
        raise InputError(
            "segmentation must be a list of polygons [[x0, y0, ...], ...] or an RLE dict; "
            f"got {plain_repr(segmentation)}"
        )
    polys = [polygon_to_rle(p, h, w) for p in segmentation]
    return polys[0] if len(polys) == 1 else rle_merge(polys)
