"""``python -m tests.fuzz``: the long fuzz campaign behind ``make fuzz``.

Splits a time budget between four parts: the API fuzzer (:mod:`tests.fuzz.api`:
hostile arguments for every public callable), the flags fuzzer (:mod:`tests.fuzz.cli`:
hostile flag values for the commands, through their real parsing and validation), the
faults (:mod:`tests.fuzz.faults`: ``nn train`` and ``batch`` in child processes under
signals, a killed worker, the scheduler gone and a full disk; every fault runs at least
once, even past its share) and the readers' mutation fuzzer
(:mod:`tests.fuzz.readers`: mutated real files for every reader, the rest of the
budget). The first two and the readers run in one :class:`~tests.fuzz.sandbox.Sandbox`.
It prints the summary table (per package, reader, command and fault: inputs, typed
errors, untyped errors, crashes, hangs, memory, peak MiB), the inputs that broke the
contract and the callables skipped with their reasons, and writes everything as JSON.

Exit status: 0 when no input gave an untyped error, a crash, a hang or an allocation
over its bound; 1 otherwise; 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from tests.fuzz.report import Tally, format_findings, format_table, to_json, totals

#: shares of the budget when every part runs (the readers get the rest)
API_SHARE = 0.5
FLAGS_SHARE = 0.12
FAULTS_SHARE = 0.08

#: the parts, in the order they run
PARTS = ("api", "flags", "faults", "readers")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line: ``--budget``, ``--only``, ``--json``, ``--seed``, ``--timeout``."""
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__.splitlines()[0])
    ap.add_argument(
        "--budget", type=float, default=1800.0, help="seconds for the whole campaign (default 1800)"
    )
    ap.add_argument("--only", choices=PARTS, help="run only one of the four campaigns")
    ap.add_argument(
        "--json",
        type=Path,
        default=Path("benchmarks/results/fuzz.json"),
        help="where to write the JSON record (default benchmarks/results/fuzz.json)",
    )
    ap.add_argument("--seed", type=int, default=0, help="campaign seed (default 0)")
    ap.add_argument(
        "--timeout", type=float, default=20.0, help="seconds per call before it counts as a hang"
    )
    ap.add_argument(
        "--memory-mb", type=float, default=2048.0, help="allocation limit per call, MiB"
    )
    ap.add_argument(
        "--packages",
        default="",
        help="comma-separated packages for the API campaign (default: all)",
    )
    args = ap.parse_args(argv)
    if not args.budget > 0:
        ap.error(f"--budget must be > 0 seconds; got {args.budget}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Run the campaign; return the exit status (see the module docstring)."""
    args = parse_args(argv)
    from tests.fuzz.sandbox import Sandbox

    if args.only in (None, "api"):
        from tests.fuzz import api  # makes the API campaign's scratch folder

        all_packages = api.PACKAGES
    else:
        all_packages = ()
    packages = tuple(p for p in args.packages.split(",") if p) or all_packages
    unknown = sorted(set(packages) - set(all_packages)) if all_packages else []
    if unknown:
        print(
            f"unknown package(s) {', '.join(unknown)}: choose from {', '.join(all_packages)}",
            file=sys.stderr,
        )
        return 2
    shares = {"api": API_SHARE, "flags": FLAGS_SHARE, "faults": FAULTS_SHARE}
    budget = {p: (args.budget if args.only == p else 0.0) for p in PARTS}
    if args.only is None:
        budget.update({p: args.budget * share for p, share in shares.items()})
    t0 = time.monotonic()

    def log(line: str) -> None:
        print(f"[{time.monotonic() - t0:7.0f} s] {line}", file=sys.stderr, flush=True)

    tallies: list[Tally] = []
    skipped: dict[str, str] = {}
    broken: list[str] = []
    disk = ""  # how the faults made a full disk: "tmpfs" or "rlimit"
    with Sandbox(timeout=args.timeout, memory_mb=args.memory_mb) as box:
        if args.only in (None, "api"):
            log(f"API campaign: {budget['api']:.0f} s over {len(packages)} packages")
            api_tallies, skipped, broken = api.run_api_campaign(
                budget["api"], args.seed, box, packages=packages, log=log
            )
            tallies += api_tallies
        if args.only in (None, "flags"):
            from tests.fuzz.cli import run_flags_campaign

            log(f"flags campaign: {budget['flags']:.0f} s")
            flag_tallies, flags_broken = run_flags_campaign(
                budget["flags"], args.seed, box, log=log
            )
            tallies += flag_tallies
            broken += flags_broken
        if args.only in (None, "faults"):
            from tests.fuzz.faults import disk_kind, run_faults_campaign

            disk = disk_kind()
            log(f"faults campaign: {budget['faults']:.0f} s (full disk: {disk})")
            tallies += run_faults_campaign(budget["faults"], args.seed, log=log)
        if args.only in (None, "readers"):
            from tests.fuzz.readers import run_readers_campaign

            left = args.budget - (time.monotonic() - t0)
            log(f"readers campaign: {left:.0f} s")
            tallies += run_readers_campaign(max(left, 1.0), args.seed, box)
    seconds = time.monotonic() - t0

    print(format_table(tallies, by_group=True))
    bad_rows = [t for t in tallies if t.bad]
    if bad_rows:
        print("\nTargets with untyped errors, crashes, hangs or memory blow-ups:")
        print(format_table(bad_rows))
        print("\nInputs that broke the contract (first of each kind per target and parameter):")
        print(format_findings(bad_rows))
    if broken:
        print("\nValid calls that did not succeed (not fuzzed):")
        print("\n".join(f"  {b}" for b in broken))
    if skipped:
        print(f"\nSkipped callables ({len(skipped)}):")
        print("\n".join(f"  {name}: {why}" for name, why in sorted(skipped.items())))
    to_json(
        tallies,
        args.json,
        budget_s=args.budget,
        seconds=round(seconds, 1),
        seed=args.seed,
        only=args.only or "all",
        skipped=skipped,
        broken=broken,
        full_disk=disk,
    )
    total = totals(tallies)
    print(
        f"\n{total.inputs} inputs in {seconds:.0f} s: {total.untyped} untyped, "
        f"{total.crashes} crashes, {total.hangs} hangs, {total.memory} memory "
        f"({total.unconfirmed} unconfirmed over-bound peaks); JSON: {args.json}"
    )
    return 1 if total.bad or broken else 0


if __name__ == "__main__":
    sys.exit(main())
