"""The plane-tracker sweep, seeds 5-9 of both cameras (see :mod:`.plane_sweep_cases`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.plane_sweep import SweepCase
from tests.pipelines.plane_sweep_cases import cases, check_case


@pytest.mark.parametrize("case", cases(range(5, 9 + 1)))
def test_sweep_meets_the_rule(case: SweepCase, tmp_path: Path) -> None:
    check_case(case, tmp_path)
