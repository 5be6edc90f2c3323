"""Tests of robopercept.nn.train.config: the run's configuration and history."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from robopercept.nn.train.config import History


def test_history_csv_and_picture(tmp_path) -> None:
    h = History(
        epoch=[1, 2],
        train_loss=[1.0, 0.5],
        train_accuracy=[0.5, 0.8],
        val_loss=[1.1, 0.6],
        val_accuracy=[0.4, 0.7],
        lr=[0.1, 0.1],
        seconds=[0.2, 0.2],
        best_epoch=2,
    )
    text = h.write_csv(tmp_path / "h.csv").read_text().splitlines()
    assert text[0] == "epoch,train_loss,train_accuracy,val_loss,val_accuracy,lr,seconds"
    assert text[2] == "2,0.5,0.8,0.6,0.7,0.1,0.2"
    assert History.from_dict(h.to_dict()) == h
    img = h.picture()
    assert img.dtype == np.uint8 and img.shape[1] == 1200 and img.shape[0] >= 3 * 260
