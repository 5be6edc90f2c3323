"""Learning pictorial structures (robopercept.nn.pose.pictorial_learn): the descriptors,
and the learned model on synthetic arms and on real MPII crops."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError, NotFittedError
from robopercept.nn.pose.pictorial_learn import (
    PictorialStructures,
    _fit_logistic,
    grid_descriptors,
)
from robopercept.nn.skeleton import MPII_16, Skeleton
from tests.conftest import data_path

# ==================================================================== descriptors


class TestGridDescriptors:
    def test_shape_and_colour_means(self):
        rng = np.random.default_rng(14)
        img = rng.random((18, 23, 3))
        d = grid_descriptors(img, cell=4, radius=1, orientations=6)
        assert d.shape == (4, 5, 9 * (6 + 3))
        # the centre cell's colour: the mean of its 4 x 4 pixels
        centre = d[2, 3, 9 * 6 + 4 * 3 : 9 * 6 + 5 * 3]
        np.testing.assert_allclose(centre, img[8:12, 12:16].reshape(-1, 3).mean(0))
        # the top-left neighbour of cell (0, 0) repeats the edge: cell (0, 0) itself
        np.testing.assert_allclose(d[0, 0, 54:57], img[:4, :4].reshape(-1, 3).mean(0))

    def test_vertical_edge_votes_the_horizontal_gradient_bins(self):
        # a step along x: the gradient is horizontal (angle 0), which lies halfway
        # between the centres of the first and last unsigned bins ((b + 1/2) pi / n)
        img = np.zeros((12, 12))
        img[:, 6:] = 1.0
        d = grid_descriptors(img, cell=4, radius=0, orientations=4)
        hist = d[1, 1, :4]  # the cell over the edge, normalized
        assert hist[0] == pytest.approx(hist[3]) and hist[0] > 0.5
        assert hist[1] == pytest.approx(0.0) and hist[2] == pytest.approx(0.0)
        assert np.all(d[1, 0, :4] == 0)  # a flat cell votes nothing

    def test_dtypes_and_gray(self):
        rng = np.random.default_rng(15)
        u8 = rng.integers(0, 256, (16, 16, 3), dtype=np.uint8)
        np.testing.assert_allclose(grid_descriptors(u8), grid_descriptors(u8 / 255.0))
        gray = rng.random((16, 16))
        np.testing.assert_allclose(
            grid_descriptors(gray), grid_descriptors(np.repeat(gray[..., None], 3, 2))
        )

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"image": np.zeros((3, 3, 3)), "cell": 4}, "smaller than one 4x4 cell"),
            ({"image": np.zeros((8, 8)), "cell": 0}, "cell must be >= 1"),
            ({"image": np.zeros((8, 8)), "radius": 9}, "radius must be at most"),
            ({"image": np.zeros((8, 8)), "radius": -1}, "radius must be >= 0"),
            ({"image": np.zeros((8, 8)), "orientations": 0}, "orientations must be >= 1"),
            ({"image": np.zeros((3, 8, 8))}, "channels-first"),
        ],
    )
    def test_bad_inputs(self, kwargs, match):
        with pytest.raises(InputError, match=match):
            grid_descriptors(**kwargs)


# ==================================================================== the model

ARM = Skeleton("arm", ["shoulder", "elbow", "wrist"], [(0, 1), (1, 2)], [])
COLOURS = np.array([[1.0, 0.1, 0.1], [0.1, 0.9, 0.1], [0.1, 0.2, 1.0]])


def arm_images(n: int, seed: int, size: int = 64, radius: int = 4):
    """``n`` noise pictures with a 3-joint arm of coloured discs: shoulder (red)
    anywhere in the upper-left, elbow (green) about 14 px right of it, wrist (blue)
    about 14 px below the elbow (offsets jittered by 2 px)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:size, :size]
    images = rng.uniform(0, 1, (n, size, size, 3))
    kp = np.zeros((n, 3, 3))
    for k in range(n):
        s = rng.uniform(12, 28, 2)
        e = s + np.array([14.0, 0.0]) + rng.normal(0, 2, 2)
        w = e + np.array([0.0, 14.0]) + rng.normal(0, 2, 2)
        for j, p in enumerate((s, e, w)):
            images[k][(xx - p[0]) ** 2 + (yy - p[1]) ** 2 <= radius**2] = COLOURS[j]
            kp[k, j] = (*p, 2)
    return images, kp


@pytest.fixture(scope="module")
def arms():
    return arm_images(40, 0), arm_images(20, 1)


@pytest.fixture(scope="module")
def arm_model(arms):
    (train, ktrain), _ = arms
    return PictorialStructures(ARM, cell=4, random_state=0).fit(train, ktrain)


class TestPictorialStructuresModel:
    def test_localizes_held_out_arms(self, arm_model, arms):
        _, (test, ktest) = arms
        pred = arm_model.predict(test)
        assert pred.shape == (20, 3, 2)
        err = np.linalg.norm(pred - ktest[..., :2], axis=2)
        # a 4-px grid puts a joint at most 2.8 px from its cell centre; allow one cell
        # of slack for the worst joint
        assert err.mean() < 3.0, err
        assert err.max() < 6.5, err

    def test_learns_the_springs(self, arm_model):
        assert arm_model.parents_.tolist() == [1, -1, 1]  # rooted at the elbow
        # the shoulder sits 14 px left of the elbow, the wrist 14 px below; the
        # offsets were jittered with sigma 2 px (so variance 4, the floor cell/2)
        np.testing.assert_allclose(arm_model.offsets_[0], [-14, 0], atol=1.0)
        np.testing.assert_allclose(arm_model.offsets_[2], [0, 14], atol=1.0)
        np.testing.assert_allclose(arm_model.variances_[[0, 2]], 4.0, rtol=0.5)
        assert np.all(arm_model.offsets_[1] == 0)

    def test_costs_are_lowest_on_the_joint(self, arm_model, arms):
        _, (test, ktest) = arms
        costs = arm_model.predict_costs(test[0])
        assert costs.shape == (3, 16, 16) and np.all(costs >= 0)
        for j in range(3):
            gy, gx = np.unravel_index(np.argmin(costs[j]), costs[j].shape)
            assert np.hypot(gx * 4 + 1.5 - ktest[0, j, 0], gy * 4 + 1.5 - ktest[0, j, 1]) < 6

    def test_logistic_regression_matches_scikit_learn(self):
        # the part classifier minimizes LogisticRegression's objective (C sum of log
        # losses + |w|^2 / 2, free intercept), which is strictly convex: both solvers
        # approach the one optimum. scikit-learn's lbfgs stops on its relative-decrease
        # test with gradients ~5e-9 per sample, a few 1e-6 from the optimum: 2e-5
        sklearn = pytest.importorskip("sklearn.linear_model")
        rng = np.random.default_rng(16)
        X = rng.normal(size=(300, 12))
        y = (X[:, 0] - 0.7 * X[:, 3] + rng.normal(size=300) > 0.5).astype(float)
        for C in (0.1, 1.0, 10.0):
            w, b = _fit_logistic(X, y, C)
            ref = sklearn.LogisticRegression(C=C, tol=1e-10, max_iter=10000).fit(X, y)
            np.testing.assert_allclose(w, ref.coef_[0], atol=2e-5)
            assert b == pytest.approx(ref.intercept_[0], abs=2e-5)
            # optimality: the gradient w + C X^T (sigma(z) - y) vanishes at our solution
            z = X @ w + b
            grad = np.r_[
                w + C * X.T @ (1 / (1 + np.exp(-z)) - y), C * np.sum(1 / (1 + np.exp(-z)) - y)
            ]
            # (per sample below 1e-8: where the trust region's ratio test meets rounding)
            assert np.abs(grad).max() < 300 * 1e-8

    def test_seeded_determinism(self, arms):
        (train, ktrain), (test, _) = arms

        def fit(seed):
            return PictorialStructures(ARM, random_state=seed).fit(train[:8], ktrain[:8])

        a, b, c = fit(3), fit(3), fit(4)
        np.testing.assert_array_equal(a.coef_, b.coef_)
        np.testing.assert_array_equal(a.predict(test[:4]), b.predict(test[:4]))
        assert not np.array_equal(a.coef_, c.coef_)  # other negatives

    def test_list_of_images_of_any_size_and_partial_labels(self, arms):
        (train, ktrain), (test, ktest) = arms
        kp = ktrain[:20].copy()
        kp[0, 2] = (np.nan, np.nan, 0)  # an unlabelled wrist: skipped
        images = [im[:60, :] if k % 2 else im for k, im in enumerate(train[:20])]
        model = PictorialStructures(ARM, cell=4, random_state=0).fit(images, kp)
        pred = model.predict([test[0], test[1][:48, :56]])
        assert pred.shape == (2, 3, 2)
        assert np.linalg.norm(pred[0] - ktest[0, :, :2], axis=1).max() < 6.5

    def test_scikit_learn_clone(self, arm_model):
        base = pytest.importorskip("sklearn.base")
        twin = base.clone(arm_model)
        ours, theirs = twin.get_params(), arm_model.get_params()
        assert ours.keys() == theirs.keys()
        assert ours.pop("skeleton").to_dict() == theirs.pop("skeleton").to_dict()
        assert ours == theirs
        assert not hasattr(twin, "coef_")
        assert "cell=4" in repr(arm_model)
        with pytest.raises(InputError, match="no parameter 'sigma'"):
            twin.set_params(sigma=1)

    def test_not_fitted(self):
        model = PictorialStructures(ARM)
        with pytest.raises(NotFittedError, match="not fitted yet"):
            model.predict(np.zeros((1, 16, 16, 3)))
        with pytest.raises(NotFittedError, match="not fitted yet"):
            model.predict_costs(np.zeros((16, 16, 3)))

    def test_bad_inputs(self, arms):
        (train, ktrain), _ = arms
        images, kp = train[:4], ktrain[:4]
        with pytest.raises(InputError, match="keypoints must be"):
            PictorialStructures(ARM).fit(images, kp[:3])
        with pytest.raises(InputError, match="keypoints must be"):
            PictorialStructures(ARM).fit(images, kp[:, :2])
        with pytest.raises(InputError, match="labelled keypoints"):
            bad = kp.copy()
            bad[0, 0, 0] = np.nan
            PictorialStructures(ARM).fit(images, bad)
        with pytest.raises(InputError, match="skeleton must be"):
            PictorialStructures("arm").fit(images, kp)
        loop = Skeleton("loop", ["a", "b", "c"], [(0, 1), (1, 2), (2, 0)], [])
        with pytest.raises(InputError, match="do not form a tree"):
            PictorialStructures(loop).fit(images, kp)
        with pytest.raises(InputError, match="wrap it in a list"):
            PictorialStructures(ARM).fit(images[0], kp[:1])
        with pytest.raises(InputError, match="at least one image"):
            PictorialStructures(ARM).fit([], kp[:0])
        with pytest.raises(InputError, match="n_negatives must be >= 1"):
            PictorialStructures(ARM, n_negatives=0).fit(images, kp)
        with pytest.raises(InputError, match="C must be"):
            PictorialStructures(ARM, C=-1.0).fit(images, kp)
        with pytest.raises(InputError, match="smaller than one 128x128 cell"):
            PictorialStructures(ARM, cell=128).fit(images, kp)

    def test_degenerate_labels(self, arms):
        (train, ktrain), _ = arms
        kp = ktrain[:4].copy()
        kp[:, 2, 2] = 0  # the wrist is never labelled
        with pytest.raises(DegenerateError, match="never labelled together"):
            PictorialStructures(ARM).fit(train[:4], kp)
        kp = ktrain[:4].copy()
        kp[:, 2, :2] = -50  # the wrist is always outside the image
        with pytest.raises(DegenerateError, match="never labelled inside the images"):
            PictorialStructures(ARM).fit(train[:4], kp)


# ==================================================================== real data


def mpii_crops(size: int = 128):
    """The five MPII people of mmpose's test set, cropped square around ``center``
    (side 1.25 x 200 x ``scale`` px, MPII's person-size convention) and resized."""
    from PIL import Image

    from robopercept.imaging import read_image

    root = data_path("detection", "mpii_keypoints_mmpose")
    images, keypoints = [], []
    for ann in json.loads((root / "test_mpii.json").read_text()):
        img = read_image(root / ann["image"])
        side = round(200 * ann["scale"] * 1.25)
        x0, y0 = (round(c - side / 2) for c in ann["center"])
        crop = Image.fromarray(img).crop((x0, y0, x0 + side, y0 + side))
        images.append(np.asarray(crop.resize((size, size), Image.BILINEAR)) / 255.0)
        xy = (np.array(ann["joints"]) - [x0, y0] + 0.5) * size / side - 0.5
        keypoints.append(np.c_[xy, 2 * np.array(ann["joints_vis"])])
    return np.stack(images), np.stack(keypoints)


@pytest.mark.realdata
def test_mpii_people():
    """Real photographs, MPII-16: the learned springs point the way bodies do, and the
    model recovers the poses it was fitted on (a smoke test: five people are too few
    to hold any out)."""
    images, kp = mpii_crops()
    model = PictorialStructures(MPII_16, cell=4, root="pelvis", random_state=0)
    model.fit(images, kp)
    off = dict(zip(MPII_16.joints, model.offsets_, strict=True))
    assert off["head_top"][1] < 0 and off["upper_neck"][1] < 0  # up the spine
    assert off["right_knee"][1] > 0 and off["left_ankle"][1] > 0  # down the legs
    pred = model.predict(images)
    labelled = kp[..., 2] > 0
    err = np.linalg.norm(pred - kp[..., :2], axis=2)[labelled]
    # a 128-px crop: heads are ~16 px, so 8 px is PCKh@0.5; measured 0.84
    assert np.mean(err <= 8.0) >= 0.7
