"""k-means, DBSCAN and mean shift: hand cases, parity with scikit-learn, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError, NotFittedError
from robopercept.learning.dbscan import DBSCAN
from robopercept.learning.kmeans import KMeans, kmeans_plusplus
from robopercept.learning.meanshift import MeanShift, estimate_bandwidth


def _blobs(gen: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    centres = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    y = np.repeat(np.arange(3), 50)
    return centres[y] + gen.normal(scale=0.5, size=(150, 2)), y


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    from sklearn.metrics import adjusted_rand_score

    return adjusted_rand_score(a, b) == 1.0


def test_kmeans_hand_case():
    X = np.array([[0.0, 0], [0, 1], [10, 0], [10, 1]])
    km = KMeans(2, init=np.array([[0.0, 0], [10, 0]])).fit(X)
    np.testing.assert_allclose(km.cluster_centers_, [[0, 0.5], [10, 0.5]])
    assert km.inertia_ == pytest.approx(1.0)
    np.testing.assert_array_equal(km.labels_, [0, 0, 1, 1])
    np.testing.assert_array_equal(km.predict([[9.0, 9.0]]), [1])


@pytest.mark.parametrize("name,k", [("iris", 3), ("digits", 10)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kmeans_matches_sklearn_from_same_centres(request, name, k, seed):
    """Same initial centres -> the same Lloyd iterations: identical labels, inertia
    within 1e-8 relative (the sums differ only in rounding order)."""
    from sklearn.cluster import KMeans as SkKMeans

    X, _ = request.getfixturevalue(name)
    init = kmeans_plusplus(X, k, random_state=seed)
    ours = KMeans(k, init=init).fit(X)
    ref = SkKMeans(k, init=init, n_init=1).fit(X)
    np.testing.assert_array_equal(ours.labels_, ref.labels_)
    assert abs(ours.inertia_ - ref.inertia_) <= 1e-8 * ref.inertia_
    np.testing.assert_allclose(ours.cluster_centers_, ref.cluster_centers_, atol=1e-9)


def test_kmeans_plusplus_spreads_and_is_seeded(rng):
    X, _ = _blobs(rng)
    a = KMeans(3, random_state=7).fit(X)
    b = KMeans(3, random_state=7).fit(X)
    np.testing.assert_array_equal(a.labels_, b.labels_)
    # k-means++ on well-separated blobs finds them
    assert a.inertia_ < 150 * 2 * 0.5**2 * 1.5
    init = kmeans_plusplus(X, 3, random_state=0)
    assert len({tuple(np.round(c / 10)) for c in init}) == 3


def test_kmeans_random_init_and_empty_cluster():
    X = np.array([[0.0], [0.1], [0.2], [5.0]])
    # the second centre is beyond every sample: it starts empty and is moved
    km = KMeans(2, init=np.array([[0.1], [100.0]])).fit(X)
    assert sorted(np.bincount(km.labels_).tolist()) == [1, 3]
    assert KMeans(3, init="random", random_state=0).fit(X).inertia_ >= 0


def test_kmeans_bad_input(iris):
    X, _ = iris
    with pytest.raises(InputError, match="more than the"):
        KMeans(200).fit(X[:10])
    with pytest.raises(InputError, match="init"):
        KMeans(3, init="magic").fit(X)
    with pytest.raises(NotFittedError):
        KMeans(3).predict(X)
    with pytest.raises(InputError, match="features"):
        KMeans(3, random_state=0).fit(X).predict(X[:, :2])


def test_dbscan_hand_case():
    # a chain of core points, one border point, one noise point
    X = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0], [4.9, 0], [20, 0]])
    db = DBSCAN(eps=1.0, min_samples=3).fit(X)
    # 1, 2 have 3 neighbours (themselves included); 0 and 3 are border; 4.9 and 20 noise
    np.testing.assert_array_equal(db.labels_, [0, 0, 0, 0, -1, -1])
    np.testing.assert_array_equal(db.core_sample_indices_, [1, 2])


@pytest.mark.parametrize(
    "name,eps,min_samples",
    [("iris", 0.5, 5), ("iris", 0.35, 3), ("digits", 20.5, 5), ("digits", 18.1, 3)],
)
def test_dbscan_labels_identical_to_sklearn(request, name, eps, min_samples):
    from sklearn.cluster import DBSCAN as SkDBSCAN

    X, _ = request.getfixturevalue(name)
    ours = DBSCAN(eps, min_samples=min_samples).fit(X)
    ref = SkDBSCAN(eps=eps, min_samples=min_samples).fit(X)
    np.testing.assert_array_equal(ours.labels_, ref.labels_)
    np.testing.assert_array_equal(ours.core_sample_indices_, ref.core_sample_indices_)


def test_dbscan_chunked_paths_agree(monkeypatch, rng):
    """The no-cache and small-chunk paths (used on millions of points) give the same
    labels as the single-chunk one, for the tree and the brute-force search."""
    import robopercept.learning.dbscan as mod

    low = rng.normal(size=(400, 3))
    high = rng.normal(size=(300, 20))
    expect = [DBSCAN(0.45, min_samples=4).fit(low).labels_, DBSCAN(4.5).fit(high).labels_]
    monkeypatch.setattr(mod, "_CHUNK", 37)
    monkeypatch.setattr(mod, "_CACHE_BYTES", 0)
    monkeypatch.setattr(mod, "_BLOCK_BYTES", 8 * 300 * 11)
    np.testing.assert_array_equal(DBSCAN(0.45, min_samples=4).fit(low).labels_, expect[0])
    np.testing.assert_array_equal(DBSCAN(4.5).fit(high).labels_, expect[1])
    assert len(set(expect[0].tolist())) > 2


def test_dbscan_all_noise_and_bad_input():
    X = np.arange(10.0)[:, None] * 10
    assert (DBSCAN(1.0, min_samples=2).fit(X).labels_ == -1).all()
    with pytest.raises(InputError, match="eps"):
        DBSCAN(0.0).fit(X)
    with pytest.raises(InputError, match="NaN"):
        DBSCAN().fit(np.array([[0.0], [np.nan]]))


def test_meanshift_finds_blob_centres(rng):
    X, y = _blobs(rng)
    ms = MeanShift(2.0).fit(X)
    assert len(ms.cluster_centers_) == 3
    assert _same_partition(ms.labels_, y)
    for c in ms.cluster_centers_:
        assert np.min(np.linalg.norm(c - [[0, 0], [10, 0], [0, 10]], axis=1)) < 0.3
    g = MeanShift(2.0, kernel="gaussian").fit(X)
    assert _same_partition(g.labels_, y)


@pytest.mark.parametrize(
    "name,bandwidth,seeds", [("iris", 0.8, "all"), ("iris", 1.0, "grid"), ("digits", 25.0, "all")]
)
def test_meanshift_matches_sklearn(request, name, bandwidth, seeds):
    """Adjusted Rand index >= 0.99 against sklearn with the same bandwidth (the
    window tests use differently rounded distances, so a sample on a window's edge may
    fall the other way)."""
    from sklearn.cluster import MeanShift as SkMeanShift
    from sklearn.metrics import adjusted_rand_score

    X = request.getfixturevalue(name)[0][:700]  # sklearn takes ~7 s on all of digits
    ours = MeanShift(bandwidth, seeds=seeds).fit(X)
    ref = SkMeanShift(bandwidth=bandwidth, bin_seeding=seeds == "grid").fit(X)
    assert adjusted_rand_score(ours.labels_, ref.labels_) >= 0.99


def test_meanshift_bad_input(rng):
    X, _ = _blobs(rng)
    with pytest.raises(InputError, match="bandwidth"):
        MeanShift(-1.0).fit(X)
    with pytest.raises(InputError, match="kernel"):
        MeanShift(1.0, kernel="box").fit(X)
    with pytest.raises(InputError, match="min_bin_freq"):
        MeanShift(1.0, seeds="grid", min_bin_freq=1000).fit(X)
    with pytest.raises(NotFittedError):
        MeanShift(1.0).predict(X)


# issue 25: data near 1e300 (or 1e-300) overflowed (underflowed) the squared distances:
# NaN inertia, or every point in one cluster. It is refused with a typed error naming
# the fix; data within 1e150 of scale gives the answer of the rescaled data
@pytest.mark.parametrize("scale", [1e300, 1e160, 1e-300, 1e-160])
def test_kmeans_refuses_data_whose_squares_overflow(scale):
    X = np.random.default_rng(0).normal(size=(40, 3))
    with pytest.raises(InputError, match="rescale your data"):
        KMeans(2, random_state=0).fit(X * scale)
    km = KMeans(2, random_state=0).fit(X)
    with pytest.raises(InputError, match="X has values up to"):
        km.predict(X * 1e300)


def test_kmeans_at_1e140_is_the_rescaled_answer():
    X = np.random.default_rng(0).normal(size=(40, 3))
    a, b = KMeans(2, random_state=0).fit(X), KMeans(2, random_state=0).fit(X * 1e140)
    np.testing.assert_array_equal(a.labels_, b.labels_)
    np.testing.assert_allclose(b.cluster_centers_, a.cluster_centers_ * 1e140, rtol=1e-9)


# issue 25: kmeans_plusplus took any n_clusters / n_local_trials (ValueError on NaN,
# TypeError on 1.9e16, an empty X reached numpy's choice), estimate_bandwidth any
# n_samples, and data near 1e300 broke the k-d tree (DBSCAN: a TypeError)
_XC = np.concatenate([np.random.default_rng(25).normal(c, 0.5, (20, 4)) for c in (0, 3, 6)])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: kmeans_plusplus(np.zeros((0, 4)), 3), "X is empty"),
        (lambda: kmeans_plusplus(_XC, np.nan), "n_clusters must be an integer"),
        (lambda: kmeans_plusplus(_XC, 2**63), "n_clusters=.* is more than the 60 samples"),
        (lambda: kmeans_plusplus(_XC, 3, n_local_trials=1.9e16), "n_local_trials must be an"),
        (lambda: kmeans_plusplus(_XC, 3, n_local_trials=0), "n_local_trials must be >= 1"),
        (lambda: kmeans_plusplus(_XC, 3, n_local_trials=2**40), "n_local_trials must be in"),
        (lambda: kmeans_plusplus(_XC * 1e300, 3), "X has values up to"),
        (lambda: estimate_bandwidth(_XC, n_samples=np.float32(2.0)), "n_samples must be an"),
        (lambda: estimate_bandwidth(_XC, n_samples=-1.3e89), "n_samples must be an integer"),
        (lambda: estimate_bandwidth(_XC, quantile="0.3"), "quantile must be a real number"),
        (lambda: DBSCAN().fit(_XC * 1e300), "X has values up to"),
        (lambda: DBSCAN(progress=np.nan).fit(_XC), "progress must be True or False"),
        (lambda: KMeans(3, n_init=2**40).fit(_XC), "n_init must be in 1..1000"),
        (lambda: KMeans(3, n_init=np.eye(3)).fit(_XC), "n_init"),
        (lambda: KMeans(3, tol="0"), "tol must be a real number"),
        (lambda: MeanShift(kernel=np.eye(3)).fit(_XC), "kernel must be one of"),
        (lambda: MeanShift(cluster_all="no").fit(_XC), "cluster_all must be True or False"),
        (lambda: MeanShift(seeds=[["a"]]).fit(_XC), "seeds must hold real numbers"),
    ],
)
def test_hostile_arguments_are_refused_by_name(call, match):
    with pytest.raises(InputError, match=match):
        est = call()
        est.fit(_XC)  # the ones that only build an estimator


def test_kmeans_plusplus_edges_still_work():
    # one centre per sample and a single trial are valid
    C = kmeans_plusplus(_XC[:5], 5, random_state=0, n_local_trials=1)
    assert sorted(map(tuple, C)) == sorted(map(tuple, _XC[:5]))
    assert estimate_bandwidth(_XC, n_samples=10**9, random_state=0) == estimate_bandwidth(_XC)
