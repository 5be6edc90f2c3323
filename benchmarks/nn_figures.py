"""Issue 23's acceptance figures for :mod:`robopercept.nn` on real data, and its
throughput benchmarks (run ``python -m benchmarks.nn_figures``; writes
``benchmarks/results/nn_figures.json`` and prints a table).

Parts (``--only digits lfw finetune throughput`` runs a subset):

- ``digits``: vgg_small, inception_small, resnet_small on scikit-learn's digits, stratified
  70/15/15 split, seeds 0-2: test accuracy, training seconds and parameters, against
  ``SVC(gamma=0.001)`` fitted on the same train split.
- ``lfw``: scikit-image's ``lfw_subset`` faces vs non-faces, 5-fold stratified CV: a
  small CNN (25 x 25 gray input, flips and small shifts) against the project's
  HOG + linear SVM (:class:`robopercept.learning.hog_detector.HogDetector`, fitted on the
  same folds, 24 x 24 top-left crops as its face model uses).
- ``finetune``: sim-to-real. resnet_small pretrained on 20,000 font-rendered digits
  (:func:`robopercept.nn.data.fonts.render_digits`), then trained on 1 or 5 real labelled
  digits per class (from the train split) three ways at the same budget: fine-tuned
  (new head, whole network, trunk at 0.1x the head's learning rate), from scratch, and a
  linear probe (frozen trunk, frozen batch norm, new head); tested on the real test split.
- ``throughput``: training images/s and inference latency (batch 1 and 256) of each
  family model against the same architecture written with plain ``torch.nn`` layers
  (the weights copied across, outputs checked equal), timed in alternation; our NumPy
  im2col ``conv2d`` against ``torch.nn.functional.conv2d`` for reference.
"""

from __future__ import annotations

import argparse
import copy
import functools
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn

from benchmarks._harness import RESULTS, machine, paired_ms
from robopercept.nn.classification.models import MODELS, build_model
from robopercept.nn.core.transfer import freeze, keep_frozen_batchnorm_in_eval, replace_head
from robopercept.nn.data.augment import Compose, Normalize, RandomAffine, RandomFlip
from robopercept.nn.data.datasets import (
    ArrayDataset,
    load_digits,
    load_lfw_subset,
    normalization_stats,
    stratified_split,
)
from robopercept.nn.data.fonts import render_digits
from robopercept.nn.train.config import TrainConfig
from robopercept.nn.train.fit import evaluate, fit

SEEDS = (0, 1, 2)
FAMILY = ("vgg_small", "inception_small", "resnet_small")

#: the digits recipe (the lead's trial): AdamW, cosine, 40 epochs, best validation loss
DIGITS_CONFIG = {"epochs": 40, "lr": 3e-3, "batch_size": 64, "monitor": "val_loss"}
#: the lfw recipe: 60 epochs, augmented, no validation split (5 folds of 40 images)
LFW_CONFIG = {"epochs": 60, "lr": 3e-3, "batch_size": 32}
#: pretraining on rendered fonts and the few-label budget
PRETRAIN_IMAGES = 20_000
PRETRAIN_CONFIG = {"epochs": 8, "lr": 3e-3, "batch_size": 128}
FEW_SHOT_EPOCHS = 60


def n_params(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def normalized(model: nn.Module, train: ArrayDataset) -> nn.Sequential:
    """``Normalize(train statistics)`` then ``model``: the statistics of the train split
    only, as the course prescribes."""
    mean, std = normalization_stats(train)
    return nn.Sequential(Normalize(mean, std), model)


def svc_accuracy(train: ArrayDataset, test: ArrayDataset, gamma: float = 0.001) -> float:
    """scikit-learn ``SVC(gamma=gamma)`` on the raw 0..16 pixel values (its digits
    example's setting), fitted on ``train``, accuracy on ``test``."""
    from sklearn.svm import SVC

    def flat(ds: ArrayDataset) -> np.ndarray:
        return ds.images.reshape(len(ds), -1) * 16.0

    clf = SVC(gamma=gamma).fit(flat(train), train.labels)
    return float((clf.predict(flat(test)) == test.labels).mean())


# --------------------------------------------------------------------------- digits


def digits_run(model_name: str, seed: int) -> dict[str, float]:
    """Train ``model_name`` on the digits split of ``seed``; test accuracy, seconds,
    parameters and the SVC's accuracy on the same split."""
    ds = load_digits()
    tr, va, te = stratified_split(ds.labels, (0.7, 0.15, 0.15), rng=seed)
    train, val, test = ds.subset(tr), ds.subset(va), ds.subset(te)
    torch.manual_seed(seed)
    model = normalized(build_model(model_name), train)
    cfg = TrainConfig(**DIGITS_CONFIG, seed=seed, patience=None)  # type: ignore[arg-type]
    t0 = time.perf_counter()
    fit(model, train, val, cfg, progress=False)
    seconds = time.perf_counter() - t0
    return {
        "accuracy": evaluate(model, test).accuracy,
        "seconds": seconds,
        "params": n_params(model),
        "svc_accuracy": svc_accuracy(train, test),
    }


def bench_digits() -> dict[str, Any]:
    """The family on digits, seeds 0-2."""
    out: dict[str, Any] = {}
    for name in FAMILY:
        runs = [digits_run(name, s) for s in SEEDS]
        out[name] = {
            "params": runs[0]["params"],
            "accuracy": [r["accuracy"] for r in runs],
            "mean_accuracy": float(np.mean([r["accuracy"] for r in runs])),
            "mean_seconds": float(np.mean([r["seconds"] for r in runs])),
            "svc_accuracy": [r["svc_accuracy"] for r in runs],
            "mean_svc_accuracy": float(np.mean([r["svc_accuracy"] for r in runs])),
        }
    return out


# --------------------------------------------------------------------------- lfw


def lfw_cnn_accuracy(
    ds: ArrayDataset, train_idx: np.ndarray, test_idx: np.ndarray, seed: int = 0
) -> float:
    """resnet_small (2 classes, 25 x 25 gray) trained on ``train_idx`` with horizontal
    flips and shifts of up to 2 pixels (4 degrees, 0.95-1.05 scale); accuracy on
    ``test_idx``."""
    augment = Compose(
        [
            RandomFlip(0.5, generator=seed),
            RandomAffine(degrees=4.0, translate=(0.08, 0.08), scale=(0.95, 1.05), generator=seed),
        ]
    )
    train = ds.subset(train_idx, transform=augment)
    test = ds.subset(test_idx)
    torch.manual_seed(seed)
    model = normalized(build_model("resnet_small", num_classes=2), ds.subset(train_idx))
    cfg = TrainConfig(**LFW_CONFIG, seed=seed, patience=None)  # type: ignore[arg-type]
    fit(model, train, None, cfg, progress=False)
    return evaluate(model, test).accuracy


def lfw_hog_accuracy(ds: ArrayDataset, train_idx: np.ndarray, test_idx: np.ndarray) -> float:
    """The project's HOG + linear SVM on 24 x 24 top-left crops (its face model's
    window), fitted on ``train_idx``; accuracy of ``score > 0`` on ``test_idx``."""
    from robopercept.learning.hog_detector import HogDetector

    patches = ds.images[:, 0, :24, :24]
    det = HogDetector().fit(patches[train_idx], ds.labels[train_idx], random_state=0)
    pred = (det.score_patches(patches[test_idx]) > 0).astype(int)
    return float((pred == ds.labels[test_idx]).mean())


def lfw_folds(n_splits: int = 5, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """scikit-learn's ``StratifiedKFold(n_splits, shuffle=True, random_state=seed)``
    over the 200 lfw_subset labels."""
    from sklearn.model_selection import StratifiedKFold

    labels = load_lfw_subset().labels
    kf = StratifiedKFold(n_splits=n_splits, shuffle=True, random_state=seed)
    return list(kf.split(np.zeros(len(labels)), labels))


def bench_lfw() -> dict[str, Any]:
    """5-fold CV of the CNN and of HOG + SVM."""
    ds = load_lfw_subset()
    cnn, hog = [], []
    for tr, te in lfw_folds():
        cnn.append(lfw_cnn_accuracy(ds, tr, te))
        hog.append(lfw_hog_accuracy(ds, tr, te))
    return {
        "cnn": {"model": "resnet_small", "folds": cnn, "mean_accuracy": float(np.mean(cnn))},
        "hog_svm": {"folds": hog, "mean_accuracy": float(np.mean(hog))},
    }


# --------------------------------------------------------------------------- fine-tuning


def pretrain_on_fonts(
    n_images: int = PRETRAIN_IMAGES, epochs: int = PRETRAIN_CONFIG["epochs"], seed: int = 100
) -> nn.Sequential:
    """resnet_small (behind a fixed ``Normalize``) trained on ``n_images`` font-rendered
    digits; the real digits are never seen."""
    images, labels = render_digits(n_images, seed=seed)
    fonts = ArrayDataset(images, labels, [str(d) for d in range(10)])
    torch.manual_seed(seed)
    model = normalized(build_model("resnet_small"), fonts)
    cfg = TrainConfig(**{**PRETRAIN_CONFIG, "epochs": epochs}, seed=seed, patience=None)  # type: ignore[arg-type]
    fit(model, fonts, None, cfg, progress=False)
    return model


def few_labels(labels: np.ndarray, pool: np.ndarray, per_class: int, seed: int) -> np.ndarray:
    """``per_class`` indices of each class drawn from ``pool`` (seeded)."""
    rng = np.random.default_rng(seed)
    return np.concatenate(
        [rng.choice(pool[labels[pool] == c], per_class, replace=False) for c in np.unique(labels)]
    )


def few_shot(
    pretrained: nn.Sequential, per_class: int, seed: int, epochs: int = FEW_SHOT_EPOCHS
) -> dict[str, float]:
    """Test accuracy on the real digits' test split of the three ways to use
    ``per_class`` real labels per class: fine-tune, from scratch, linear probe."""
    ds = load_digits()
    tr, _, te = stratified_split(ds.labels, (0.7, 0.15, 0.15), rng=seed)
    small, test = ds.subset(few_labels(ds.labels, tr, per_class, seed)), ds.subset(te)
    base = {"epochs": epochs, "batch_size": 64, "patience": None, "seed": seed}
    out = {}

    # fine-tune: new head, the whole network trains, the trunk at 0.1x the head's lr
    torch.manual_seed(seed)
    model = copy.deepcopy(pretrained)
    replace_head(model, 10)
    cfg = TrainConfig(lr=3e-3, lr_multipliers={"1.features": 0.1}, **base)  # type: ignore[arg-type]
    fit(model, small, None, cfg, progress=False)
    out["finetune"] = evaluate(model, test).accuracy

    # from scratch: same architecture, fresh weights, same budget (its own best lr)
    torch.manual_seed(seed)
    model = normalized(build_model("resnet_small"), small)
    fit(model, small, None, TrainConfig(lr=3e-3, **base), progress=False)  # type: ignore[arg-type]
    out["scratch"] = evaluate(model, test).accuracy

    # linear probe: frozen trunk (batch norm in eval mode), new head
    torch.manual_seed(seed)
    model = copy.deepcopy(pretrained)
    freeze(model)
    replace_head(model, 10)
    keep_frozen_batchnorm_in_eval(model)
    fit(model, small, None, TrainConfig(lr=1e-2, **base), progress=False)  # type: ignore[arg-type]
    out["linear_probe"] = evaluate(model, test).accuracy
    return out


def bench_finetune() -> dict[str, Any]:
    """Pretrain once, then 1 and 5 labels per class, seeds 0-2."""
    t0 = time.perf_counter()
    pretrained = pretrain_on_fonts()
    seconds = time.perf_counter() - t0
    ds = load_digits()
    out: dict[str, Any] = {
        "pretrain_images": PRETRAIN_IMAGES,
        "pretrain_seconds": seconds,
        "pretrained_zero_shot_accuracy": evaluate(pretrained, ds).accuracy,
    }
    for k in (1, 5):
        runs = [few_shot(pretrained, k, s) for s in SEEDS]
        means = {m: float(np.mean([r[m] for r in runs])) for m in runs[0]}
        out[f"{k}_per_class"] = {
            "runs": runs,
            "mean": means,
            "finetune_minus_scratch_points": 100 * (means["finetune"] - means["scratch"]),
        }
    return out


# --------------------------------------------------------------------------- throughput


class PlainResidual(nn.Module):
    """``relu(bn(conv(relu(bn(conv(x))))) + skip(x))`` in plain torch.nn layers."""

    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(cin, cout, 3, stride, 1, bias=False),
            nn.BatchNorm2d(cout),
            nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, 1, 1, bias=False),
            nn.BatchNorm2d(cout),
        )
        self.skip: nn.Module = (
            nn.Identity()
            if stride == 1 and cin == cout
            else nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))
        )
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The block's output."""
        return self.relu(self.body(x) + self.skip(x))


def _cbr(cin: int, cout: int, k: int) -> list[nn.Module]:
    """Conv (k x k, same padding, no bias), BatchNorm2d, ReLU: a ConvBNAct's layers."""
    return [nn.Conv2d(cin, cout, k, 1, k // 2, bias=False), nn.BatchNorm2d(cout), nn.ReLU(True)]


class PlainInception(nn.Module):
    """The four-branch Inception block in plain torch.nn layers."""

    def __init__(self, cin: int, c1: int, c3r: int, c3: int, c5r: int, c5: int, cp: int) -> None:
        super().__init__()
        self.b1 = nn.Sequential(*_cbr(cin, c1, 1))
        self.b3 = nn.Sequential(*_cbr(cin, c3r, 1), *_cbr(c3r, c3, 3))
        self.b5 = nn.Sequential(*_cbr(cin, c5r, 1), *_cbr(c5r, c5, 5))
        self.bp = nn.Sequential(nn.MaxPool2d(3, 1, 1), *_cbr(cin, cp, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The concatenated branches."""
        return torch.cat([self.b1(x), self.b3(x), self.b5(x), self.bp(x)], 1)


def plain_model(name: str) -> nn.Sequential:
    """The default ``name`` of the family (1 channel in, 10 classes) written directly
    with torch.nn layers (no input checks, no wrappers)."""
    layers: list[nn.Module] = []
    if name == "vgg_small":
        cin = 1
        for w in (16, 32, 64):
            layers += [*_cbr(cin, w, 3), *_cbr(w, w, 3), nn.MaxPool2d(2, 2)]
            cin = w
    elif name == "inception_small":
        from robopercept.nn.classification.models import INCEPTION_SMALL_BLOCKS

        layers += _cbr(1, 32, 3)
        cin = 32
        for i, b in enumerate(INCEPTION_SMALL_BLOCKS):
            layers.append(PlainInception(cin, *b))
            cin = b[0] + b[2] + b[4] + b[5]
            if i < len(INCEPTION_SMALL_BLOCKS) - 1:
                layers.append(nn.MaxPool2d(2, 2))
    elif name == "resnet_small":
        layers += _cbr(1, 16, 3)
        cin = 16
        for stage, w in enumerate((16, 32, 64)):
            layers.append(PlainResidual(cin, w, 2 if stage else 1))
            cin = w
    else:
        raise ValueError(name)
    layers += [nn.AdaptiveAvgPool2d(1), nn.Flatten(1), nn.Dropout(0.2), nn.Linear(cin, 10)]
    return nn.Sequential(*layers)


def copy_weights(src: nn.Module, dst: nn.Module) -> None:
    """Copy ``src``'s parameters and buffers into ``dst`` in registration order (the two
    architectures register the same tensors in the same order; shapes are checked)."""
    a, b = list(src.state_dict().values()), dst.state_dict()
    if len(a) != len(b):
        raise AssertionError(f"{len(a)} vs {len(b)} tensors: the architectures differ")
    for value, (key, target) in zip(a, b.items(), strict=True):
        if value.shape != target.shape:
            raise AssertionError(f"{key}: {tuple(value.shape)} vs {tuple(target.shape)}")
        target.copy_(value)


def train_step(model: nn.Module, opt: torch.optim.Optimizer, x: torch.Tensor, y: torch.Tensor):
    """One AdamW step on one batch (forward, cross-entropy, backward, step)."""
    opt.zero_grad(set_to_none=True)
    nn.functional.cross_entropy(model(x), y).backward()
    opt.step()


def bench_throughput(repeats: int = 20) -> dict[str, Any]:
    """Training images/s (batch 64 of 8 x 8 digits) and inference latency at batch 1
    and 256, ours vs plain torch.nn, paired timings; NumPy conv2d vs F.conv2d."""
    from robopercept.nn.functional import conv2d

    gen = torch.Generator().manual_seed(0)
    out: dict[str, Any] = {}
    for name in FAMILY:
        ours = build_model(name)
        ref = plain_model(name)
        copy_weights(ours, ref)
        ours.eval()
        ref.eval()
        probe = torch.rand(4, 1, 8, 8, generator=gen)
        with torch.no_grad():
            torch.testing.assert_close(ours(probe), ref(probe), rtol=1e-5, atol=1e-5)
        row: dict[str, Any] = {"params": n_params(ours), "ref_params": n_params(ref)}
        for batch in (1, 256):
            x = torch.rand(batch, 1, 8, 8, generator=gen)

            def infer(m: nn.Module, x: torch.Tensor = x) -> Callable[[], object]:
                """A no-argument call of ``m(x)`` in inference mode."""

                def call() -> object:
                    with torch.inference_mode():
                        return m(x)

                return call

            a, b = paired_ms(infer(ours), infer(ref), repeats=repeats * 5)
            row[f"infer_b{batch}_ms"] = a
            row[f"ref_infer_b{batch}_ms"] = b
            row[f"infer_b{batch}_ratio"] = a / b
        ours.train()
        ref.train()
        x = torch.rand(64, 1, 8, 8, generator=gen)
        y = torch.randint(0, 10, (64,), generator=gen)
        opt_a = torch.optim.AdamW(ours.parameters(), 1e-3)
        opt_b = torch.optim.AdamW(ref.parameters(), 1e-3)
        a, b = paired_ms(
            functools.partial(train_step, ours, opt_a, x, y),
            functools.partial(train_step, ref, opt_b, x, y),
            repeats,
        )
        row["train_images_per_s"] = 64 / (a / 1e3)
        row["ref_train_images_per_s"] = 64 / (b / 1e3)
        row["train_ratio"] = a / b
        out[name] = row
    rng = np.random.default_rng(0)
    x = rng.standard_normal((1, 16, 64, 64)).astype(np.float32)
    w = rng.standard_normal((32, 16, 3, 3)).astype(np.float32)
    xt, wt = torch.from_numpy(x), torch.from_numpy(w)
    a, b = paired_ms(
        lambda: conv2d(x, w, padding=1),
        lambda: torch.nn.functional.conv2d(xt, wt, padding=1),
        repeats,
    )
    diff = conv2d(x, w, padding=1) - torch.nn.functional.conv2d(xt, wt, padding=1).numpy()
    err = float(np.abs(diff).max())
    out["numpy_conv2d_1x16x64x64_32x3x3"] = {
        "ours_ms": a,
        "torch_ms": b,
        "ratio": a / b,
        "max_abs_diff": err,
    }
    return out


# --------------------------------------------------------------------------- report


def table(results: dict[str, Any]) -> str:
    """The figures as a plain-text table."""
    lines = []
    if "digits" in results:
        lines.append("digits (stratified 70/15/15, seeds 0-2): model  params  acc  s/run  SVC")
        for name, r in results["digits"].items():
            lines.append(
                f"  {name:16s} {r['params']:7d}  {100 * r['mean_accuracy']:.2f}%  "
                f"{r['mean_seconds']:5.1f}  {100 * r['mean_svc_accuracy']:.2f}%"
            )
    if "lfw" in results:
        r = results["lfw"]
        lines.append(
            f"lfw_subset 5-fold: CNN {100 * r['cnn']['mean_accuracy']:.1f}%  "
            f"HOG+SVM {100 * r['hog_svm']['mean_accuracy']:.1f}%"
        )
    if "finetune" in results:
        r = results["finetune"]
        lines.append(
            f"fonts -> digits (pretrain {r['pretrain_images']} images, "
            f"{r['pretrain_seconds']:.0f} s, zero-shot "
            f"{100 * r['pretrained_zero_shot_accuracy']:.1f}%)"
        )
        for k in (1, 5):
            m = r[f"{k}_per_class"]["mean"]
            lines.append(
                f"  {k} label/class: fine-tune {100 * m['finetune']:.1f}%  scratch "
                f"{100 * m['scratch']:.1f}%  linear probe {100 * m['linear_probe']:.1f}%  "
                f"(+{r[f'{k}_per_class']['finetune_minus_scratch_points']:.1f} points)"
            )
    if "throughput" in results:
        lines.append("throughput (ours / plain torch.nn): train img/s, infer b1 ms, infer b256 ms")
        for name, r in results["throughput"].items():
            if name in MODELS:
                lines.append(
                    f"  {name:16s} {r['train_images_per_s']:7.0f} / "
                    f"{r['ref_train_images_per_s']:7.0f}"
                    f"   {r['infer_b1_ms']:.3f} / {r['ref_infer_b1_ms']:.3f}"
                    f"   {r['infer_b256_ms']:.2f} / {r['ref_infer_b256_ms']:.2f}"
                )
        c = results["throughput"]["numpy_conv2d_1x16x64x64_32x3x3"]
        lines.append(
            f"  NumPy conv2d {c['ours_ms']:.2f} ms vs F.conv2d {c['torch_ms']:.2f} ms "
            f"({c['ratio']:.1f}x)"
        )
    return "\n".join(lines)


PARTS: dict[str, Callable[[], dict[str, Any]]] = {
    "digits": bench_digits,
    "lfw": bench_lfw,
    "finetune": bench_finetune,
    "throughput": bench_throughput,
}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the parts, merge them into the JSON file, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=sorted(PARTS), default=list(PARTS))
    parser.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    path = RESULTS / "nn_figures.json"
    results: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    for part in args.only:
        t0 = time.perf_counter()
        results[part] = PARTS[part]()
        results.setdefault("seconds", {})[part] = time.perf_counter() - t0
    results["machine"] = machine()
    results["torch"] = torch.__version__
    results["threads"] = args.threads
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(results, indent=2) + "\n")
    print(table(results))
    return results


if __name__ == "__main__":
    main()
