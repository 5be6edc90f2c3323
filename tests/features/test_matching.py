"""Descriptor matching: a hand case, parity with cv2.BFMatcher (L2, Hamming, knn,
cross-check), the ratio test, the k-d tree path, empty and bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.features import knn_match, match_descriptors


def test_hand_case():
    query = np.array([[0.0, 0.0], [10.0, 0.0], [5.0, 5.0]])
    train = np.array([[0.0, 1.0], [10.0, 3.0], [20.0, 20.0]])
    idx, dist = knn_match(query, train, 2)
    np.testing.assert_array_equal(idx, [[0, 1], [1, 0], [1, 0]])
    np.testing.assert_allclose(dist[:, 0], [1.0, 3.0, np.hypot(5, 2)], rtol=1e-6)
    # ratio 0.5: query 2 sits between two train points (5.39 vs 6.40) and is dropped
    m = match_descriptors(query, train, ratio=0.5)
    np.testing.assert_array_equal(m.query_idx, [0, 1])
    np.testing.assert_array_equal(m.train_idx, [0, 1])
    # cross-check: train 1's nearest query is 1, so query 2 -> train 1 is dropped
    m = match_descriptors(query, train, cross_check=True)
    np.testing.assert_array_equal(m.query_idx, [0, 1])
    m = match_descriptors(query, train, max_distance=2.0)
    np.testing.assert_array_equal(m.query_idx, [0])


def _cv_knn(matcher, q, t, k):
    ref = matcher.knnMatch(q, t, k=k)
    return (
        np.array([[m.trainIdx for m in r] for r in ref]),
        np.array([[m.distance for m in r] for r in ref]),
    )


def test_l2_matches_bfmatcher(rng):
    q = rng.random((700, 128), dtype=np.float32) * 255
    t = rng.random((600, 128), dtype=np.float32) * 255
    ri, rd = _cv_knn(cv2.BFMatcher(cv2.NORM_L2), q, t, 2)
    idx, dist = knn_match(q, t, 2)
    # random descriptors have no ties: identical neighbours; distances to float32
    # rounding (OpenCV accumulates in float32, we recompute the chosen pairs in float64)
    np.testing.assert_array_equal(idx, ri)
    np.testing.assert_allclose(dist, rd, rtol=1e-5)
    ours = match_descriptors(q, t, cross_check=True)
    ref = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(q, t)
    assert set(zip(ours.query_idx, ours.train_idx, strict=True)) == {
        (m.queryIdx, m.trainIdx) for m in ref
    }


def test_hamming_matches_bfmatcher(rng):
    q = rng.integers(0, 256, (500, 32), dtype=np.uint8)
    t = rng.integers(0, 256, (400, 32), dtype=np.uint8)
    _, rd = _cv_knn(cv2.BFMatcher(cv2.NORM_HAMMING), q, t, 2)
    idx, dist = knn_match(q, t, 2, metric="hamming")
    np.testing.assert_array_equal(dist, rd)  # integers: exact
    # ties in Hamming distance are common; ours breaks them by the lower train index
    xor = np.unpackbits(q[:, None, :] ^ t[None, :, :], axis=2).sum(axis=2)
    np.testing.assert_array_equal(np.take_along_axis(xor, idx, 1), dist)


def test_kdtree_path_equals_brute_force(rng):
    q = rng.random((3000, 8))
    t = rng.random((2500, 8))
    a_idx, a_dist = knn_match(q, t, 3, method="brute")
    b_idx, b_dist = knn_match(q, t, 3, method="kdtree")
    np.testing.assert_array_equal(a_idx, b_idx)
    np.testing.assert_allclose(a_dist, b_dist, rtol=1e-5)
    c_idx, _ = knn_match(q, t, 3)  # auto: the tree here (D <= 16, > 2000 rows)
    np.testing.assert_array_equal(c_idx, a_idx)


def test_ratio_test_keeps_distinctive_matches(rng):
    # 200 train descriptors; queries are noisy copies of the first 100, plus 100 that
    # sit halfway between two train descriptors (ambiguous): the ratio test keeps the
    # copies and drops the ambiguous ones
    t = rng.random((200, 64))
    copies = t[:100] + rng.normal(0, 0.01, (100, 64))
    between = (t[100:150] + t[150:200]) / 2
    q = np.vstack([copies, between])
    m = match_descriptors(q, t, ratio=0.8)
    assert set(m.query_idx) == set(range(100))
    np.testing.assert_array_equal(m.train_idx, np.arange(100))


def test_empty_and_bad_input():
    empty = np.zeros((0, 128), dtype=np.float32)
    some = np.ones((5, 128), dtype=np.float32)
    assert len(match_descriptors(empty, some)) == 0
    assert len(match_descriptors(some, empty)) == 0
    idx, dist = knn_match(some, some[:1], 3)  # k capped at the train size
    assert idx.shape == (5, 1) and dist.shape == (5, 1)
    with pytest.raises(InputError, match="differ in length"):
        knn_match(some, np.ones((3, 64)))
    with pytest.raises(InputError, match="uint8"):
        knn_match(some, some, metric="hamming")
    with pytest.raises(InputError, match="at least 2"):
        match_descriptors(some, some[:1], ratio=0.8)
    with pytest.raises(InputError, match="ratio"):
        match_descriptors(some, some, ratio=1.5)
    with pytest.raises(InputError, match="NaN"):
        knn_match(np.full((2, 4), np.nan), np.ones((2, 4)))
    with pytest.raises(InputError, match=r"\(N, D\)"):
        knn_match(np.ones(4), np.ones((2, 4)))
    with pytest.raises(InputError, match="kdtree"):
        knn_match(
            np.zeros((2, 4), np.uint8),
            np.zeros((2, 4), np.uint8),
            metric="hamming",
            method="kdtree",
        )


# issue 25: an empty query (a blank image's SIFT gives 0 descriptors) with the
# cross-check raised IndexError; every filter combination on an empty set gives an empty
# Matches of int64 indices and float64 distances, as cv2.BFMatcher(crossCheck=True).match
# gives an empty tuple for an empty query (and raises for an empty train set)
@pytest.mark.parametrize("metric", ["l2", "hamming"])
@pytest.mark.parametrize(("nq", "nt"), [(0, 5), (5, 0), (0, 0), (0, 1)])
@pytest.mark.parametrize(
    "kwargs",
    [{"cross_check": True}, {"ratio": 0.8}, {"ratio": 0.8, "cross_check": True}, {}],
)
def test_empty_sets_give_empty_matches(metric, nq, nt, kwargs):
    dtype = np.uint8 if metric == "hamming" else np.float32
    query, train = np.ones((nq, 32), dtype), np.ones((nt, 32), dtype)
    m = match_descriptors(query, train, metric=metric, **kwargs)
    assert len(m) == 0
    assert m.query_idx.dtype == m.train_idx.dtype == np.int64
    assert m.distance.dtype == np.float64
    assert m.query_idx.shape == m.train_idx.shape == m.distance.shape == (0,)
    norm = cv2.NORM_HAMMING if metric == "hamming" else cv2.NORM_L2
    if nq == 0:  # (OpenCV asserts on an empty train set with a non-empty query)
        assert len(cv2.BFMatcher(norm, crossCheck=True).match(query, train)) == 0


# issue 25: scalar parameters are checked at the boundary
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"ratio": float("nan")}, "ratio must be finite"),
        ({"ratio": True}, "ratio must be a real number"),
        ({"max_distance": [1.0]}, "max_distance must be a real number"),
        ({"cross_check": 1}, "cross_check must be True or False"),
        ({"metric": None}, "metric must be one of"),
    ],
)
def test_scalar_parameters_are_checked(kwargs, match):
    some = np.ones((5, 8), dtype=np.float32)
    with pytest.raises(InputError, match=match):
        match_descriptors(some, some, **kwargs)
