"""Make the pictures of docs/nn.md: a small ResNet trained on scikit-learn's digits.

Run from the repository root (about 15 s on 2 cores)::

    python docs/make_nn_pictures.py

Writes docs/img/nn_filters.png (the first layer's 3x3 filters), nn_feature_maps.png (one
digit and what the first stage makes of it), nn_curves.png (training curves) and
nn_confusion.png (test split), and prints the test accuracy.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from robopercept.imaging import write_image
from robopercept.nn.classification.models import build_model
from robopercept.nn.data.augment import Normalize
from robopercept.nn.data.datasets import load_digits, normalization_stats, stratified_split
from robopercept.nn.train.config import TrainConfig
from robopercept.nn.train.fit import evaluate, fit
from robopercept.viz import confusion_picture, tiles_picture

IMG = Path(__file__).resolve().parent / "img"


def main() -> None:
    digits = load_digits()
    train_i, val_i, test_i = stratified_split(digits.labels, (0.7, 0.15, 0.15), rng=0)
    train, val, test = (digits.subset(i) for i in (train_i, val_i, test_i))
    mean, std = normalization_stats(train)
    torch.manual_seed(0)
    net = build_model("resnet_small", in_channels=1, num_classes=10)
    model = nn.Sequential(Normalize(mean, std), net)
    cfg = TrainConfig(epochs=40, lr=3e-3, seed=0, monitor="val_loss", patience=None)
    history = fit(model, train, val, cfg)
    ev = evaluate(model, test)
    print(f"test accuracy {ev.accuracy:.4f} ({len(test)} images), best epoch {history.best_epoch}")
    IMG.mkdir(exist_ok=True)
    write_image(IMG / "nn_curves.png", history.picture())
    cm = ev.confusion_matrix(10)
    write_image(IMG / "nn_confusion.png", confusion_picture(cm, [str(d) for d in range(10)]))
    first = next(m for m in net.modules() if isinstance(m, nn.Conv2d))
    w = first.weight.detach().numpy()[:, 0]  # (out, 3, 3)
    write_image(IMG / "nn_filters.png", tiles_picture(w, signed=True, tile_px=90))
    x, label = test[0]
    maps: list[np.ndarray] = []
    hook = first.register_forward_hook(lambda m, i, o: maps.append(o.detach().numpy()[0]))
    model.eval()
    with torch.no_grad():
        model(x[None])
    hook.remove()
    tiles = np.concatenate([x.numpy(), maps[0]])
    names = [f"digit {label}"] + [f"map {i}" for i in range(len(maps[0]))]
    write_image(IMG / "nn_feature_maps.png", tiles_picture(tiles, tile_px=96, names=names))


if __name__ == "__main__":
    main()
