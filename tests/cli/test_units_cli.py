"""Rates on the command line read well (issue 48): ``batch`` prints its speed with
:func:`robopercept.progress.format_rate`, over the items it ran (not the ones a resume
skipped), never ``373203.96 items/s``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from robopercept.cli.main import main


class _Result:
    """What :func:`robopercept.pipelines.batch.run_batch` returns, as far as the
    command reads it."""

    def __init__(self, summary: dict[str, Any]) -> None:
        self.summary = summary
        self.items: list[dict[str, Any]] = []

    def to_dict(self) -> dict[str, Any]:
        return self.summary

    def first_failure(self) -> None:
        return None


def _summary_line(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    **counts: Any,
) -> str:
    summary = {"ok": 0, "failed": 0, "skipped": 0, "cancelled": 0, "workers": 2}
    summary |= counts
    summary["items"] = summary["ok"] + summary["failed"] + summary["skipped"]
    summary["items_per_second"] = summary["items"] / summary["seconds"]
    summary["manifest"] = str(tmp_path / "batch.json")
    monkeypatch.setattr("robopercept.pipelines.batch.run_batch", lambda *a, **k: _Result(summary))
    image = tmp_path / "a.png"
    image.write_bytes(b"")
    assert main(["batch", "edges", str(image), "-o", str(tmp_path / "out")]) == 0
    return capsys.readouterr().out.strip().splitlines()[-1]


def test_batch_slow_items_read_seconds_per_item(monkeypatch, capsys, tmp_path) -> None:
    line = _summary_line(monkeypatch, capsys, tmp_path, ok=3, seconds=12.0)
    assert "in 12.0 s (4.00 s/item) ->" in line, line
    assert "items/s" not in line and "item/s" not in line


def test_batch_fast_items_read_items_per_second(monkeypatch, capsys, tmp_path) -> None:
    line = _summary_line(monkeypatch, capsys, tmp_path, ok=200, failed=1, seconds=8.0)
    assert "(25.1 item/s)" in line, line


def test_batch_resumed_items_give_no_absurd_rate(monkeypatch, capsys, tmp_path) -> None:
    """Every item done by an earlier run: no rate at all (was 373203.96 items/s)."""
    line = _summary_line(monkeypatch, capsys, tmp_path, skipped=5, seconds=0.0000134)
    assert "/s" not in line and "s/item" not in line, line
    assert "5 skipped of 5 items" in line
