"""The Python quick start that opens ``docs/nn.md`` runs as written (issue 46): its
examples are doctests, with the options of the project's own doctests."""

from __future__ import annotations

import doctest
from pathlib import Path

import pytest

pytest.importorskip("torch")

DOC = Path(__file__).resolve().parents[2] / "docs" / "nn.md"


@pytest.mark.usefixtures("torch_one_thread")
def test_docs_nn_quick_start_runs():
    text = DOC.read_text()
    assert text.index("## Quick start") < text.index("## The layer arithmetic")
    result = doctest.testfile(
        str(DOC),
        module_relative=False,
        optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
        verbose=False,
        report=True,
    )
    assert result.attempted >= 15 and result.failed == 0, result
