r"""Circle-grid detection: the centres of a symmetric or asymmetric grid of circles,
ordered as ``cv2.findCirclesGrid`` orders them.

:func:`find_circles_grid` works in three steps.

1. **Blobs at many thresholds** (the scheme of OpenCV's ``SimpleBlobDetector``, which
   ``findCirclesGrid`` uses): the image, with the circles dark (light circles: its
   negative), is thresholded at 10, 20, ..., 220; in each
   binary image the connected components of the circles' colour whose area lies in
   ``[min_area, max_area]`` and that look like filled ellipses are kept. A component's
   second moments give its covariance :math:`\Sigma`; a filled ellipse has area
   :math:`A = 4 \pi \sqrt{\det \Sigma}` and an inertia ratio
   :math:`\lambda_{min}/\lambda_{max}` equal to its squared axis ratio, so components
   with :math:`A / (4 \pi \sqrt{\det \Sigma})` outside :math:`[0.85, 1.15]` (holes,
   ragged shapes, merged blobs) or an inertia ratio below 0.1 are dropped. Centroids
   that agree across at least two thresholds (within half the blob radius) make one
   circle, at the mean of those centroids.
2. **Lattice growing.** Both grids are square lattices: the symmetric one along its rows
   and columns, the asymmetric one along its diagonals (each centre's four nearest
   neighbours sit at :math:`(\pm 1, \pm 1)` half-spacings). From a seed, the nearest
   neighbour and the nearest one not along it span the lattice; every further node is
   predicted by the parallelogram rule :math:`p_{a,b} \approx p_{a-1,b} + p_{a,b-1} -
   p_{a-1,b-1}` (or by extrapolation along a line) and filled by the nearest circle
   within 0.3 of the local spacing, so perspective is followed.
3. **Labelling.** Lattice coordinates :math:`(a, b)` become board coordinates. Under
   each of the lattice's eight symmetries, every placement (translation) of the
   ``w x h`` pattern whose nodes all hold a circle, with the board's x step turning
   clockwise into its y step in the image (a board seen from the front), is a
   candidate; the one candidate set of circles gives the order. A lattice may be larger
   than the pattern: stray blobs (screws, holes, a label) that happen to sit on the
   lattice's extension join it, and ``cv2.findCirclesGrid`` still finds the pattern
   there, so the pattern-sized window is taken, provided it is the only complete one
   and the lattice holds no complete ``(w + 1) x h`` or ``w x (h + 1)`` grid (then the
   board is larger than ``pattern_size`` says, and any window of it would be a guess).

**Order and board coordinates**, as OpenCV's calibration sample: row ``i`` of
``pattern_size[1]``, ``pattern_size[0]`` centres per row; the symmetric grid's centre
``(i, j)`` at ``(j s, i s)`` and the asymmetric grid's at ``((2 j + i mod 2) s / 2,
i s / 2)`` with ``s`` the distance between neighbouring centres in a row
(:func:`circles_grid_points`). An asymmetric grid with an odd number of rows has no
symmetry, so its order is fixed by the board; a symmetric grid, or an asymmetric one
with an even number of rows, looks the same turned by half a turn, and its first
centre is taken to be the one higher in the image.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from robopercept._checks import check_bool, check_choice, check_int, check_real
from robopercept.calibration._lattice import grow_lattice
from robopercept.calibration.chessboard import MAX_LENGTH, check_pattern_size
from robopercept.errors import InputError
from robopercept.imaging.blobs import label_components
from robopercept.imaging.color import rgb_to_gray

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

__all__ = ["CircleGridDetection", "circles_grid_points", "find_circles_grid"]

_THRESHOLDS = tuple(range(10, 221, 10))  # SimpleBlobDetector's defaults
_MIN_REPEAT = 2


@dataclass(frozen=True)
class CircleGridDetection:
    """Result of :func:`find_circles_grid`.

    It unpacks as the tuple of ``ok, centers = cv2.findCirclesGrid(gray, (4, 11),
    flags=cv2.CALIB_CB_ASYMMETRIC_GRID)``: ``ok, centers = find_circles_grid(gray,
    (4, 11))`` gives ``ok`` (bool) and, when found, ``centers`` as OpenCV's
    ``(w * h, 1, 2)`` float32 array, or ``None`` when not found, as OpenCV gives. The
    attributes stay the primary interface: :attr:`centers` there is (w * h, 2) float64
    and holds the partial lattice when not found.

    Attributes
    ----------
    found : bool
        Whether every circle of the pattern was found.
    centers : (w * h, 2) ndarray
        Ordered centres ``(x, y)`` when found, else the circles of the largest partial
        lattice (unordered, for drawing), possibly empty.
    pattern_size : (int, int)
    asymmetric : bool
    reason : str
        Why the grid was not found ("" when found).
    """

    found: bool
    centers: np.ndarray
    pattern_size: tuple[int, int]
    asymmetric: bool
    reason: str = ""

    @property
    def corners(self) -> np.ndarray:
        """The centres, under the name the chessboard detection uses (for code and
        drawing that take either)."""
        return self.centers

    def __iter__(self) -> Iterator[bool | np.ndarray | None]:
        """``ok, centers``, the order of ``cv2.findCirclesGrid``'s result."""
        centers = self.centers.astype(np.float32).reshape(-1, 1, 2) if self.found else None
        return iter((bool(self.found), centers))


def circles_grid_points(
    pattern_size: tuple[int, int], spacing: float = 1.0, *, asymmetric: bool = True
) -> np.ndarray:
    """Board coordinates ``(n, 3)`` of the centres, in the detection order.

    Centre ``k`` (row ``i = k // w``, column ``j = k % w``) sits at ``(j s, i s, 0)`` on
    a symmetric grid and at ``((2 j + i % 2) s / 2, i s / 2, 0)`` on an asymmetric one,
    ``s = spacing`` being the distance between neighbouring centres of one row
    (OpenCV's sample passes ``s / 2`` as its "square size" for the asymmetric grid).

    Parameters
    ----------
    pattern_size : (int, int)
        Circles per row and rows (:func:`~robopercept.calibration.chessboard.check_pattern_size`).
    spacing : float
        In (0, 1e140].
    asymmetric : bool

    Returns
    -------
    (w * h, 3) float64 ndarray

    Raises
    ------
    InputError
        A parameter of the wrong type or out of its range.

    Examples
    --------
    >>> circles_grid_points((2, 2), 2.0, asymmetric=False)[:, :2].tolist()
    [[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0]]
    """
    w, h = check_pattern_size(pattern_size, "circles")
    spacing = check_real(spacing, "spacing", 0.0, MAX_LENGTH, low_inclusive=False)
    asymmetric = check_bool(asymmetric, "asymmetric")
    i, j = np.divmod(np.arange(w * h), w)
    if asymmetric:
        x, y = (2 * j + i % 2) * spacing / 2.0, i * spacing / 2.0
    else:
        x, y = j * float(spacing), i * float(spacing)
    return np.stack([x, y, np.zeros(w * h)], axis=1).astype(np.float64)


@njit(cache=True)
def _moments(labels, n):  # pragma: no cover - compiled
    # per label: area, sums of x, y, x^2, y^2, xy (about the bbox corner, for precision)
    # and whether it touches the image border
    h, w = labels.shape
    m = np.zeros((n + 1, 6))
    x0 = np.full(n + 1, w, dtype=np.int64)
    y0 = np.full(n + 1, h, dtype=np.int64)
    edge = np.zeros(n + 1, dtype=np.bool_)
    for y in range(h):
        for x in range(w):
            k = labels[y, x]
            if k > 0 and x0[k] == w:
                x0[k], y0[k] = x, y
    for y in range(h):
        for x in range(w):
            k = labels[y, x]
            if k == 0:
                continue
            dx = float(x - x0[k])
            dy = float(y - y0[k])
            m[k, 0] += 1.0
            m[k, 1] += dx
            m[k, 2] += dy
            m[k, 3] += dx * dx
            m[k, 4] += dy * dy
            m[k, 5] += dx * dy
            if x == 0 or y == 0 or x == w - 1 or y == h - 1:
                edge[k] = True
    return m, x0, y0, edge


def _ellipse_blobs(mask: np.ndarray, min_area: float, max_area: float) -> np.ndarray:
    """Centroid and radius ``(n, 3)`` of the components of ``mask`` that are filled
    ellipses of an accepted size, not touching the border."""
    labels, n = label_components(mask, connectivity=8)
    if n == 0:
        return np.zeros((0, 3))
    m, x0, y0, edge = _moments(labels, n)
    m, x0, y0, edge = m[1:], x0[1:], y0[1:], edge[1:]
    a = m[:, 0]
    keep = (a >= min_area) & (a <= max_area) & ~edge
    m, x0, y0, a = m[keep], x0[keep], y0[keep], a[keep]
    mx, my = m[:, 1] / a, m[:, 2] / a
    sxx = m[:, 3] / a - mx * mx
    syy = m[:, 4] / a - my * my
    sxy = m[:, 5] / a - mx * my
    det = np.maximum(sxx * syy - sxy * sxy, 1e-12)
    tr = sxx + syy
    disc = np.sqrt(np.maximum(0.25 * tr * tr - det, 0.0))
    lmin, lmax = 0.5 * tr - disc, 0.5 * tr + disc
    fill = a / (4.0 * np.pi * np.sqrt(det))
    ok = (fill > 0.85) & (fill < 1.15) & (lmin >= 0.1 * lmax)
    return np.stack([x0[ok] + mx[ok], y0[ok] + my[ok], np.sqrt(a[ok] / np.pi)], axis=1)


def _circles(gray: np.ndarray, dark: bool, min_area: float, max_area: float) -> np.ndarray:
    """Circle centres and radii: blobs repeated over at least two thresholds."""
    from scipy.spatial import cKDTree

    groups: list[list[np.ndarray]] = []
    centres = np.zeros((0, 2))
    for t in _THRESHOLDS:  # on the image with the circles dark (light ones: 255 - gray)
        blobs = _ellipse_blobs(gray < t if dark else gray > 255 - t, min_area, max_area)
        if len(groups) and len(blobs):
            d, k = cKDTree(centres).query(blobs[:, :2])
            tol = 0.5 * np.minimum(blobs[:, 2], [groups[j][-1][2] for j in k])
            new = []
            for b, dist, j, tj in zip(blobs, d, k, tol, strict=True):
                if dist <= tj:
                    groups[j].append(b)
                else:
                    new.append(b)
        else:
            new = list(blobs)
        groups.extend([b] for b in new)
        centres = np.array([np.mean([b[:2] for b in g], axis=0) for g in groups]).reshape(-1, 2)
    out = [np.mean(g, axis=0) for g in groups if len(g) >= _MIN_REPEAT]
    return np.array(out).reshape(-1, 3)


def _grow(pts: np.ndarray, s: int, tree: cKDTree, limit: int) -> dict:
    """Lattice ``{(a, b): index}`` grown from seed ``s`` (see the module docstring): its
    nearest neighbour and the nearest one not along it start it, :func:`grow_lattice`
    does the rest."""
    d, nb = tree.query(pts[s], k=min(7, len(pts)))
    d, nb = d[1:], nb[1:]
    if len(nb) < 2:
        return {(0, 0): s}
    u = pts[nb[0]] - pts[s]
    second = -1
    for dist, k in zip(d[1:], nb[1:], strict=True):
        v = pts[k] - pts[s]
        c = abs(u @ v) / (np.linalg.norm(u) * dist)
        if c < 0.5 and dist < 2.0 * d[0]:  # between 60 and 120 degrees from u
            second = k
            break
    if second < 0:
        return {(0, 0): s}
    # grow_lattice stops at a span of limit + 1: beyond the pattern in either orientation
    return grow_lattice(pts, s, int(nb[0]), int(second), limit + 1)


_SYMMETRIES = tuple((swap, sx, sy) for swap in (False, True) for sx in (1, -1) for sy in (1, -1))


def _pattern(w: int, h: int, asymmetric: bool) -> np.ndarray:
    """Board coordinates ``(w h, 2)`` of the centres in detection order, integer:
    half-spacings ``(2 j + i mod 2, i)`` (asymmetric) or spacings ``(j, i)``."""
    i, j = np.divmod(np.arange(w * h), w)
    return np.stack([2 * j + i % 2, i], 1) if asymmetric else np.stack([j, i], 1)


def _windows(
    base: np.ndarray, idx: np.ndarray, pts: np.ndarray, want: np.ndarray, *, handed: bool
) -> dict[frozenset, list[np.ndarray]]:
    """Every placement of the pattern ``want`` (board coordinates) on the lattice (board
    coordinates ``base`` of circles ``idx``) under the lattice's eight symmetries in
    which each pattern node holds a circle: ``{circles: [ordered centres, ...]}``, one
    entry per distinct set of circles. ``handed`` keeps only placements whose x step
    turns clockwise into the y step in the image (the board seen from the front)."""
    from numpy.lib.stride_tricks import sliding_window_view

    mask = np.zeros((int(want[:, 1].max()) + 1, int(want[:, 0].max()) + 1), dtype=bool)
    mask[want[:, 1], want[:, 0]] = True
    board = np.column_stack([want, np.ones(len(want))])
    out: dict[frozenset, list[np.ndarray]] = {}
    for swap, sx, sy in _SYMMETRIES:
        xy = base[:, ::-1] if swap else base
        xy = xy * np.array([sx, sy])
        xy = xy - xy.min(axis=0)
        occ = np.full((xy[:, 1].max() + 1, xy[:, 0].max() + 1), -1, dtype=np.int64)
        occ[xy[:, 1], xy[:, 0]] = idx
        if occ.shape[0] < mask.shape[0] or occ.shape[1] < mask.shape[1]:
            continue
        full = (sliding_window_view(occ >= 0, mask.shape) | ~mask).all(axis=(2, 3))
        for oy, ox in np.argwhere(full):
            sel = occ[oy + want[:, 1], ox + want[:, 0]]  # centre k -> circle index
            if handed:  # affine fit board -> image: x step turns clockwise into y step
                M, *_ = np.linalg.lstsq(board, pts[sel], rcond=None)
                if M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0] <= 0:
                    continue
            out.setdefault(frozenset(sel.tolist()), []).append(pts[sel])
    return out


def _label(
    grid: dict, pts: np.ndarray, w: int, h: int, asymmetric: bool
) -> tuple[np.ndarray | None, str]:
    """The centres in detection order, or None and why the lattice is not the pattern
    ("" when it is too small or holds no complete pattern).

    A lattice larger than the pattern (stray blobs on the lattice's extension: screws,
    holes, a label) still gives the pattern when exactly one ``w x h`` window of it is
    complete and no ``(w + 1) x h`` or ``w x (h + 1)`` grid is (which would make the
    board larger than ``pattern_size`` says, and the window a guess).
    """
    n = w * h
    if len(grid) < n:
        return None, ""
    ab = np.array(list(grid.keys()), dtype=np.int64)
    idx = np.array(list(grid.values()), dtype=np.int64)
    # board coordinates (x, y) in half-spacings (asymmetric: the lattice runs along the
    # diagonals) or spacings (symmetric)
    base = np.stack([ab[:, 0] - ab[:, 1], ab[:, 0] + ab[:, 1]], 1) if asymmetric else ab
    found = _windows(base, idx, pts, _pattern(w, h, asymmetric), handed=True)
    if not found:
        return None, ""
    if len(grid) > n:
        for ww, hh in ((w + 1, h), (w, h + 1)):
            if _windows(base, idx, pts, _pattern(ww, hh, asymmetric), handed=False):
                return None, f"a {ww} x {hh} grid"
    if len(found) > 1:
        return None, f"{len(found)} different {w} x {h} grids"
    # half-turn symmetric patterns match twice: the first centre higher in the image
    return min(next(iter(found.values())), key=lambda c: (c[0, 1], c[0, 0])), ""


def find_circles_grid(
    image: np.ndarray,
    pattern_size: tuple[int, int],
    *,
    asymmetric: bool = True,
    blob_color: str = "dark",
    min_area: float = 25.0,
    max_area: float = 5000.0,
    max_seeds: int = 20,
) -> CircleGridDetection:
    """Find the centres of a grid of circles (``cv2.findCirclesGrid``).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8 or float image (RGB for colour).
    pattern_size : (int, int)
        Circles per row and rows, e.g. ``(4, 11)`` for OpenCV's asymmetric pattern.
    asymmetric : bool
        OpenCV's ``CALIB_CB_ASYMMETRIC_GRID`` (rows offset by half a spacing) or the
        symmetric grid.
    blob_color : {"dark", "light"}
        Circles darker than their surround (OpenCV's default detector) or lighter.
    min_area, max_area : float
        Accepted circle area in pixels (OpenCV's defaults).
    max_seeds : int
        Lattices of 4 circles or more grown before giving up.

    Returns
    -------
    CircleGridDetection
        ``found`` is False (with the reason) unless every circle was found. Extra
        circles on the grid's extension (stray blobs) are left out; a grid larger than
        ``pattern_size`` is not found. Unpacks as ``ok, centers`` in the order of
        ``cv2.findCirclesGrid`` (centres ``(w * h, 1, 2)`` float32, or None).

    Raises
    ------
    InputError
        An image that :func:`~robopercept.imaging.rgb_to_gray` refuses, a
        ``pattern_size`` that
        :func:`~robopercept.calibration.chessboard.check_pattern_size` refuses, or a
        parameter of the wrong type or range.
    """
    w, h = check_pattern_size(pattern_size, "circles")
    asymmetric = check_bool(asymmetric, "asymmetric")
    check_choice(blob_color, "blob_color", ("dark", "light"))
    min_area = check_real(min_area, "min_area", 0.0, low_inclusive=False)
    max_area = check_real(max_area, "max_area", 0.0, low_inclusive=False)
    if not min_area <= max_area:
        raise InputError(f"need 0 < min_area <= max_area; got {min_area}, {max_area}")
    max_seeds = check_int(max_seeds, "max_seeds", 1)
    gray = np.ascontiguousarray(rgb_to_gray(image), dtype=np.float64)  # validates; same scale
    if image.dtype.kind == "f" and gray.max() <= 1.0 + 1e-9:
        gray = gray * 255.0
    circles = _circles(gray, blob_color == "dark", float(min_area), float(max_area))
    n = w * h
    if len(circles) < n:
        return CircleGridDetection(
            False, circles[:, :2], (w, h), asymmetric,
            f"only {len(circles)} circle-like blobs; need {n}"
            + ("" if len(circles) else f" (are the circles {blob_color}?)"),
        )  # fmt: skip
    from scipy.spatial import cKDTree

    pts = circles[:, :2]
    tree = cKDTree(pts)
    order = np.argsort(np.hypot(*(pts - np.median(pts, axis=0)).T), kind="stable")
    used = np.zeros(len(pts), dtype=bool)
    largest: dict = {}
    ambiguous = ""  # why a lattice holding the pattern was not taken
    tries = 0
    limit = w + h + 2 if asymmetric else max(w, h) + 2
    for s in order:
        if used[s]:
            continue
        grid = _grow(pts, int(s), tree, limit)
        used[list(grid.values())] = True
        if len(grid) < 4:
            continue
        tries += 1
        if len(grid) > len(largest):
            largest = grid
        centers, larger = _label(grid, pts, w, h, asymmetric)
        if centers is not None:
            return CircleGridDetection(True, centers, (w, h), asymmetric)
        if larger and not ambiguous:
            ambiguous = f"the lattice of {len(grid)} circles holds {larger}"
        if tries >= max_seeds:
            break
    partial = pts[list(largest.values())] if largest else np.zeros((0, 2))
    kind = "asymmetric" if asymmetric else "symmetric"
    if ambiguous:
        reason = (
            f"{ambiguous}, so a {w} x {h} {kind} grid of it would be a guess: the grid "
            "has more circles than the pattern size says (give circles per row x rows of "
            "the whole grid)"
        )
    else:
        reason = (
            f"no complete {w} x {h} {kind} grid of circles (largest lattice: {len(largest)} "
            "circles); the whole grid must be visible"
        )
    return CircleGridDetection(False, partial, (w, h), asymmetric, reason)
