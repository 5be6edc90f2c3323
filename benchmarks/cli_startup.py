"""Start-up time of the command: ``robopercept --version``, ``--help`` and ``nn --help``.

``python -m benchmarks.cli_startup``: each command line run 5 times in a fresh process
(the installed ``robopercept`` entry point, as a user types it), wall time from start to
exit; the median and all five are recorded. Beside it, the floor every Python command
pays: ``python -c pass`` and ``python -c "import numpy"`` (what any command that touches
an array pays). The target is ``--version`` and ``--help`` under 0.3 s on the 2-core
machine. Results go to ``benchmarks/results/cli_startup.json``; ``docs/benchmarks.md``
has the table.
"""

from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchmarks._harness import RESULTS, machine

#: the command lines timed (arguments of the entry point), then the interpreter floors
LINES: dict[str, list[str]] = {
    "robopercept --version": ["--version"],
    "robopercept --help": ["--help"],
    "robopercept nn --help": ["nn", "--help"],
    "robopercept edges --help": ["edges", "--help"],
}
FLOORS: dict[str, list[str]] = {
    "python -c pass": ["-c", "pass"],
    "python -c 'import numpy'": ["-c", "import numpy"],
}
RUNS = 5


def _wall(argv: list[str]) -> float:
    """Seconds from start to exit of ``argv`` (its output discarded)."""
    t = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t


def main() -> int:
    entry = shutil.which("robopercept") or str(Path(sys.executable).with_name("robopercept"))
    rows = []
    todo = [(n, [entry, *a]) for n, a in LINES.items()]
    todo += [(n, [sys.executable, *a]) for n, a in FLOORS.items()]
    for name, argv in todo:
        _wall(argv)  # a first run fills the file cache, as for a user's second call
        times = [_wall(argv) for _ in range(RUNS)]
        rows.append(
            {
                "line": name,
                "median_s": round(statistics.median(times), 3),
                "runs_s": [round(t, 3) for t in times],
            }
        )
        print(f"{name:<28} median {statistics.median(times):6.3f} s", flush=True)
    out = {"benchmark": "cli_startup", "machine": machine(), "runs": RUNS, "rows": rows}
    path = RESULTS / "cli_startup.json"
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
