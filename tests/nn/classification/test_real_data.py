"""Issue 23's real-data acceptance figures, each at CI cost (one seed or one fold).

The full figures (3 seeds, 5 folds, 20,000 pretraining images) come from
``python -m benchmarks.nn_figures``; these tests run the same code paths with the
benchmark's own recipes, smaller where noted, and assert the targets.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("sklearn")

from benchmarks.nn_figures import (  # noqa: E402
    digits_run,
    few_shot,
    lfw_cnn_accuracy,
    lfw_folds,
    lfw_hog_accuracy,
    pretrain_on_fonts,
)
from robopercept.nn.data.datasets import load_lfw_subset  # noqa: E402


@pytest.fixture(autouse=True)
def _two_threads():
    """The figures are for 2 threads, whatever an earlier test left (training with 1
    thread sums in another order: the sim-to-real margins move by up to 3 points);
    restore the thread count afterwards."""
    old = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(old)


def test_digits_resnet_small_matches_svc():
    """resnet_small (< 100k parameters) on digits, seed 0: >= 98.5% test accuracy,
    at most 0.5 points below SVC(gamma=0.001) on the same split. (The <= 60 s of
    training is a benchmark figure, not asserted: wall time on a shared CI machine is
    not a property of the code.)"""
    r = digits_run("resnet_small", seed=0)
    assert r["params"] <= 100_000
    assert r["accuracy"] >= 0.985, r
    assert r["accuracy"] >= r["svc_accuracy"] - 0.005, r


def test_lfw_one_fold_cnn_beats_hog_svm():
    """Faces vs non-faces, first of the 5 stratified folds: the CNN >= 95% and at least
    as good as the project's HOG + SVM on the same fold."""
    pytest.importorskip("skimage")
    ds = load_lfw_subset()
    train, test = lfw_folds()[0]
    assert len(test) == 40 and np.bincount(ds.labels[test]).tolist() == [20, 20]
    cnn = lfw_cnn_accuracy(ds, train, test)
    hog = lfw_hog_accuracy(ds, train, test)
    assert cnn >= 0.95, (cnn, hog)
    assert cnn >= hog, (cnn, hog)


def test_font_pretraining_helps_with_one_label_per_class():
    """Sim-to-real at CI size (6,000 rendered digits, 6 epochs, not the benchmark's
    20,000 x 8): with one real label per class, fine-tuning the font-pretrained
    network beats training from scratch by >= 10 points on the mean of the few-shot
    seeds 0-2, and by >= 5 on each (measured with 2 threads: +18.2 / +19.8 / +11.9,
    mean +16.6; with 1 thread +16.4 / +16.8 / +9.3); the benchmark's full pretraining
    gives >= 15 on the mean (docs/nn.md). The digits are rendered from matplotlib's
    fonts, so this is the same on every machine (issue 44: with the system's fonts it
    held or failed by what was installed)."""
    pytest.importorskip("PIL")
    pretrained = pretrain_on_fonts(n_images=6000, epochs=6)
    runs = [few_shot(pretrained, per_class=1, seed=s) for s in (0, 1, 2)]
    margins = [r["finetune"] - r["scratch"] for r in runs]
    assert np.mean(margins) >= 0.10, runs
    assert min(margins) >= 0.05, runs
    assert all(r["linear_probe"] > r["scratch"] for r in runs), runs
