"""Type-check ``src/robopercept`` with mypy against a baseline that may only shrink.

Usage (from anywhere; paths are taken relative to the repository root)::

    python tools/typecheck.py                          # check: fail on errors not in the baseline
    python tools/typecheck.py --update                 # shrink the baseline to what still fails
    python tools/typecheck.py --update --allow-grow    # rewrite it from scratch (may add lines)

Each mypy error is normalised to ``path: error-code: message``: no line or column numbers
(a ``line 42`` inside a message becomes ``line N``), so that editing a file does not churn
the baseline. The baseline, ``tools/mypy-baseline.txt``, holds one normalised error per
line, sorted, each preceded by how many times it occurs (``2  src/x.py: arg-type: ...``).

The check compares multisets: an error whose count exceeds its baseline count is new, and
makes the check FAIL (exit 1, listing them); baseline entries that no longer occur only
print a note asking to run ``--update``, which rewrites the baseline to the errors of both
(the intersection). ``--update`` never adds a line or raises a count unless
``--allow-grow`` is given. Exit 2 when mypy itself cannot run (a crash, a bad config).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "tools" / "mypy-baseline.txt"
TARGET = "src/robopercept"

HEADER = (
    "# mypy errors accepted for now: count, then 'path: error-code: message' (no line numbers).\n"
    "# Shrink it with `python tools/typecheck.py --update`; never add to it by hand.\n"
)

# path:line[:col]: error: message  [code]
_ERROR = re.compile(
    r"^(?P<path>[^:\n]+?):\d+(?::\d+)?: error: (?P<msg>.*?)(?:\s+\[(?P<code>[a-z0-9-]+)\])?\s*$"
)
_LINE_REF = re.compile(r"\bline \d+\b")


def normalise(output: str, root: Path = ROOT) -> Counter[str]:
    """Counts of ``path: error-code: message`` in mypy's text output (notes dropped)."""
    counts: Counter[str] = Counter()
    for raw in output.splitlines():
        m = _ERROR.match(raw.strip())
        if m is None:
            continue
        path = Path(m["path"])
        if path.is_absolute():
            try:
                path = path.relative_to(root)
            except ValueError:
                pass
        msg = _LINE_REF.sub("line N", m["msg"].strip())
        counts[f"{path.as_posix()}: {m['code'] or 'misc'}: {msg}"] += 1
    return counts


def parse_baseline(text: str) -> Counter[str]:
    """The baseline file's entries (``count  entry`` lines; ``#`` comments skipped)."""
    counts: Counter[str] = Counter()
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        head, _, entry = line.partition(" ")
        if not head.isdigit() or not entry.strip():
            raise ValueError(f"baseline line {lineno} is not 'count  entry': {raw!r}")
        counts[entry.strip()] += int(head)
    return counts


def format_baseline(counts: Counter[str]) -> str:
    """The baseline file's text: sorted entries with their counts, deterministic."""
    lines = [f"{counts[e]}  {e}\n" for e in sorted(counts) if counts[e] > 0]
    return HEADER + "".join(lines)


@dataclass(frozen=True)
class Comparison:
    """Errors beyond the baseline (``new``) and baseline entries gone (``fixed``)."""

    new: Counter[str]
    fixed: Counter[str]

    @property
    def ok(self) -> bool:
        return not self.new


def compare(baseline: Counter[str], current: Counter[str]) -> Comparison:
    """Multiset difference both ways: ``current - baseline`` and ``baseline - current``."""
    return Comparison(new=current - baseline, fixed=baseline - current)


def _listing(counts: Counter[str]) -> Iterable[str]:
    for e in sorted(counts):
        yield f"  {e}" + (f"  (x{counts[e]})" if counts[e] > 1 else "")


def run_mypy(root: Path = ROOT) -> tuple[int, str]:
    """Run mypy on the package from the repository root; (exit code, stdout + stderr)."""
    cmd = [
        sys.executable,
        "-m",
        "mypy",
        "--config-file",
        "pyproject.toml",
        "--show-error-codes",
        "--no-pretty",
        "--no-error-summary",
        "--hide-error-context",
        "--no-color-output",
        TARGET,
    ]
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, check=False)
    return proc.returncode, proc.stdout + proc.stderr


def main(
    argv: list[str] | None = None,
    *,
    mypy: Callable[[], tuple[int, str]] = run_mypy,
    baseline_path: Path = BASELINE,
    out: Callable[[str], None] = print,
) -> int:
    """Check (or ``--update``) the baseline; returns the exit code."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--update", action="store_true", help="rewrite the baseline (shrink only)")
    ap.add_argument(
        "--allow-grow", action="store_true", help="with --update: allow new entries and counts"
    )
    args = ap.parse_args(argv)
    if args.allow_grow and not args.update:
        ap.error("--allow-grow only goes with --update")

    rc, output = mypy()
    current = normalise(output)
    if rc not in (0, 1) or (rc == 1 and not current):
        out(output.rstrip())
        out(f"typecheck: mypy did not run cleanly (exit {rc}); see its output above")
        return 2
    baseline = (
        parse_baseline(baseline_path.read_text(encoding="utf-8"))
        if baseline_path.exists()
        else Counter()
    )
    cmp = compare(baseline, current)

    if args.update:
        if cmp.new and not args.allow_grow:
            kept = baseline & current  # shrink what was fixed, never add
            baseline_path.write_text(format_baseline(kept), encoding="utf-8")
            out(f"typecheck: {sum(cmp.new.values())} error(s) not in the baseline, NOT added:")
            for line in _listing(cmp.new):
                out(line)
            out(
                f"typecheck: baseline shrunk to {sum(kept.values())} error(s); fix the new "
                "ones, or rerun with --update --allow-grow to accept them"
            )
            return 1
        baseline_path.write_text(format_baseline(current), encoding="utf-8")
        out(
            f"typecheck: baseline {_rel(baseline_path)} rewritten: {sum(current.values())} "
            f"error(s) ({sum(cmp.fixed.values())} removed, {sum(cmp.new.values())} added)"
        )
        return 0

    if cmp.new:
        out(f"typecheck: {sum(cmp.new.values())} mypy error(s) not in the baseline:")
        for line in _listing(cmp.new):
            out(line)
        out("typecheck: FAILED; fix them (run `python -m mypy` for line numbers)")
        return 1
    if cmp.fixed:
        out(f"typecheck: {sum(cmp.fixed.values())} baseline error(s) no longer occur:")
        for line in _listing(cmp.fixed):
            out(line)
        out("typecheck: note: run `python tools/typecheck.py --update` to shrink the baseline")
    out(
        f"typecheck: OK, {sum(current.values())} error(s), all in the baseline "
        f"({sum(baseline.values())} entries)"
    )
    return 0


def _rel(path: Path) -> str:
    try:
        return path.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


if __name__ == "__main__":
    sys.exit(main())
