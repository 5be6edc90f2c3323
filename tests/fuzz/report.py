"""Counting fuzz outcomes and printing the campaign's summary table.

A :class:`Tally` counts the outcomes of one target (a public function, a method, a
reader): inputs tried, typed errors (a ``RoboperceptError``), untyped errors (any other
exception: the contract is broken), crashes (the worker died: segfault, abort),
hangs (over the time limit), memory (over the allocation limit), the largest traced
allocation and the total time. It also keeps the first few examples of each bad kind
so the table can be followed by the list of inputs to fix.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

__all__ = ["BAD_KINDS", "Finding", "Tally", "format_findings", "format_table", "to_json", "totals"]

#: outcome kinds that break the contract (the campaign exits 1 on any of them)
BAD_KINDS: tuple[str, ...] = ("untyped", "crash", "hang", "memory")


@dataclass(frozen=True)
class Finding:
    """One input that broke the contract: where, with what, and what came out.

    Parameters
    ----------
    target : str
        The callable (``imaging.gaussian_blur``) or reader.
    kind : str
        ``"untyped"``, ``"crash"``, ``"hang"`` or ``"memory"``.
    error : str
        The exception type name, ``"SIGSEGV"``, ``"timeout"`` or ``"MemoryError"``.
    parameter : str
        The parameter that was made hostile (``""`` when none was).
    value : str
        A one-line description of the hostile value.
    message : str
        The first line of the error message.
    """

    target: str
    kind: str
    error: str
    parameter: str
    value: str
    message: str


@dataclass
class Tally:
    """Outcome counts of one target.

    Parameters
    ----------
    target : str
        What was called (``"imaging.gaussian_blur"``, ``"read_pcd"``).
    group : str
        The package or campaign it belongs to (``"imaging"``, ``"readers"``).
    keep : int
        How many findings of each (kind, error, parameter) to keep.

    Attributes
    ----------
    inputs, ok, typed, untyped, crashes, hangs, memory : int
        Counts by outcome kind; ``inputs`` is their sum.
    unconfirmed : int
        Over-bound peaks that a rerun of the same input in a fresh worker did not
        reproduce (not in ``inputs``' sum: the rerun's outcome is counted).
    peak_mb : float
        The largest traced peak allocation of one call, MiB (calls that ran out of
        memory are left out: their peak is the allocation that was refused).
    seconds : float
        Time spent in calls, summed.
    findings : list of Finding
        The first inputs of each bad kind (and of the unconfirmed peaks).
    """

    target: str
    group: str = ""
    keep: int = 3
    inputs: int = 0
    ok: int = 0
    typed: int = 0
    untyped: int = 0
    crashes: int = 0
    hangs: int = 0
    memory: int = 0
    unconfirmed: int = 0
    peak_mb: float = 0.0
    seconds: float = 0.0
    findings: list[Finding] = field(default_factory=list)

    _FIELDS: ClassVar[dict[str, str]] = {
        "ok": "ok",
        "typed": "typed",
        "untyped": "untyped",
        "crash": "crashes",
        "hang": "hangs",
        "memory": "memory",
    }

    def add(self, outcome: Any, parameter: str = "", value: str = "") -> None:
        """Count one outcome (a ``tests.fuzz.sandbox.Outcome``).

        Parameters
        ----------
        outcome : Outcome
            Has ``kind``, ``error``, ``message``, ``seconds`` and ``peak_mb``.
        parameter : str
            The parameter made hostile for this input.
        value : str
            A description of the hostile value.
        """
        attr = self._FIELDS.get(outcome.kind)
        if attr is None:
            raise ValueError(f"unknown outcome kind {outcome.kind!r}")
        setattr(self, attr, getattr(self, attr) + 1)
        self.inputs += 1
        self.seconds += float(outcome.seconds)
        if outcome.kind != "memory":  # a refused allocation was traced, not made
            self.peak_mb = max(self.peak_mb, float(outcome.peak_mb or 0.0))
        if outcome.kind in BAD_KINDS:
            same = [
                f
                for f in self.findings
                if (f.kind, f.error, f.parameter) == (outcome.kind, outcome.error, parameter)
            ]
            if len(same) < self.keep:
                first = (outcome.message or "").strip().splitlines()
                self.findings.append(
                    Finding(
                        self.target,
                        outcome.kind,
                        outcome.error,
                        parameter,
                        value,
                        first[0][:200] if first else "",
                    )
                )

    def add_unconfirmed(self, parameter: str, value: str, message: str) -> None:
        """Record an over-bound peak that a rerun of the same input in a fresh worker
        did not reproduce (``tests.fuzz.readers``): not a finding, kept in view (the
        first :attr:`keep` as findings of kind ``"unconfirmed memory"``)."""
        self.unconfirmed += 1
        if sum(f.kind == "unconfirmed memory" for f in self.findings) < self.keep:
            self.findings.append(
                Finding(self.target, "unconfirmed memory", "", parameter, value, message[:200])
            )

    @property
    def bad(self) -> int:
        """Untyped errors, crashes, hangs and memory blow-ups together."""
        return self.untyped + self.crashes + self.hangs + self.memory

    def merge(self, other: Tally) -> None:
        """Add ``other``'s counts and findings to this tally (same target)."""
        for name in (
            "inputs", "ok", "typed", "untyped", "crashes", "hangs", "memory", "unconfirmed"
        ):  # fmt: skip
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.seconds += other.seconds
        self.peak_mb = max(self.peak_mb, other.peak_mb)
        self.findings.extend(other.findings)

    def as_dict(self) -> dict[str, Any]:
        """The counts and findings as JSON-ready values."""
        return {
            "target": self.target,
            "group": self.group,
            "inputs": self.inputs,
            "ok": self.ok,
            "typed": self.typed,
            "untyped": self.untyped,
            "crashes": self.crashes,
            "hangs": self.hangs,
            "memory": self.memory,
            "unconfirmed_memory": self.unconfirmed,
            "peak_mb": round(self.peak_mb, 2),
            "seconds": round(self.seconds, 3),
            "findings": [vars(f) for f in self.findings],
        }


def totals(tallies: Iterable[Tally], target: str = "total", group: str = "") -> Tally:
    """One tally summing ``tallies`` (findings included).

    Parameters
    ----------
    tallies : iterable of Tally
    target, group : str
        Names of the sum.

    Returns
    -------
    Tally
    """
    out = Tally(target, group)
    for t in tallies:
        out.merge(t)
    return out


_COLUMNS = ("inputs", "ok", "typed", "untyped", "crashes", "hangs", "memory")


def format_table(
    tallies: Sequence[Tally], *, by_group: bool = False, only_bad: bool = False
) -> str:
    """A fixed-width table of the tallies, one row each, the totals last.

    Parameters
    ----------
    tallies : sequence of Tally
    by_group : bool
        Sum the rows of each group into one row (``imaging``, ``readers``) instead of
        one row per target.
    only_bad : bool
        List only the rows with an untyped error, crash, hang or memory blow-up (the
        totals still count every row).

    Returns
    -------
    str
        Columns: target, inputs, ok, typed, untyped, crashes, hangs, memory, peak MiB,
        seconds.
    """
    rows = list(tallies)
    if by_group:
        groups: dict[str, list[Tally]] = {}
        for t in rows:
            groups.setdefault(t.group or t.target, []).append(t)
        shown = [totals(ts, target=g, group=g) for g, ts in groups.items()]
    else:
        shown = rows
    if only_bad:
        shown = [t for t in shown if t.bad]
    total = totals(rows)
    width = max([len("target")] + [len(t.target) for t in shown] + [len("total")])
    head = (
        f"{'target':<{width}} "
        + " ".join(f"{c:>8}" for c in _COLUMNS)
        + f" {'peak MiB':>9} {'seconds':>9}"
    )
    rule = "-" * len(head)
    lines = [head, rule]
    for t in [*shown, total]:
        if t is total:
            lines.append(rule)
        cells = " ".join(f"{getattr(t, c):>8d}" for c in _COLUMNS)
        lines.append(f"{t.target:<{width}} {cells} {t.peak_mb:>9.1f} {t.seconds:>9.1f}")
    return "\n".join(lines)


def format_findings(tallies: Iterable[Tally], limit: int = 200) -> str:
    """The inputs that broke the contract, one line each: target, parameter, value, error.

    Parameters
    ----------
    tallies : iterable of Tally
    limit : int
        At most this many lines.

    Returns
    -------
    str
    """
    lines = []
    for t in tallies:
        for f in t.findings:
            where = f"{f.target}({f.parameter}=...)" if f.parameter else f.target
            lines.append(f"{f.kind:8} {where}: {f.value} -> {f.error}: {f.message}")
    if len(lines) > limit:
        lines = [*lines[:limit], f"... {len(lines) - limit} more"]
    return "\n".join(lines)


def to_json(tallies: Sequence[Tally], path: str | Path | None = None, **meta: Any) -> str:
    """The tallies and their totals as JSON; also written to ``path`` if given.

    Parameters
    ----------
    tallies : sequence of Tally
    path : str or Path, optional
        Where to write (folders are created).
    **meta
        Extra top-level fields (budget, seed, duration).

    Returns
    -------
    str
        The JSON text.
    """
    doc = {**meta, "totals": totals(tallies).as_dict(), "targets": [t.as_dict() for t in tallies]}
    doc["totals"].pop("findings", None)
    text = json.dumps(doc, indent=1, default=str)
    if path is not None:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text + "\n")
    return text
