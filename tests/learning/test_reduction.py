"""PCA and LDA: hand cases, parity with scikit-learn, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError, NotFittedError
from robopercept.learning import LDA, PCA


def test_pca_of_a_line_has_one_component():
    t = np.linspace(-1, 1, 11)
    X = np.c_[3 * t + 1, 4 * t - 2]  # along (3, 4) / 5
    pca = PCA().fit(X)
    np.testing.assert_allclose(pca.components_[0], [0.6, 0.8], atol=1e-12)
    np.testing.assert_allclose(pca.explained_variance_ratio_, [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pca.explained_variance_[0], 25 * np.var(t, ddof=1), rtol=1e-12)
    Z = pca.transform(X)
    np.testing.assert_allclose(pca.inverse_transform(Z), X, atol=1e-12)


@pytest.mark.parametrize("name,k", [("iris", None), ("digits", 10), ("digits", 0.9)])
def test_pca_matches_sklearn(request, name, k):
    """Components equal up to sign (here the sign rule is the same, so equal) to 1e-8:
    both are exact eigenvectors; the differences are rounding (~1e-14)."""
    from sklearn.decomposition import PCA as SkPCA

    X, _ = request.getfixturevalue(name)
    ours = PCA(k).fit(X)
    ref = SkPCA(k, svd_solver="full").fit(X)
    assert ours.n_components_ == ref.n_components_
    np.testing.assert_allclose(ours.components_, ref.components_, atol=1e-8)
    np.testing.assert_allclose(ours.explained_variance_, ref.explained_variance_, rtol=1e-10)
    np.testing.assert_allclose(ours.explained_variance_ratio_, ref.explained_variance_ratio_)
    np.testing.assert_allclose(ours.transform(X), ref.transform(X), atol=1e-8)


def test_pca_standardize_is_pca_of_standardized_data(iris):
    from sklearn.decomposition import PCA as SkPCA
    from sklearn.preprocessing import StandardScaler

    X, _ = iris
    ours = PCA(2, standardize=True).fit(X)
    ref = SkPCA(2).fit(StandardScaler().fit_transform(X))
    np.testing.assert_allclose(ours.components_, ref.components_, atol=1e-10)


def test_pca_bad_input(iris):
    X, _ = iris
    with pytest.raises(InputError, match="n_components"):
        PCA(7).fit(X)
    with pytest.raises(InputError, match="fraction"):
        PCA(1.5).fit(X)
    with pytest.raises(NotFittedError, match="fit"):
        PCA().transform(X)
    bad = X.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        PCA().fit(bad)
    with pytest.raises(InputError, match="features"):
        PCA(2).fit(X).transform(X[:, :3])


def test_lda_two_gaussians_direction():
    """Two classes with covariance diag(1, 100), means apart along x and y: Fisher's
    direction is S_W^-1 (m1 - m0) ∝ (1, 0.01) (for a (1, 1) mean difference)."""
    gen = np.random.default_rng(0)
    a = gen.normal(size=(4000, 2)) * [1, 10]
    b = gen.normal(size=(4000, 2)) * [1, 10] + [1, 1]
    X = np.r_[a, b]
    y = np.r_[np.zeros(4000), np.ones(4000)]
    w = LDA().fit(X, y).scalings_[:, 0]
    w = w / w[0]
    assert abs(w[1] - 0.01) < 0.003


@pytest.mark.parametrize("name", ["iris", "digits"])
def test_lda_matches_sklearn_eigen(request, name):
    """Projections equal sklearn's eigen solver up to sign and scale per axis (the ratio
    of the two, column by column, is constant to 1e-9); predictions identical.
    Digits' constant pixels make S_W singular, where sklearn's eigen solver fails, so
    the comparison drops them."""
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

    X, y = request.getfixturevalue(name)
    X = X[:, X.std(axis=0) > 0]
    ours = LDA().fit(X, y)
    ref = LinearDiscriminantAnalysis(solver="eigen").fit(X, y)
    assert ours.shrinkage_ == 0
    za = ours.transform(X)
    zb = ref.transform(X)
    zb = zb - zb.mean(axis=0)  # sklearn's eigen transform does not centre
    ratio = za / zb
    spread = ratio.std(axis=0) / np.abs(ratio.mean(axis=0))
    assert spread.max() < 1e-9
    assert za.shape[1] == np.unique(y).size - 1
    np.testing.assert_array_equal(ours.predict(X), ref.predict(X))
    np.testing.assert_allclose(ours.predict_proba(X), ref.predict_proba(X), atol=1e-8)


def test_lda_singular_scatter_is_regularized(digits):
    X, y = digits  # constant pixels: S_W singular
    lda = LDA(n_components=2).fit(X, y)
    assert lda.shrinkage_ > 0
    assert lda.transform(X).shape == (X.shape[0], 2)
    assert lda.score(X, y) > 0.95


def test_lda_bad_input(iris):
    X, y = iris
    with pytest.raises(InputError, match="at least 2 classes"):
        LDA().fit(X, np.zeros(len(y)))
    with pytest.raises(InputError, match="n_components"):
        LDA(n_components=3).fit(X, y)
    with pytest.raises(NotFittedError):
        LDA().predict(X)


# issue 25: data near 1e300 raised NumPy's LinAlgError ("Eigenvalues did not
# converge"), near 1e-300 gave explained_variance_ratio_ [0, 0]; refused with a typed
# error. At 1e140 the components are those of the rescaled data
@pytest.mark.parametrize("scale", [1e300, 1e160, 1e-300])
def test_pca_refuses_data_whose_squares_overflow(scale):
    X = np.random.default_rng(0).normal(size=(40, 3))
    with pytest.raises(InputError, match="rescale your data"):
        PCA(2).fit(X * scale)
    with pytest.raises(InputError, match="X has values up to"):
        PCA(2).fit(X).transform(X * 1e300)
    a, b = PCA(2).fit(X), PCA(2).fit(X * 1e140)
    np.testing.assert_allclose(b.components_, a.components_, atol=1e-9)
    np.testing.assert_allclose(b.explained_variance_ratio_, a.explained_variance_ratio_)


# issue 25: n_components and shrinkage reached int()/float() unchecked, standardize a
# truth test, and LDA's scatter matrices overflowed for data near 1e300
_X = np.random.default_rng(25).normal(size=(30, 3))
_Y = np.repeat([0, 1, 2], 10)


@pytest.mark.parametrize(
    ("make", "X", "match"),
    [
        (lambda: LDA(n_components=np.nan), _X, "n_components \\(or None\\) must be an integer"),
        (lambda: LDA(n_components=[1, 2]), _X, "n_components"),
        (lambda: LDA(shrinkage="bogus"), _X, "shrinkage \\(or None\\) must be a real number"),
        (lambda: LDA(shrinkage=1 + 1j), _X, "shrinkage"),
        (lambda: LDA(), _X * 1e300, "X has values up to"),
        (lambda: PCA(standardize=np.eye(3)), _X, "standardize must be True or False"),
    ],
)
def test_hostile_hyperparameters_are_refused_at_fit(make, X, match):
    with pytest.raises(InputError, match=match):
        make().fit(X, _Y)


def test_lda_edge_shrinkage_and_components_still_fit():
    lda = LDA(n_components=2, shrinkage=1.0).fit(_X, _Y)
    assert lda.transform(_X).shape == (30, 2) and lda.shrinkage_ == 1.0
