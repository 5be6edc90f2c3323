"""Connected components and blob features."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import measure

from robopercept.errors import InputError
from robopercept.imaging import blob_features, label_components, otsu_threshold
from robopercept.imaging.blobs import uf_find, uf_roots, uf_union, uf_union_pairs
from tests.conftest import data_path


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True if label images a and b split the pixels identically (a bijection of labels)."""
    if not np.array_equal(a == 0, b == 0):
        return False
    pairs = np.unique(np.stack([a.ravel(), b.ravel()]), axis=1)
    return len(np.unique(pairs[0])) == pairs.shape[1] == len(np.unique(pairs[1]))


def test_square_features_hand():
    mask = np.zeros((20, 20), np.uint8)
    mask[5:15, 3:13] = 1
    labels, n = label_components(mask)
    assert n == 1
    f = blob_features(labels)
    assert f.area.tolist() == [100]
    assert f.bbox.tolist() == [[3, 5, 10, 10]]
    np.testing.assert_allclose(f.centroid, [[7.5, 9.5]])
    assert f.aspect_ratio[0] == 1.0
    # 36 border pixels, each in a straight run or an L corner (weight 1): skimage's
    # estimator follows pixel centres, 4 sides of 9 pixel steps = 36; issue 48: that is
    # below 40, the hull of the pixel squares (the square's outline), so P = 40
    assert measure.regionprops(labels)[0].perimeter == pytest.approx(36.0)
    assert f.perimeter[0] == pytest.approx(40.0)
    # a 45-degree step edge costs sqrt(2) per step
    tri = np.tril(np.ones((6, 6), np.uint8))
    assert blob_features(label_components(tri)[0]).perimeter[0] > 5 + 5
    assert f.circularity[0] == pytest.approx(4 * np.pi * 100 / f.perimeter[0] ** 2)
    assert f.circularity[0] == pytest.approx(np.pi / 4)  # a square's 4 pi A / P^2
    assert f.holes[0] == 0


def test_ring_has_one_hole_and_figure_eight_two():
    ring = np.zeros((12, 12), bool)
    ring[2:10, 2:10] = True
    ring[4:8, 4:8] = False
    assert blob_features(label_components(ring)[0]).holes.tolist() == [1]
    eight = np.zeros((12, 20), bool)
    eight[2:10, 2:18] = True
    eight[4:8, 4:8] = False
    eight[4:8, 12:16] = False
    assert blob_features(label_components(eight)[0]).holes.tolist() == [2]


def test_connectivity_4_vs_8():
    diag = np.eye(5, dtype=bool)
    assert label_components(diag, 8)[1] == 1
    assert label_components(diag, 4)[1] == 5


def test_labels_in_raster_order_same_partition_as_opencv(rng):
    mask = rng.random((60, 80)) > 0.6
    ours, n = label_components(mask)
    n_cv, ref = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    assert n == n_cv - 1
    assert same_partition(ours, ref)
    # numbered by first pixel in raster order (OpenCV's block scan numbers differently)
    flat = ours.ravel()
    firsts = [flat.tolist().index(lab) for lab in range(1, n + 1)]
    assert firsts == sorted(firsts)


@pytest.mark.parametrize("connectivity", [4, 8])
@pytest.mark.parametrize("shape", [(1, 1), (7, 13), (33, 64), (40, 121)])
@pytest.mark.parametrize("density", [0.2, 0.5, 0.9])
def test_random_masks_same_partition_as_opencv(rng, connectivity, shape, density):
    # widths that are and are not whole 8-byte words (the run scan reads 8 at a time),
    # bool, uint8 and strided (non-contiguous) masks
    mask = rng.random(shape) < density
    for m in (mask, mask.astype(np.uint8) * 7, np.asfortranarray(mask)):
        ours, n = label_components(m, connectivity)
        n_cv, ref = cv2.connectedComponents(mask.astype(np.uint8), connectivity=connectivity)
        assert n == n_cv - 1
        assert same_partition(ours, ref)
        assert ((ours > 0) == mask).all()


def hull_bound(mask: np.ndarray) -> float:
    """Perimeter of the convex hull of a blob's pixel squares, by scipy's ConvexHull on
    the squares' corners (the reference for blob_features' lower bound)."""
    from scipy.spatial import ConvexHull

    ys, xs = np.nonzero(mask)
    corners = np.unique(
        np.concatenate([np.c_[xs + dx, ys + dy] for dx in (-0.5, 0.5) for dy in (-0.5, 0.5)]),
        axis=0,
    )
    v = corners[ConvexHull(corners).vertices]
    return float(np.linalg.norm(v - np.roll(v, 1, axis=0), axis=1).sum())


def to_ref_order(labels: np.ndarray, ref: np.ndarray, n: int) -> np.ndarray:
    """For each of our labels 1..n, the reference label of the same blob."""
    idx = np.zeros(n + 1, dtype=np.int64)
    idx[labels.ravel()] = ref.ravel()
    return idx[1:]


def _real_masks(camera, astronaut):
    masks = []
    for img in (camera, cv2.cvtColor(astronaut, cv2.COLOR_RGB2GRAY)):
        masks.append(img > otsu_threshold(img))
    for name in ("box.png", "box_in_scene.png"):
        img = cv2.imread(str(data_path("features", "opencv_box", name)), cv2.IMREAD_GRAYSCALE)
        masks.append(img > otsu_threshold(img))
    return masks


@pytest.mark.realdata
@pytest.mark.parametrize("connectivity", [4, 8])
def test_partition_and_stats_match_opencv(camera, astronaut, connectivity):
    for mask in _real_masks(camera, astronaut):
        labels, n = label_components(mask, connectivity)
        n_cv, ref, stats, centroids = cv2.connectedComponentsWithStats(
            mask.astype(np.uint8), connectivity=connectivity
        )
        assert n == n_cv - 1
        assert same_partition(labels, ref)
        f = blob_features(labels)
        order = to_ref_order(labels, ref, n)
        np.testing.assert_array_equal(f.area, stats[order, cv2.CC_STAT_AREA])
        np.testing.assert_array_equal(f.bbox, stats[order, :4])
        np.testing.assert_allclose(f.centroid, centroids[order], atol=1e-9)


@pytest.mark.realdata
def test_perimeter_and_holes_match_skimage(camera, astronaut):
    for mask in _real_masks(camera, astronaut):
        labels, _ = label_components(mask, 8)
        f = blob_features(labels)
        props = measure.regionprops(labels)
        # Same estimator (weighted border-pixel configurations), so equal up to float
        # summation order, 1e-9 relative, wherever it reaches the convex-hull bound
        # (issue 48); below it (small or thin blobs) P is the bound, never less.
        sk = np.array([p.perimeter for p in props])
        bound = np.array([hull_bound(labels == k) for k in f.labels])
        np.testing.assert_allclose(f.perimeter, np.maximum(sk, bound), rtol=1e-9)
        above = sk >= bound
        assert above.any() and (~above).any()  # both cases occur on real masks
        np.testing.assert_allclose(f.perimeter[above], sk[above], rtol=1e-9)
        assert f.circularity.max() <= 1.0
        # holes = 1 - Euler number (8-connected foreground, 4-connected background)
        np.testing.assert_array_equal(f.holes, [1 - p.euler_number for p in props])


def test_otsu_matches_opencv(camera, astronaut):
    for img in (camera, cv2.cvtColor(astronaut, cv2.COLOR_RGB2GRAY)):
        t_cv, _ = cv2.threshold(img, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
        assert otsu_threshold(img) == t_cv


def test_empty_and_full_masks():
    labels, n = label_components(np.zeros((5, 5), bool))
    assert n == 0 and len(blob_features(labels)) == 0
    labels, n = label_components(np.ones((5, 5), bool))
    assert n == 1 and blob_features(labels).area.tolist() == [25]
    assert len(blob_features(np.zeros((0, 0), np.int32))) == 0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: label_components(np.zeros((3, 3, 3))), "2-D"),
        (lambda: label_components(np.zeros((3, 3)), 6), "connectivity"),
        (lambda: blob_features(np.zeros((3, 3)) + 0.5), "integer"),
        (lambda: blob_features(-np.ones((3, 3), int)), ">= 0"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


class TestUnionFind:
    """The shared union-find forest (``uf_*``), also used by learning.dbscan."""

    def test_hand(self):
        parent = np.arange(6)
        assert uf_union(parent, 4, 2) == 2  # the smaller root wins
        assert uf_union(parent, 5, 4) == 2
        assert uf_union(parent, 1, 3) == 1
        assert uf_union(parent, 2, 2) == 2  # a node with itself: nothing changes
        assert uf_roots(parent).tolist() == [0, 1, 2, 1, 2, 2]
        # path compression: 5 -> 4 -> 2 becomes 5 -> 2
        parent = np.array([0, 1, 2, 3, 2, 4])
        assert uf_find(parent, 5) == 2
        assert parent.tolist() == [0, 1, 2, 3, 2, 2]

    @pytest.mark.parametrize("dtype", [np.int32, np.int64])
    def test_matches_scipy_components_and_order_free(self, rng, dtype):
        # the partition equals scipy's connected components of the pair graph, each set
        # rooted at its smallest member whatever the order of the unions
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        n = 200
        a, b = rng.integers(0, n, 150), rng.integers(0, n, 150)
        _, comp = connected_components(coo_matrix((np.ones(150), (a, b)), shape=(n, n)))
        smallest = np.full(comp.max() + 1, n)
        np.minimum.at(smallest, comp, np.arange(n))
        for perm in (np.arange(150), rng.permutation(150)):
            parent = np.arange(n, dtype=dtype)
            uf_union_pairs(parent, a[perm].astype(dtype), b[perm].astype(dtype))
            np.testing.assert_array_equal(uf_roots(parent), smallest[comp])

    def test_empty(self):
        parent = np.arange(3)
        uf_union_pairs(parent, np.zeros(0, np.int64), np.zeros(0, np.int64))
        assert uf_roots(parent).tolist() == [0, 1, 2]
        assert uf_roots(np.zeros(0, np.int64)).shape == (0,)


# issue 25: sparse label values
def test_issue25_sparse_label_values_do_not_allocate_by_the_largest():
    """int32 labels up to 2**31 - 1 in a small image made blob_features allocate
    per-label arrays of 2**31 entries (MemoryError); the features are those of the
    labels numbered 1..k, reported under their own values."""
    dense = np.zeros((12, 16), np.int32)
    dense[1:4, 1:5] = 1
    dense[6:11, 8:15] = 2
    dense[8, 10] = 0  # a hole
    sparse = np.where(dense == 1, 7, np.where(dense == 2, 2**31 - 1, 0)).astype(np.int32)
    a, b = blob_features(dense), blob_features(sparse)
    np.testing.assert_array_equal(b.labels, [7, 2**31 - 1])
    for field in ("area", "bbox", "centroid", "perimeter", "circularity", "holes"):
        np.testing.assert_array_equal(getattr(b, field), getattr(a, field))
    full = np.full((3, 3), 2**40, np.int64)  # no background at all
    assert blob_features(full).labels.tolist() == [2**40]
    assert blob_features(full).area.tolist() == [9]


def test_min_area_drops_small_blobs_and_numbers_the_rest_1_to_n():
    """Issue 30: ``blobs`` printed raw ids with gaps (1, 2, 5, 10, ...) after dropping
    small blobs; ``min_area`` drops them in the library and numbers the rest 1..n in the
    same order, as skimage's remove_small_objects then relabel_sequential."""
    from skimage.morphology import remove_small_objects
    from skimage.segmentation import relabel_sequential

    rng = np.random.default_rng(30)
    mask = rng.random((80, 90)) > 0.62
    for conn in (4, 8):
        raw, n_raw = label_components(mask, conn)
        labels, n = label_components(mask, conn, min_area=5)
        areas = np.bincount(raw.ravel())[1:]
        assert n == (areas >= 5).sum() < n_raw  # some dropped, hand-counted
        assert np.array_equal(np.unique(labels), np.arange(n + 1))  # 0..n, no gaps
        # skimage >= 0.26 removes objects of at most max_size pixels: those below 5
        kept = remove_small_objects(raw, max_size=4)
        ref, _, _ = relabel_sequential(kept)
        np.testing.assert_array_equal(labels, ref)  # same pixels, same (raster) order
    same, k = label_components(mask, 8, min_area=1)
    assert np.array_equal(same, label_components(mask, 8)[0]) and k == label_components(mask)[1]
    with pytest.raises(InputError, match="min_area must be"):
        label_components(mask, 8, min_area=-1)


# issue 48: circularity reached 37.7 on a 3-pixel line
@pytest.mark.parametrize(
    ("pixels", "perimeter"),
    [
        ([[1]], 4.0),  # a lone pixel: its square's outline
        ([[1, 1]], 6.0),  # a 2x1 rectangle
        ([[1, 1, 1]], 8.0),  # a 3x1 rectangle (skimage: 1, circularity 37.7)
        ([[1], [1], [1]], 8.0),
        ([[1, 1], [1, 0]], 6.0 + np.sqrt(2.0)),  # an L: hull of a 2x2 square minus a corner
        ([[1, 0], [0, 1]], 4.0 + 2 * np.sqrt(2.0)),  # a diagonal pair (8-connected)
        ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], 4.0 + 4 * np.sqrt(2.0)),
    ],
)
def test_tiny_blobs_perimeter_is_the_hull_bound_and_circularity_at_most_1(pixels, perimeter):
    """Hand values: the perimeter of the convex hull of the pixel squares (the centres'
    hull walked round, + 4), which skimage's centre-chain estimator undercuts on such
    blobs (0 for 1 or 2 pixels, 1 for a 3-pixel line); circularity 4 pi A / P^2 <= 1."""
    mask = np.pad(np.array(pixels, bool), 2)
    labels, n = label_components(mask, 8)
    assert n == 1
    f = blob_features(labels)
    assert f.perimeter[0] == pytest.approx(perimeter, abs=1e-12)
    assert f.perimeter[0] == pytest.approx(hull_bound(mask), abs=1e-9)
    assert measure.regionprops(labels)[0].perimeter < perimeter  # skimage's shortfall
    area = mask.sum()
    assert f.circularity[0] == pytest.approx(4 * np.pi * area / perimeter**2)
    assert 0 < f.circularity[0] <= 1.0


@pytest.mark.parametrize("radius", [20.3, 31.0, 45.0])
def test_disc_perimeter_is_regionprops_and_circularity_near_1(radius):
    """A digital disc of radius 20 or more (below about 15 the hull bound wins):
    skimage's estimate is above the hull bound, so the perimeter is regionprops' (1e-9
    relative: summation order), within 6% of 2 pi r (the estimator's own bias on
    discs), and the circularity is 0.88..1."""
    y, x = np.mgrid[-50:51, -50:51]
    mask = (x - 0.3) ** 2 + (y + 0.2) ** 2 <= radius**2
    labels, _ = label_components(mask)
    f = blob_features(labels)
    sk = measure.regionprops(labels)[0].perimeter
    assert sk > hull_bound(mask)
    assert f.perimeter[0] == pytest.approx(sk, rel=1e-9)
    assert f.perimeter[0] == pytest.approx(2 * np.pi * radius, rel=0.06)
    assert 0.88 <= f.circularity[0] <= 1.0


def test_circularity_never_exceeds_1_on_random_masks(rng):
    """Property (isoperimetric inequality with the hull bound), on many small and thin
    blobs; perimeter = max(regionprops perimeter, hull bound) for every blob."""
    worst = 0.0
    for _ in range(40):
        mask = rng.random((14, 14)) < rng.uniform(0.15, 0.7)
        labels, _ = label_components(mask, 8)
        f = blob_features(labels)
        sk = np.array([p.perimeter for p in measure.regionprops(labels)])
        bound = np.array([hull_bound(labels == k) for k in f.labels])
        np.testing.assert_allclose(f.perimeter, np.maximum(sk, bound), rtol=1e-9)
        worst = max(worst, float(f.circularity.max()))
    assert worst <= 1.0
