"""HOG + linear SVM detector: NMS, persistence, cross-validated accuracy on lfw_subset."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError, NotFittedError
from robopercept.learning.hog_detector import (
    HogDetector,
    box_iou,
    default_face_detector,
    face_training_data,
    non_max_suppression,
    train_face_detector,
)
from robopercept.learning.model_selection import cross_val_score
from robopercept.learning.svm import LinearSVC


def test_iou_and_nms_hand_case():
    boxes = np.array([[0, 0, 10, 10], [1, 0, 10, 10], [20, 20, 5, 5], [0, 0, 10, 10.0]])
    np.testing.assert_allclose(box_iou(boxes[0], boxes[:3]), [1, 90 / 110, 0])
    keep = non_max_suppression(boxes, [0.9, 0.95, 0.5, 0.1], iou=0.3)
    np.testing.assert_array_equal(keep, [1, 2])  # 0 and 3 overlap the better box 1
    assert non_max_suppression(np.zeros((0, 4)), []).size == 0
    with pytest.raises(InputError, match="scores"):
        non_max_suppression(boxes, [1.0])


def test_hog_svm_cross_validated_accuracy_on_lfw_subset():
    """Real faces vs non-faces (scikit-image's lfw_subset): 5-fold accuracy >= 0.9, with
    the shipped model's HOG (signed, 18 bins) and the plain unsigned 9-bin one."""
    patches, labels = face_training_data()
    for det in (HogDetector(orientations=18, signed=True, C=1.0), HogDetector(C=0.1)):
        X = det.describe(patches)
        svm = LinearSVC(C=det.C, random_state=0)
        assert cross_val_score(svm, X, labels, cv=5).mean() >= 0.9
        precision = cross_val_score(svm, X, labels, cv=5, scoring="precision")
        recall = cross_val_score(svm, X, labels, cv=5, scoring="recall")
        assert precision.mean() > 0.85 and recall.mean() > 0.85


ASTRONAUT_FACE = np.array([165, 70, 100, 120.0])  # x, y, w, h, read off the picture


def test_shipped_face_model_finds_the_astronauts_face_with_few_false_boxes(astronaut):
    """The acceptance items (issue 30): at the model's default threshold (chosen on the
    held-out PR curve) the face is found and at most 2 boxes are not the face (18 at
    the old threshold 0). Measured: 3 boxes, the face 2nd (score 1.25) after the
    mission patch on her sleeve (1.47)."""
    found = default_face_detector().detect(astronaut)
    assert 1 <= len(found) <= 3, found.scores
    face = box_iou(ASTRONAUT_FACE, found.boxes) > 0.5
    assert face.any() and (~face).sum() <= 2, (found.boxes, found.scores)


def test_training_reproduces_the_shipped_model():
    """train_face_detector() with its defaults gives the bundled weights (seeded, so
    exactly: the hard negatives and the SVM's coordinate order are drawn from random_state=0),
    and its cross-validated accuracy is >= 0.9."""
    det, cv = train_face_detector(random_state=0)
    shipped = default_face_detector()
    np.testing.assert_allclose(det.coef_, shipped.coef_, atol=1e-9)
    assert det.intercept_ == pytest.approx(shipped.intercept_, abs=1e-9)
    assert cv["accuracy"] >= 0.9 and cv["recall"] >= 0.9


def test_detector_finds_a_trained_pattern_and_round_trips(tmp_path):
    """A bright disc on noise: trained on 24x24 discs, it finds a 48-px disc placed in a
    larger image at the right place and size; save/load gives the same scores."""
    gen = np.random.default_rng(0)
    yy, xx = np.mgrid[:24, :24]
    disc = ((yy - 11.5) ** 2 + (xx - 11.5) ** 2 < 8**2).astype(float)
    pos = np.clip(disc * 0.8 + gen.normal(0.1, 0.05, (60, 24, 24)), 0, 1)
    neg = np.clip(gen.normal(0.3, 0.15, (60, 24, 24)), 0, 1)
    det = HogDetector().fit(np.r_[pos, neg], np.r_[np.ones(60), np.zeros(60)])
    image = np.clip(gen.normal(0.3, 0.05, (160, 200)), 0, 1)
    big = np.kron(disc, np.ones((2, 2)))
    image[60:108, 100:148] = np.clip(image[60:108, 100:148] + big * 0.6, 0, 1)
    found = det.detect(image, threshold=0.0)
    assert len(found) >= 1
    assert box_iou(np.array([100, 60, 48, 48.0]), found.boxes[:1])[0] > 0.5
    path = tmp_path / "model.npz"
    det.save(path)
    again = HogDetector.load(path)
    np.testing.assert_allclose(again.score_patches(pos[:5]), det.score_patches(pos[:5]))


def test_detector_bad_input(tmp_path):
    with pytest.raises(NotFittedError):
        HogDetector().detect(np.zeros((50, 50)))
    with pytest.raises(InputError, match="patches"):
        HogDetector().describe(np.zeros((3, 20, 20)))
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(FileFormatError, match="HOG model"):
        HogDetector.load(bad)


# issue 25: HogDetector.load let BadZipFile, EOFError, KeyError, ValueError, zlib.error,
# tokenize errors... through on corrupt .npz files; every damaged file is now refused
# with a FileFormatError naming it


def _shipped_model_bytes():
    from importlib import resources

    return (resources.files("robopercept") / "data" / "face_hog_svm.npz").read_bytes()


def test_mutated_model_files_load_or_are_refused_by_name(tmp_path):
    """300 seeded mutants of the shipped model (bit flips, truncations, zeroed runs,
    0xFF runs): each loads a detector with the shipped shape or raises FileFormatError
    naming the file, nothing else (most of them raised BadZipFile before)."""
    data = _shipped_model_bytes()
    shipped = default_face_detector()
    gen = np.random.default_rng(25)
    path = tmp_path / "mutant.npz"
    outcomes = {"loaded": 0, "refused": 0}
    for k in range(300):
        m = bytearray(data)
        kind = k % 4
        at = int(gen.integers(len(m)))
        if kind == 0:
            for _ in range(int(gen.integers(1, 5))):
                i = int(gen.integers(len(m)))
                m[i] ^= 1 << int(gen.integers(8))
        elif kind == 1:
            m = m[:at]
        else:
            n = int(gen.integers(1, 33))
            m[at : at + n] = (b"\x00" if kind == 2 else b"\xff") * len(m[at : at + n])
        path.write_bytes(bytes(m))
        try:
            det = HogDetector.load(path)
        except FileFormatError as exc:
            assert "mutant.npz" in str(exc)
            outcomes["refused"] += 1
        else:
            assert det.coef_.shape == shipped.coef_.shape
            assert np.isfinite(det.coef_).all() and np.isfinite(det.intercept_)
            outcomes["loaded"] += 1
    assert outcomes["refused"] > 200  # the mutants do break the file


def _save_model(path, coef, meta, compressed=False):
    import json

    save = np.savez_compressed if compressed else np.savez
    save(path, coef=coef, meta=np.array(json.dumps(meta)))


def test_crafted_model_files_are_refused(tmp_path):
    det = default_face_detector()
    meta = {"kind": "robopercept.HogDetector", "window": list(det.window),
            "cell_size": det.cell_size, "block_size": det.block_size,
            "orientations": det.orientations, "signed": det.signed, "C": det.C,
            "intercept": det.intercept_}  # fmt: skip
    # the same model compressed loads, with the same weights
    _save_model(tmp_path / "z.npz", det.coef_, meta, compressed=True)
    again = HogDetector.load(tmp_path / "z.npz")
    assert np.array_equal(again.coef_, det.coef_) and again.intercept_ == det.intercept_
    cases = {
        "pickle": (np.array([object()] * 3, dtype=object), meta, "pickles"),
        "complex": (det.coef_ + 1j, meta, "finite real numbers"),
        "nan": (np.r_[np.nan, det.coef_[1:]], meta, "finite real numbers"),
        "short": (det.coef_[:-1], meta, "weights have shape"),
        "huge_window": (det.coef_, {**meta, "window": [10**9, 24]}, "window width"),
        "bool_cell": (det.coef_, {**meta, "cell_size": True}, "cell_size is True"),
        "float_orient": (det.coef_, {**meta, "orientations": 9.5}, "orientations is 9.5"),
        "nan_C": (det.coef_, {**meta, "C": float("nan")}, "C is nan"),
        "inf_b": (det.coef_, {**meta, "intercept": float("inf")}, "intercept is inf"),
        "kind": (det.coef_, {**meta, "kind": "other"}, "kind is 'other'"),
        "window": (det.coef_, {**meta, "window": 24}, "window is 24"),
    }
    for name, (coef, m, match) in cases.items():
        if name == "pickle":
            np.savez(tmp_path / f"{name}.npz", coef=coef, meta=np.array("{}"))
        else:
            _save_model(tmp_path / f"{name}.npz", coef, m)
        with pytest.raises(FileFormatError, match=match) as info:
            HogDetector.load(tmp_path / f"{name}.npz")
        assert f"{name}.npz" in str(info.value)
    np.save(tmp_path / "one.npy", det.coef_)
    with pytest.raises(FileFormatError, match=r"one \.npy array, not an archive"):
        HogDetector.load(tmp_path / "one.npy")
    np.savez(tmp_path / "nometa.npz", coef=det.coef_)
    with pytest.raises(FileFormatError, match="no 'meta' array"):
        HogDetector.load(tmp_path / "nometa.npz")
    # an NPY header that claims 10^12 weights, in a sound zip (right CRC), is refused
    # before anything is allocated
    import io
    import json
    import zipfile

    from numpy.lib import format as npy

    lie = io.BytesIO()
    npy.write_array_header_1_0(lie, {"descr": "<f8", "fortran_order": False,
                                     "shape": (10**12,)})  # fmt: skip
    lie.write(det.coef_.tobytes())
    meta_npy = io.BytesIO()
    np.save(meta_npy, np.array(json.dumps(meta)))
    with zipfile.ZipFile(tmp_path / "lie.npz", "w") as z:
        z.writestr("coef.npy", lie.getvalue())
        z.writestr("meta.npy", meta_npy.getvalue())
    with pytest.raises(FileFormatError, match=r"header says 1000000000000 x 8 bytes"):
        HogDetector.load(tmp_path / "lie.npz")


@pytest.mark.parametrize("word", [0x7FFFFFFF, 0x80000000])
def test_huge_stated_member_sizes_cost_no_memory(tmp_path, word):
    """Issue 25, long fuzz campaign: a model file whose zip entries state a 2 GiB
    compressed size made ZipFile.read allocate 1 GiB before the short read came back
    (6 kB file); now refused by name, with a small peak."""
    import struct
    import tracemalloc

    m = bytearray(_shipped_model_bytes())
    # every central-directory entry (PK\x01\x02): compressed size at offset 20
    at = 0
    while (at := m.find(b"PK\x01\x02", at)) >= 0:
        m[at + 20 : at + 24] = struct.pack("<I", word)
        at += 4
    path = tmp_path / "huge.npz"
    path.write_bytes(bytes(m))
    tracemalloc.start()
    try:
        with pytest.raises(FileFormatError, match=r"huge\.npz"):
            HogDetector.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * 2**20, peak


# issue 30: the default threshold comes from a held-out precision/recall curve and is
# stored with the model


def test_choose_threshold_on_a_hand_made_score_list():
    """Five faces, five non-faces. By hand: at score >= 0.6 all 5 faces and the
    non-face at 0.7 are in: P = 5/6, R = 1, F1 = 10/11 = 0.909, the best F1 (>= 0.8:
    P = 4/5, R = 4/5, F1 0.8; >= 1.0: 3/4 ... no: P = 1, R = 0.6, F1 0.75). The
    threshold is the midpoint to the next lower score, (0.6 + 0.3) / 2. Precision
    >= 0.95 first holds at >= 0.8 (P = 1, R = 0.8): threshold (0.8 + 0.7) / 2."""
    from robopercept.errors import DegenerateError
    from robopercept.learning.hog_detector import choose_threshold
    from robopercept.learning.metrics import precision_recall_curve

    labels = [1, 1, 1, 1, 1, 0, 0, 0, 0, 0]
    scores = [2.0, 1.5, 1.0, 0.8, 0.6, 0.7, 0.3, 0.1, -0.5, -1.0]
    c = choose_threshold(labels, scores)
    assert c.rule == "f1" and c.score == 0.6 and c.threshold == pytest.approx(0.45)
    assert c.precision == pytest.approx(5 / 6) and c.recall == 1.0
    assert c.f1 == pytest.approx(10 / 11)
    assert (c.n_positive, c.n_negative) == (5, 5)
    p, r, t = precision_recall_curve(labels, scores)
    np.testing.assert_array_equal(c.curve_thresholds, t)
    np.testing.assert_array_equal(c.curve_precision, p)
    np.testing.assert_array_equal(c.curve_recall, r)
    # "score > threshold" keeps exactly the examples the chosen point counts as positive
    s = np.asarray(scores)
    assert np.array_equal(s > c.threshold, s >= c.score)
    c = choose_threshold(labels, scores, rule="precision", min_precision=0.95)
    assert c.score == 0.8 and c.threshold == pytest.approx(0.75)
    assert (c.precision, c.recall) == (1.0, 0.8)
    c = choose_threshold(labels, scores, rule="precision", min_precision=0.8)
    assert c.score == 0.6 and c.recall == 1.0  # P = 0.833 >= 0.8 at the lowest score
    # the lowest score chosen: just below it
    c = choose_threshold([1, 1, 0], [0.5, 0.2, 0.9], rule="precision", min_precision=0.6)
    assert c.score == 0.2 and c.threshold < 0.2 and c.threshold > 0.2 - 1e-9
    with pytest.raises(DegenerateError, match=r"no threshold reaches precision 1\.0"):
        choose_threshold([1, 0], [0.0, 1.0], rule="precision", min_precision=1.0)
    with pytest.raises(InputError, match="both classes"):
        choose_threshold([1, 1], [0.0, 1.0])
    with pytest.raises(InputError, match="0 \\(background\\) or 1"):
        choose_threshold([2, 0], [0.0, 1.0])
    with pytest.raises(InputError, match="finite"):
        choose_threshold([1, 0], [np.nan, 1.0])
    with pytest.raises(InputError, match="one length"):
        choose_threshold([1, 0, 1], [0.0, 1.0])
    with pytest.raises(InputError, match="rule"):
        choose_threshold([1, 0], [0.0, 1.0], rule="auc")
    with pytest.raises(InputError, match="min_precision"):
        choose_threshold([1, 0], [0.0, 1.0], rule="precision", min_precision=0.0)


def test_threshold_is_saved_read_and_used_by_default(tmp_path):
    """detect() without a threshold uses the model's; save/load keeps it; a model file
    written before issue 30 (no threshold in its header) reads as threshold 0."""
    import json

    shipped = default_face_detector()
    assert shipped.threshold > 0  # chosen on the held-out PR curve, not the old 0
    gen = np.random.default_rng(0)
    image = gen.random((60, 80))
    shipped.threshold = -0.25
    path = tmp_path / "m.npz"
    shipped.save(path)
    again = HogDetector.load(path)
    assert again.threshold == -0.25
    by_default = again.detect(image)
    explicit = again.detect(image, threshold=-0.25)
    np.testing.assert_array_equal(by_default.scores, explicit.scores)
    assert (by_default.scores > -0.25).all()
    meta = {"kind": "robopercept.HogDetector", "window": [24, 24], "cell_size": 6,
            "block_size": 2, "orientations": 18, "signed": True, "C": 1.0,
            "intercept": 0.5}  # fmt: skip
    _save_model(tmp_path / "old.npz", shipped.coef_, meta)
    assert HogDetector.load(tmp_path / "old.npz").threshold == 0.0
    _save_model(tmp_path / "nan.npz", shipped.coef_, {**meta, "threshold": float("nan")})
    with pytest.raises(FileFormatError, match="threshold is nan"):
        HogDetector.load(tmp_path / "nan.npz")
    with pytest.raises(InputError, match="threshold"):
        again.detect(image, threshold="high")
    assert json.loads(str(np.load(path)["meta"]))["threshold"] == -0.25


def test_train_detector_from_folders(tmp_path):
    """Bright discs against noise pictures: the held-out discs are split off (2 of 8),
    the threshold is chosen on them, the report counts the unreadable files, and the
    bad folders are refused by name."""
    from robopercept.imaging import write_image
    from robopercept.learning.hog_detector import train_detector_from_folders

    gen = np.random.default_rng(1)
    yy, xx = np.mgrid[:30, :30]
    disc = ((yy - 14.5) ** 2 + (xx - 14.5) ** 2 < 100).astype(float)
    pos, neg = tmp_path / "pos", tmp_path / "neg"
    pos.mkdir()
    neg.mkdir()
    for i in range(8):
        img = np.clip(0.2 + 0.6 * disc + gen.normal(0, 0.05, disc.shape), 0, 1)
        write_image(pos / f"{i}.png", (255 * img).astype(np.uint8))
        write_image(neg / f"{i}.png", (255 * gen.random((60, 90))).astype(np.uint8))
    (neg / "bad.png").write_bytes(b"\x89PNG broken")
    det, report = train_detector_from_folders(pos, neg, mining_rounds=1, random_state=0)
    assert report["positives"] == 8 and report["negatives"] == 8
    assert len(report["skipped"]) == 1 and report["skipped"][0].startswith("neg/bad.png: ")
    assert report["choice"].n_positive == 4  # 2 held-out discs and their mirrors
    assert det.threshold == report["threshold"] == report["choice"].threshold
    assert report["heldout_recall"] == 1.0 and report["heldout_precision"] == 1.0
    again, _ = train_detector_from_folders(pos, neg, mining_rounds=1, random_state=0)
    np.testing.assert_array_equal(again.coef_, det.coef_)  # seeded
    det0, r0 = train_detector_from_folders(pos, neg, mining_rounds=0, holdout=0)
    assert r0["choice"] is None and det0.threshold == 0.0
    with pytest.raises(InputError, match=r"positives folder .* does not exist"):
        train_detector_from_folders(tmp_path / "absent", neg)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match=r"negatives folder .* holds no readable image"):
        train_detector_from_folders(pos, empty)
    one = tmp_path / "one"
    one.mkdir()
    write_image(one / "a.png", (255 * disc).astype(np.uint8))
    with pytest.raises(InputError, match="at least 2 positives"):
        train_detector_from_folders(one, neg)
    with pytest.raises(InputError, match="whole cells"):
        train_detector_from_folders(pos, neg, window=(25, 24))
    with pytest.raises(InputError, match="holdout"):
        train_detector_from_folders(pos, neg, holdout=0.75)
