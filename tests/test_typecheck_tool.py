"""tools/typecheck.py: the baseline comparison, on fake mypy outputs (mypy is not run)."""

from __future__ import annotations

import importlib.util
import sys
from collections import Counter
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parent.parent / "tools" / "typecheck.py"
_spec = importlib.util.spec_from_file_location("typecheck_tool", _PATH)
assert _spec is not None and _spec.loader is not None
tc = importlib.util.module_from_spec(_spec)
sys.modules["typecheck_tool"] = tc  # dataclasses look the module up by name
_spec.loader.exec_module(tc)

MSG = 'Incompatible return value type (got "int", expected "str")'
A = f"src/robopercept/a.py:12: error: {MSG}  [return-value]"
A2 = f"src/robopercept/a.py:40:5: error: {MSG}  [return-value]"  # same error, with a column
B = 'src/robopercept/b.py:3: error: Name "x" already defined on line 1  [no-redef]'
C = 'src/robopercept/c.py:7: error: Need type annotation for "out"  [var-annotated]'
NOTE = 'src/robopercept/a.py:12: note: Revealed type is "builtins.int"'

KEY_A = f"src/robopercept/a.py: return-value: {MSG}"
KEY_B = 'src/robopercept/b.py: no-redef: Name "x" already defined on line N'
KEY_C = 'src/robopercept/c.py: var-annotated: Need type annotation for "out"'


def _fake(*lines: str, rc: int | None = None):
    code = (1 if lines else 0) if rc is None else rc
    return lambda: (code, "\n".join(lines) + "\n")


def _run(tmp_path: Path, argv: list[str], *lines: str, rc: int | None = None):
    printed: list[str] = []
    code = tc.main(
        argv, mypy=_fake(*lines, rc=rc), baseline_path=tmp_path / "base.txt", out=printed.append
    )
    return code, "\n".join(printed)


def _write(tmp_path: Path, counts: dict[str, int]) -> None:
    (tmp_path / "base.txt").write_text(tc.format_baseline(Counter(counts)), encoding="utf-8")


def _read(tmp_path: Path) -> Counter:
    return tc.parse_baseline((tmp_path / "base.txt").read_text(encoding="utf-8"))


class TestNormalise:
    def test_drops_line_numbers_columns_and_notes_and_counts_repeats(self):
        got = tc.normalise("\n".join([A, A2, B, NOTE, "Found 3 errors in 2 files"]))
        assert got == Counter({KEY_A: 2, KEY_B: 1})

    def test_absolute_paths_become_relative_to_the_root(self, tmp_path):
        line = f"{tmp_path}/{C}"
        assert tc.normalise(line, root=tmp_path) == Counter({KEY_C: 1})

    def test_format_is_sorted_and_round_trips(self):
        counts = Counter({KEY_C: 1, KEY_A: 3, KEY_B: 2})
        text = tc.format_baseline(counts)
        body = [ln for ln in text.splitlines() if not ln.startswith("#")]
        assert body == [f"3  {KEY_A}", f"2  {KEY_B}", f"1  {KEY_C}"]
        assert tc.parse_baseline(text) == counts

    def test_bad_baseline_line_is_reported(self):
        with pytest.raises(ValueError, match="line 1"):
            tc.parse_baseline("src/x.py: misc: no count\n")


class TestCompare:
    def test_counts_are_a_multiset(self):
        cmp = tc.compare(Counter({KEY_A: 2, KEY_B: 1}), Counter({KEY_A: 3, KEY_C: 1}))
        assert cmp.new == Counter({KEY_A: 1, KEY_C: 1})
        assert cmp.fixed == Counter({KEY_B: 1})
        assert not cmp.ok


class TestCheck:
    def test_same_errors_pass(self, tmp_path):
        _write(tmp_path, {KEY_A: 1, KEY_B: 1})
        code, text = _run(tmp_path, [], A, B)
        assert code == 0
        assert "OK" in text

    def test_new_error_fails_and_is_listed(self, tmp_path):
        _write(tmp_path, {KEY_A: 1})
        code, text = _run(tmp_path, [], A, C)
        assert code == 1
        assert KEY_C in text and "FAILED" in text

    def test_one_more_of_a_known_error_fails(self, tmp_path):
        _write(tmp_path, {KEY_A: 1})
        code, text = _run(tmp_path, [], A, A2)
        assert code == 1
        assert KEY_A in text

    def test_fixed_error_passes_with_a_note(self, tmp_path):
        _write(tmp_path, {KEY_A: 2, KEY_B: 1})
        code, text = _run(tmp_path, [], A)
        assert code == 0
        assert "--update" in text and KEY_B in text
        assert _read(tmp_path) == Counter({KEY_A: 2, KEY_B: 1})  # the check writes nothing

    def test_no_baseline_file_means_empty(self, tmp_path):
        assert _run(tmp_path, [])[0] == 0
        assert _run(tmp_path, [], A)[0] == 1

    def test_mypy_crash_is_exit_2(self, tmp_path):
        code, text = _run(tmp_path, [], "mypy: error: bad config", rc=2)
        assert code == 2
        assert "bad config" in text


class TestUpdate:
    def test_shrinks(self, tmp_path):
        _write(tmp_path, {KEY_A: 2, KEY_B: 1})
        code, _ = _run(tmp_path, ["--update"], A)
        assert code == 0
        assert _read(tmp_path) == Counter({KEY_A: 1})

    def test_refuses_to_grow(self, tmp_path):
        _write(tmp_path, {KEY_A: 1, KEY_B: 1})
        code, text = _run(tmp_path, ["--update"], A, A2, C)
        assert code == 1
        assert "NOT added" in text and KEY_C in text
        assert _read(tmp_path) == Counter({KEY_A: 1})  # B fixed: gone; A and C not raised

    def test_allow_grow_rewrites(self, tmp_path):
        _write(tmp_path, {KEY_B: 1})
        code, _ = _run(tmp_path, ["--update", "--allow-grow"], A, A2, C)
        assert code == 0
        assert _read(tmp_path) == Counter({KEY_A: 2, KEY_C: 1})

    def test_allow_grow_needs_update(self, tmp_path):
        with pytest.raises(SystemExit):
            _run(tmp_path, ["--allow-grow"])

    def test_deterministic(self, tmp_path):
        _run(tmp_path, ["--update", "--allow-grow"], C, B, A)
        first = (tmp_path / "base.txt").read_bytes()
        _run(tmp_path, ["--update", "--allow-grow"], A, C, B)
        assert (tmp_path / "base.txt").read_bytes() == first
