"""SIFT: a Gaussian blob by hand, parity with cv2.SIFT (keypoints and descriptors),
the Oxford affine evaluation against ground-truth homographies, invariances, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

from robopercept.errors import InputError
from robopercept.features import Features, match_descriptors, sift
from robopercept.imaging import read_image, transform_points
from tests.conftest import data_path

OXFORD = ("graf", "boat", "bikes", "leuven", "ubc", "bark")


def _cv_sift(gray: np.ndarray):
    kp, desc = cv2.SIFT_create().detectAndCompute(gray, None)
    xy = np.array([k.pt for k in kp]).reshape(-1, 2) - 0.25  # OpenCV's quarter-pixel shift
    size = np.array([k.size for k in kp])
    ang = np.array([k.angle for k in kp])
    return xy, size, ang, desc


def _homography(name: str, n: int) -> np.ndarray:
    path = data_path("features", "oxford_affine", name, f"H1to{n}p.xml")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    return fs.getNode(f"H1{n}").mat()


@pytest.mark.parametrize("s", [4.0, 6.0, 10.0])
def test_gaussian_blob_position_and_scale(s):
    # a Gaussian blob of std s is a DoG extremum at its centre; the scale-normalized
    # Laplacian peaks at sigma = s, and the DoG between sigma and k sigma samples it at
    # their geometric mean, so the reported sigma = size / 2 is s / 2^(1/6)
    y, x = np.mgrid[0:101, 0:101]
    img = (np.exp(-((x - 50.3) ** 2 + (y - 49.6) ** 2) / (2 * s * s)) * 200 / 255).astype(
        np.float32
    )
    kp = sift(img).keypoints
    i = np.argmin(np.hypot(kp.xy[:, 0] - 50.3, kp.xy[:, 1] - 49.6))
    assert np.hypot(*(kp.xy[i] - [50.3, 49.6])) < 0.15
    np.testing.assert_allclose(kp.scale[i] / 2 * 2 ** (1 / 6), s, rtol=0.03)
    # the octave holds that scale: sigma = 1.6 * 2^octave * 2^(l / 3), l in [0.5, 3.5]
    # (DoG layers 1..3, refined by at most half a layer)
    level = 3 * np.log2(kp.scale[i] / 2 / 1.6 / 2.0 ** kp.octave[i])
    assert 0.5 - 1e-6 <= level <= 3.5 + 1e-6


def _paired(ours: Features, ref):
    # pair each of our keypoints with OpenCV's at the same position, size and angle
    xy, size, ang, _ = ref
    tree = cKDTree(xy)
    pairs = tree.query_ball_point(ours.keypoints.xy, 0.01)
    deg = np.rad2deg(ours.keypoints.orientation)
    found = np.full(len(ours), -1)
    for i, cand in enumerate(pairs):
        for j in cand:
            da = abs((ang[j] - deg[i] + 180) % 360 - 180)
            if da < 0.01 and abs(size[j] - ours.keypoints.scale[i]) < 1e-3:
                found[i] = j
                break
    return found


def test_parity_with_opencv_on_camera(camera):
    # the same pipeline in float32: the same keypoints (position, size, angle) and
    # descriptors within one unit of 0..255 (a rounding of the final scaling)
    ours = sift(camera)
    ref = _cv_sift(camera)
    assert abs(len(ours) - len(ref[0])) <= 0.002 * len(ref[0])
    found = _paired(ours, ref)
    assert np.mean(found >= 0) > 0.99
    ok = found >= 0
    diff = np.abs(ours.descriptors[ok] - ref[3][found[ok]])
    assert diff.max() <= 1.0
    assert np.mean(diff == 0) > 0.99


@pytest.mark.realdata
def test_parity_with_opencv_on_graf(graf):
    gray = cv2.cvtColor(graf, cv2.COLOR_RGB2GRAY)
    ours = sift(gray)
    ref = _cv_sift(gray)
    found = _paired(ours, ref)
    assert np.mean(found >= 0) > 0.99
    assert ours.descriptors.dtype == np.float32 and ours.descriptors.shape[1] == 128


@pytest.mark.realdata
@pytest.mark.parametrize("name", OXFORD)
def test_oxford_affine_matches_against_ground_truth(name):
    # the issue's acceptance: ratio test 0.8; a match is correct when the true
    # homography puts it within 3 px; ours >= 90% of OpenCV's correct matches and
    # precision within 5 points, on pairs 1->2 and 1->3
    root = ("features", "oxford_affine", name)
    g1 = read_image(data_path(*root, "img1.png"), mode="gray")
    f1, r1 = sift(g1), _cv_sift(g1)
    bf = cv2.BFMatcher()
    for n in (2, 3):
        g2 = read_image(data_path(*root, f"img{n}.png"), mode="gray")
        f2, r2 = sift(g2), _cv_sift(g2)
        h = _homography(name, n)
        m = match_descriptors(f1.descriptors, f2.descriptors, ratio=0.8)
        err = np.linalg.norm(
            transform_points(h, f1.keypoints.xy[m.query_idx]) - f2.keypoints.xy[m.train_idx],
            axis=1,
        )
        cm = [a for a, b in bf.knnMatch(r1[3], r2[3], k=2) if a.distance < 0.8 * b.distance]
        q = np.array([a.queryIdx for a in cm])
        t = np.array([a.trainIdx for a in cm])
        # OpenCV's own positions (with its quarter-pixel shift on both images)
        cerr = np.linalg.norm(transform_points(h, r1[0][q] + 0.25) - (r2[0][t] + 0.25), axis=1)
        ours_ok, ref_ok = int((err < 3).sum()), int((cerr < 3).sum())
        assert ours_ok >= 0.9 * ref_ok, (name, n, ours_ok, ref_ok)
        assert (err < 3).mean() >= (cerr < 3).mean() - 0.05, (name, n)


def test_rotation_invariance(camera):
    # a 90-degree rotation: most keypoints reappear at the rotated position and their
    # descriptors match (the orientation assignment undoes the rotation)
    a = sift(camera)
    b = sift(np.ascontiguousarray(np.rot90(camera)))  # (x, y) -> (y, W - 1 - x)
    m = match_descriptors(a.descriptors, b.descriptors, ratio=0.8)
    xy = a.keypoints.xy[m.query_idx]
    expect = np.stack([xy[:, 1], camera.shape[1] - 1 - xy[:, 0]], axis=1)
    err = np.linalg.norm(expect - b.keypoints.xy[m.train_idx], axis=1)
    assert len(m.query_idx) > 0.5 * len(a)
    assert np.mean(err < 1.0) > 0.95


def test_flat_image_has_no_keypoints():
    f = sift(np.full((64, 64), 128, np.uint8))
    assert len(f) == 0
    assert f.keypoints.xy.shape == (0, 2) and f.descriptors.shape == (0, 128)


def test_options_dtype_and_determinism(camera):
    a = sift(camera)
    b = sift(camera, descriptor_dtype=np.uint8)
    assert b.descriptors.dtype == np.uint8
    np.testing.assert_array_equal(a.descriptors, b.descriptors.astype(np.float32))
    np.testing.assert_array_equal(a.keypoints.xy, sift(camera).keypoints.xy)
    # strongest first; n_features keeps the strongest
    assert np.all(np.diff(a.keypoints.response) <= 0)
    top = sift(camera, n_features=100)
    assert len(top) >= 100 and top.keypoints.response.min() >= a.keypoints.response[99]
    np.testing.assert_allclose(top.keypoints.response[:100], a.keypoints.response[:100])
    # descriptors are unit-free: float [0, 1] input equals uint8
    c = sift(camera.astype(np.float32) / 255)
    assert abs(len(c) - len(a)) <= 0.002 * len(a)
    # no doubling: fewer, larger keypoints
    d = sift(camera, upsample=False)
    assert len(d) < len(a) and d.keypoints.octave.min() == 0


def test_bad_input():
    with pytest.raises(InputError, match="at least 6x6"):
        sift(np.zeros((5, 40), np.uint8))
    with pytest.raises(InputError, match="at least 12x12 pixels without upsample"):
        sift(np.zeros((10, 40), np.uint8), upsample=False)
    with pytest.raises(InputError, match="descriptor_dtype"):
        sift(np.zeros((40, 40), np.uint8), descriptor_dtype=np.int16)
    with pytest.raises(InputError, match="n_features"):
        sift(np.zeros((40, 40), np.uint8), n_features=-1)


def test_rows_fuller_than_the_parallel_store(monkeypatch):
    # a row of 32 blobs puts up to 31 extrema on one scan row, more than the parallel
    # scan keeps per row (16): those rows are rescanned, with the same result as a
    # store large enough for all of them
    import importlib

    # (the package's `sift` attribute is the function, so fetch the module by name)
    sift_module = importlib.import_module("robopercept.features.sift")

    y, x = np.mgrid[0:40, 0:400]
    gain = np.random.default_rng(1).uniform(0.5, 1, 32)
    img = sum(
        g * np.exp(-((x - cx) ** 2 + (y - 20) ** 2) / (2 * 1.5**2))
        for g, cx in zip(gain, range(10, 390, 12), strict=True)
    )
    img = (img / img.max() * 255).astype(np.uint8)
    small = sift(img)
    monkeypatch.setattr(sift_module, "_ROW_CAP", 1000)
    large = sift(img)
    assert len(small) > 100
    np.testing.assert_array_equal(small.keypoints.xy, large.keypoints.xy)
    np.testing.assert_array_equal(small.descriptors, large.descriptors)


# issue 25: a contrast_threshold near 1e225 (or 2**63) overflowed the integer threshold,
# None raised TypeError, and n_octave_layers or sigma had no bound on the pyramid they
# build; each is now refused with an InputError, and a huge finite threshold finds nothing
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"contrast_threshold": None}, "contrast_threshold must be a real number"),
        ({"contrast_threshold": np.nan}, "contrast_threshold must be finite"),
        ({"edge_threshold": "3"}, "edge_threshold must be a real number"),
        ({"n_octave_layers": 2**40}, "n_octave_layers must be at most 32"),
        ({"sigma": 2.0**40}, "sigma must be at most the image's larger side"),
        ({"upsample": "yes"}, "upsample must be True or False"),
    ],
)
def test_issue25_hostile_parameters_are_input_errors(kwargs, match):
    with pytest.raises(InputError, match=match):
        sift(np.zeros((32, 32), np.uint8), **kwargs)


def test_issue25_huge_contrast_threshold_finds_no_keypoint():
    img = np.zeros((64, 64), np.uint8)
    img[20:44, 20:44] = 255
    assert len(sift(img).keypoints) > 0
    for c in (2.1e225, 2**63):
        f = sift(img, contrast_threshold=c)
        assert len(f.keypoints) == 0 and f.descriptors.shape == (0, 128)


# issue 48: kp, des = sift(img) and kp[i] as cv2.KeyPoint
def test_unpacks_as_detect_and_compute_and_records_match_cv2_keypoints(camera):
    """``kp, des = sift(img)`` as ``detectAndCompute``; ``kp[i]`` carries OpenCV's
    ``KeyPoint`` values for the same keypoint: pt (ours + OpenCV's 0.25 shift, 1e-2 px,
    the pairing radius), angle in degrees (0.01 deg: OpenCV's float32 angle through our
    float64 radians), size (1e-3), response (1e-4 relative) and octave (OpenCV's packed
    octave read as a signed byte). Attribute access stays."""
    features = sift(camera)
    kp, des = features
    assert kp is features.keypoints and des is features.descriptors
    assert des.shape == (len(kp), 128) and len(features) == len(kp)
    ck, _ = cv2.SIFT_create().detectAndCompute(camera, None)
    tree = cKDTree(np.array([k.pt for k in ck]) - 0.25)
    checked = 0
    for rec in list(kp)[:200]:
        for j in tree.query_ball_point(rec.pt, 0.01):
            c = ck[j]
            if (
                abs((c.angle - rec.angle + 180) % 360 - 180) < 0.01
                and abs(c.size - rec.size) < 1e-3
            ):
                octave = (c.octave & 255) - 256 * ((c.octave & 255) >= 128)
                assert rec.octave == octave
                assert rec.response == pytest.approx(c.response, rel=1e-4)
                assert 0 <= rec.angle < 360
                checked += 1
                break
    assert checked >= 0.99 * 200
    assert kp[0].pt == tuple(kp.xy[0].tolist())
    assert kp[0].angle == pytest.approx(np.rad2deg(kp.orientation[0]) % 360)


def test_unpacking_an_empty_result():
    kp, des = sift(np.zeros((32, 32), np.uint8))
    assert len(kp) == 0 and des.shape == (0, 128) and list(kp) == []
