"""The install contract of the README's two commands: torch is the pinned CPU build,
the users' extra stays a range (issue 23)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_constraints_pin_the_local_cpu_torch() -> None:
    pins = [
        ln.strip()
        for ln in (ROOT / "constraints.txt").read_text().splitlines()
        if ln.strip() and not ln.startswith("#")
    ]
    assert "torch==2.13.0" in pins


def test_users_extra_is_a_range_below_the_next_minor() -> None:
    # (tomllib is Python >= 3.11; the project supports 3.10)
    deep = re.search(r"^deep = (.*)$", (ROOT / "pyproject.toml").read_text(), re.M)
    assert deep is not None and deep.group(1) == '["torch>=2.4,<2.14"]'


def test_makefile_installs_torch_pinned_before_the_extras() -> None:
    make = (ROOT / "Makefile").read_text()
    recipe = make.split("$(VENV)/.dev:")[1].split("\n\n")[0]
    lines = [ln.strip() for ln in recipe.splitlines()[1:]]
    torch_line = next(i for i, ln in enumerate(lines) if '"torch==2.13.0"' in ln)
    extras_line = next(i for i, ln in enumerate(lines) if ".[dev,deep]" in ln)
    assert torch_line < extras_line
    for i in (torch_line, extras_line):  # both under the constraints: no CUDA download
        assert re.search(r"-c constraints\.txt", lines[i])
