"""First-use compile time of every command, and how long a user sees nothing (issue 22).

``python -m benchmarks.first_use [NAME ...]``: for each ``robopercept warmup`` workload
(:func:`robopercept.cli.warmup.workloads`: each command on tiny inputs), in a fresh
process with an empty numba cache (``NUMBA_CACHE_DIR`` set to a new folder: what a user
meets on the first run after installing):

* **cold**: wall time of the first run, the compile time it reports ("compiled kernels
  in N s") and the longest stretch with no output on its terminal (stderr on a pseudo
  terminal, so the spinner of :class:`robopercept.jit.CompileNotice` runs as it does for
  a user). Without the notice, the silent wait was the whole compile time.
* **warm**: the same command again with the cache now filled.

Then ``robopercept warmup`` itself, cold (all workloads, 2 workers) and warm. Results go
to ``benchmarks/results/first_use.json``; ``docs/benchmarks.md`` has the table.
"""

from __future__ import annotations

import json
import os
import platform
import pty
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._harness import RESULTS, machine
from robopercept.cli.warmup import workloads
from robopercept.pipelines.samples import make_inputs


def _timed_run(argv: list[str], env: dict[str, str]) -> dict[str, float]:
    """Run ``robopercept ARGV`` with stderr on a pseudo terminal; wall time, the
    reported compile time and the longest silence (seconds)."""
    master, slave = pty.openpty()
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "robopercept.cli.main", *argv],
        stdout=subprocess.DEVNULL,
        stderr=slave,
        env=env,
    )
    os.close(slave)
    last = start
    longest = 0.0
    text = b""
    while True:
        ready, _, _ = select.select([master], [], [], 0.05)
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                chunk = b""
            if not chunk and proc.poll() is not None:
                break
            now = time.perf_counter()
            longest = max(longest, now - last)
            last = now
            text += chunk
        elif proc.poll() is not None:
            break
    proc.wait()
    os.close(master)
    end = time.perf_counter()
    longest = max(longest, end - last)
    compiled = 0.0
    for line in text.decode(errors="replace").replace("\r", "\n").splitlines():
        if "compiled kernels in" in line:
            compiled = float(line.split("compiled kernels in")[1].split()[0])
    return {
        "wall_s": round(end - start, 2),
        "compile_s": compiled,
        "longest_silence_s": round(longest, 2),
        "exit_code": proc.returncode,
    }


def main(argv: list[str] | None = None) -> int:
    names = list(argv if argv is not None else sys.argv[1:])
    rows = []
    with tempfile.TemporaryDirectory(prefix="first-use-") as tmp:
        inputs = make_inputs(Path(tmp) / "in")
        # without --quiet: the compile notice and the bars show, as for a user
        lines = {
            name: [a for a in argv if a != "--quiet"]
            for name, argv in workloads(inputs, Path(tmp) / "out").items()
        }
        chosen = names or list(lines)
        for name in chosen:
            cache = tempfile.mkdtemp(prefix="numba-", dir=tmp)
            env = dict(os.environ, NUMBA_CACHE_DIR=cache)
            cold = _timed_run(lines[name], env)
            warm = _timed_run(lines[name], env)
            rows.append({"name": name, "cold": cold, "warm": warm})
            print(
                f"{name:<22} cold {cold['wall_s']:6.1f} s (compile {cold['compile_s']:5.1f} s,"
                f" longest silence {cold['longest_silence_s']:4.1f} s)  warm {warm['wall_s']:5.1f}"
                f" s  exit {cold['exit_code']}/{warm['exit_code']}",
                flush=True,
            )
        warmup = {}
        if not names:
            cache = tempfile.mkdtemp(prefix="numba-", dir=tmp)
            env = dict(os.environ, NUMBA_CACHE_DIR=cache)
            for key in ("cold", "warm"):
                t = time.perf_counter()
                subprocess.run(
                    [sys.executable, "-m", "robopercept.cli.main", "warmup", "--quiet"],
                    env=env,
                    check=True,
                    stdout=subprocess.DEVNULL,
                )
                warmup[key] = round(time.perf_counter() - t, 1)
            print(f"robopercept warmup: cold {warmup['cold']} s, warm {warmup['warm']} s")
            for row in rows:  # after warmup, a command compiles nothing
                row["after_warmup"] = _timed_run(lines[row["name"]], env)
                if row["after_warmup"]["compile_s"]:
                    print(f"  {row['name']}: still compiled {row['after_warmup']['compile_s']} s")
    out = {
        "benchmark": "first_use",
        "machine": machine(),
        "python": platform.python_version(),
        "workloads": rows,
        "warmup_s": warmup,
    }
    path = RESULTS / "first_use.json"
    if not names:
        path.write_text(json.dumps(out, indent=2) + "\n")
        print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
