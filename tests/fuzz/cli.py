"""The flags fuzzer: hostile values for the flags of the commands, through the real
argument parsing and validation, in the sandbox (issue 47).

Each command of :data:`COMMANDS` (``nn train``, ``nn detect train``, ``batch``,
``rgbd-import``, ``calibrate``, ...) has a *base* command line: a small valid call
(a few images, one epoch, a tiny model) whose files are the API fuzzer's fixtures,
made on first use in the worker. A fuzz input changes ONE thing of it: a flag's value
replaced by a hostile one (negative, zero, huge, NaN and infinite numbers, empty
strings, sizes such as ``0x0`` or ``99999x99999``, paths that do not exist or are
files where folders go, devices such as ``cuda:99``, Dask addresses such as
``tls://x``, ``ucx://x``, ``tcp://host``, ``tcp://h:99999`` or ``foo://x``), a
switch added or removed, a positional input replaced by a hostile path, a flag given
twice, or an unknown flag. The flags of each command are read off its ``--help``
(:func:`command_flags`); what each one takes is :data:`FLAG_KINDS` (by the flag's
name) and its strategy :data:`HOSTILE`.

The call runs ``robopercept.cli.main.main(argv)`` in the sandbox worker
(:func:`run_cli`), with stdout and stderr captured, in a fresh output folder, and is
classified like an API call:

* exit 0, or still working after :data:`WORK_BUDGET` seconds (the values were
  accepted and the work began: a count such as ``--epochs 2**40`` is the user's
  choice): ``ok``;
* exit 1 or 2 with a one-line ``robopercept: ...`` message on stderr: ``typed``
  (the contract holds: the command refused the value and said why);
* exit 70 (the command's internal error), any other status, a traceback, or an
  exit 1/2 that says nothing: ``untyped`` (a broken contract);
* crash, hang (a call that ignores the budget: native code that never returns) and
  memory as for every sandboxed call (the calls are not traced by tracemalloc, under
  which training runs several times slower: their allocations are bounded by the
  sandbox's address-space limit, and their peak is not reported).
"""

from __future__ import annotations

import contextlib
import functools
import io
import multiprocessing
import os
import re
import shutil
import signal
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

from robopercept.errors import RoboperceptError
from tests.fuzz import api
from tests.fuzz.report import Tally

__all__ = [
    "COMMANDS",
    "FLAG_KINDS",
    "HOSTILE",
    "WARM",
    "WORK_BUDGET",
    "CliContractError",
    "Refused",
    "command_flags",
    "draw_inputs",
    "run_cli",
    "run_command",
    "run_flags_campaign",
    "warm",
]

#: seconds a call may work before it is stopped and counted as accepted (``ok``)
WORK_BUDGET = 8.0

#: the base command lines: ``{name}`` is the path of the API fuzzer's fixture ``name``
#: (:data:`tests.fuzz.api.FIXTURES`, or :data:`FIXTURES` here), ``{out}`` a fresh output
#: folder of the call
COMMANDS: dict[str, tuple[str, ...]] = {
    "nn train": ("nn", "train", "--data", "{images}", "--size", "16x16", "--epochs", "1",
                 "--batch-size", "4", "--model", "vgg_small", "-o", "{out}/run", "--quiet"),
    "nn eval": ("nn", "eval", "{run}", "--data", "digits", "-o", "{out}/confusion.png"),
    "nn predict": ("nn", "predict", "{run}", "{digit.png}", "--top-k", "2"),
    "nn summary": ("nn", "summary", "vgg_small", "--input", "1,16,16", "--classes", "3"),
    "nn models": ("nn", "models", "--kind", "detect"),
    "nn detect train": ("nn", "detect", "train", "--data", "shapes", "--images", "4", "--size",
                        "32x32", "--epochs", "1", "--batch-size", "2", "--width", "4", "--model",
                        "fcos", "-o", "{out}/run", "--quiet"),
    "nn detect eval": ("nn", "detect", "eval", "{detector.pt}", "--data", "{coco_images/gt.json}",
                       "--quiet"),
    "nn detect": ("nn", "detect", "{image.png}", "--model", "{detector.pt}", "-o", "{out}/det",
                  "--quiet"),
    "nn segment train": ("nn", "segment", "train", "--data", "shapes", "--images", "4", "--size",
                         "32x32", "--epochs", "1", "--batch-size", "2", "--width", "4", "-o",
                         "{out}/run", "--quiet"),
    "nn segment eval": ("nn", "segment", "eval", "{shapes_segmenter.pt}", "--data", "shapes",
                        "--images", "4", "--size", "32x32", "--quiet"),
    "nn segment": ("nn", "segment", "{image.png}", "--model", "{segmenter.pt}", "-o",
                   "{out}/seg", "--quiet"),
    "nn pose train": ("nn", "pose", "train", "--data", "figures", "--images", "4", "--size",
                      "32x32", "--epochs", "1", "--batch-size", "2", "--width", "2", "-o",
                      "{out}/run", "--quiet"),
    "nn pose eval": ("nn", "pose", "eval", "{pose.pt}", "--data", "figures", "--images", "4",
                     "--size", "32x32", "--quiet"),
    "nn pose": ("nn", "pose", "{image.png}", "--model", "{pose.pt}", "-o", "{out}/pose",
                "--quiet"),
    "nn cloud train": ("nn", "cloud", "train", "--data", "shapes", "--shapes", "1", "--points",
                       "16", "--epochs", "1", "--batch-size", "4", "--width", "0.125", "-o",
                       "{out}/run", "--quiet"),
    "nn cloud eval": ("nn", "cloud", "eval", "{cloud_shapes_model.pt}", "--data", "shapes",
                      "--shapes", "1", "--points", "8", "--quiet"),
    "nn cloud": ("nn", "cloud", "{cloud.ply}", "--model", "{cloud_model.pt}", "-o",
                 "{out}/cloud", "--quiet"),
    "batch": ("batch", "edges", "{image.png}", "-o", "{out}/batch", "--workers", "1",
              "--connect-timeout", "2", "--quiet"),
    "rgbd-import": ("rgbd-import", "{rgbd_pairs}", "{out}/imported", "--intrinsics",
                    "50,50,32,24", "-q"),
    "calibrate": ("calibrate", "{board0.png}", "{board1.png}", "{board2.png}", "{board3.png}",
                  "--board", "4x3", "--square", "0.03", "-o", "{out}/camera.json", "--quiet"),
}  # fmt: skip

#: what each flag takes (by its name; ``"command:flag"`` where a command differs):
#: a key of :data:`HOSTILE`, or ``"switch"`` (no value: added or removed)
FLAG_KINDS: dict[str, str] = {
    # counts (positive integers)
    **dict.fromkeys(
        [
            "--epochs",
            "--batch-size",
            "--patience",
            "--nproc",
            "--images",
            "--top-k",
            "--max-disparity",
            "--max-frames",
            "--points",
            "--shapes",
            "--stages",
            "--k",
            "--classes",
            "--val-every",
            "--tile",
            "--overlap",
            "--width",
        ],
        "count",
    ),
    "nn cloud train:--width": "real",
    "--workers": "workers",
    "--seed": "int",
    "--min-disparity": "int",
    "--retries": "int",
    **dict.fromkeys(
        [
            "--lr",
            "--dropout",
            "--square",
            "--depth-scale",
            "--fps",
            "--voxel",
            "--lr-check",
            "--score-thresh",
            "--ema",
            "--connect-timeout",
        ],
        "real",
    ),
    "--size": "size",
    "--board": "size",
    "--split": "split",
    "--intrinsics": "list",
    "--tta-scales": "real",
    "--input": "list",
    "--planes": "planes",
    **dict.fromkeys(
        [
            "--optimizer",
            "--schedule",
            "--task",
            "--tta",
            "--format",
            "--preset",
            "--depth-encoding",
            "--method",
            "--detector",
            "--kind",
        ],
        "choice",
    ),
    "--model": "model",
    "nn train:--model": "choice",
    "nn detect train:--model": "choice",
    "nn segment train:--model": "choice",
    "nn pose train:--model": "choice",
    "nn cloud train:--model": "choice",
    "--segment": "model",
    "--data": "data",
    "--images-dir": "path_in",
    **dict.fromkeys(["-o", "--out", "--output", "--overlays", "--undistorted"], "path_out"),
    "--device": "device",
    "--scheduler": "scheduler",
    "--match": "text",
    "--camera-name": "text",
    "--allow-outside-paths": "switch",
    **dict.fromkeys(
        [
            "--augment",
            "--gray",
            "--resume",
            "--overwrite",
            "--json",
            "--quiet",
            "-q",
            "--per-process-bn",
            "--all-scores",
            "--no-flip",
            "--lift3d",
            "--heatmaps",
            "--no-lr-check",
            "--l1-gradient",
        ],
        "switch",
    ),
}

_NUMBERS = ["-1", "0", "-0", "nan", "NaN", "inf", "-inf", "1e309", "1e-320", "1e30",
            str(2**31), str(2**63), "9" * 40, "", " ", "abc", "1.5", "0x10", "1_000", "\u0663",
            "+5", "1e3", "-5.5"]  # fmt: skip

#: hostile values by kind (strings: what a shell passes); ``{scratch}`` is the campaign's
#: input folder, ``{file}`` a regular file, ``{missing}`` a path that does not exist
HOSTILE: dict[str, tuple[str, ...]] = {
    "count": tuple(_NUMBERS),
    "int": tuple(_NUMBERS),
    "real": (*_NUMBERS, "1e-300", "5e-324", "0.9999999999999999", "1.0000001"),
    "size": ("0x0", "-1x5", "99999x99999", "100000x1", "8x", "x8", "nanxnan", "8x8x8", "",
             "1e9x1", "8X8", "8,8", "1x1", "2x2", "abc", "0", "\u0663x\u0663"),
    "split": ("0,0,0", "1,0,0", "nan,0.5,0.5", "0.7,0.15", "-1,1,1", "", "a,b,c",
              "0.7,0.15,0.15,0", "inf,0,0", "0.5,0.5,0", "1e308,1e308,1e308"),
    "list": ("0,0,0,0", "nan,1,1,1", "1,1,1", "-5,5,1,1", "1e309,1,1,1", "a,b,c,d", "",
             "1,1,1,1,1", "inf,inf,inf,inf", "0,8,8", "99999,99999,99999", "1,0,8"),
    "planes": ("0:0.1", "-1:0.1", "3:nan", "3", ":", f"{2**40}:1", "3:-1", "3:inf", "a:b",
               "3:0", "", "3:0.1:4"),
    "choice": ("", "bogus", "NONE", " x", "\u00e9"),
    "model": ("{missing}.pt", "{scratch}", "{empty.pt}", "{garbage.pt}",
              "{checkpoint.pt}", "{segmenter.pt}", "{detector.pt}",
              "{cloud_model.pt}", "{pose.pt}", "{image.png}", "bogus",
              "", "fcos", "unet", "pointnet", "hrnet", "digits"),
    "data": ("{missing}", "{empty.json}", "{garbage.json}", "{image.png}",
             "{coco.json}", "{voc.xml}", "{labelme_folder}",
             "{empty}", "{images}", "", "bogus", "digits", "shapes", "figures",
             "{scratch}/nul\x00name"),
    "path_in": ("{missing}", "{missing}/", "{empty}", "{garbage.png}",
                "{image.png}", "{scratch}", "", "{scratch}/nul\x00name",
                "{scratch}/" + "n" * 300, "/dev/null", "/proc/self/status"),
    # outputs stay in the call's own folder (never /dev/null or the shared inputs: a
    # command run as root that replaced /dev/null by its file would break the machine)
    "path_out": ("{file}", "{file}/sub", "", "/proc/x", "{out}/nul\x00name",
                 "{out}/" + "n" * 300, "{out}", "{full}", "{out}/a/../b", "{out}/\u00e9 x"),
    # no huge counts: `batch --workers N` starts N processes, whatever N (see the report
    # of issue 47: the fuzzer does not fork-bomb the machine to show it)
    "workers": ("-1", "0", "nan", "", "abc", "1.5", "1e3", "0x10", " ", "-0"),
    "device": ("cuda", "cuda:99", "cuda:-1", "cuda:x", "mps", "cpu:0", "cpu:1", "", "tpu",
               "meta", "CPU", "cuda:0,1", "auto:1", "xla"),
    "scheduler": ("tls://x", "ucx://x", "tcp://host", "tcp://h:99999", "foo://x", "tcp://h:-1",
                  "tcp://h:port", "tcp://:0", "tcp://[::1", "inproc://", "", "local ", "LOCAL",
                  "tcp://127.0.0.1:1", "tcp://", "://", "tcp://h:1:2", "ws://x", "tcp://\u00e9:1"),
    "text": ("", "[", "*" * 300, "../x", "\u00e9\u00e8", "a\x00b", "**/**", "{", "-x"),
}  # fmt: skip


class Refused(RoboperceptError):
    """The command exited 1 or 2 with its one-line message (the contract holds)."""


class CliContractError(Exception):
    """The command broke its contract: exit 70 (its internal error), another status, a
    traceback, or an exit 1/2 with no message."""


class _Budget(BaseException):
    """Raised in the worker when a call has worked for :data:`WORK_BUDGET` seconds."""


def _on_alarm(signum: int, frame: Any) -> None:
    raise _Budget


# --------------------------------------------------------------------------- fixtures


def _write_boards(path: Path) -> None:
    """Four 160 x 120 photographs of a 5 x 4-square board (4 x 3 inner corners) seen
    from four poses (``board0.png`` ... ``board3.png`` beside ``path``)."""
    from robopercept.imaging import write_image
    from tests.calibration._render import render_board

    k = np.array([[150.0, 0, 80], [0, 150.0, 60], [0, 0, 1]])
    poses = [
        ((0.3, 0.1, 0.0), (-0.05, -0.04, 0.4)),
        ((-0.25, 0.3, 0.1), (-0.04, -0.03, 0.45)),
        ((0.1, -0.35, -0.1), (-0.05, -0.05, 0.4)),
        ((0.3, 0.25, 0.05), (-0.06, -0.03, 0.42)),
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    for i, (rvec, tvec) in enumerate(poses):
        img = render_board(k, np.zeros(5), rvec, tvec, pattern=(4, 3), square=0.03,
                           size=(160, 120), ss=2)  # fmt: skip
        write_image(path.parent / f"board{i}.png", img)


def _write_digit(path: Path) -> None:
    """An 8 x 8 light-on-dark digit picture (what the digits model expects)."""
    from robopercept.imaging import write_image

    img = np.zeros((8, 8), np.uint8)
    img[1:7, 3:5] = 255
    write_image(path, img)


#: fixtures of this module (the rest are the API fuzzer's)
FIXTURES: dict[str, Callable[[Path], None]] = {
    **{f"board{i}.png": _write_boards for i in range(4)},
    "digit.png": _write_digit,
}


def _fixture(name: str) -> str:
    """The path of fixture ``name``, made on first use (in the worker)."""
    path = api.IN_DIR / name
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        if name.startswith("empty"):
            path.touch()
        elif name.startswith("garbage"):
            path.write_bytes(np.random.default_rng(0).integers(0, 256, 512, np.uint8).tobytes())
        elif name in FIXTURES:
            FIXTURES[name](path)
        else:
            api.Fixture(name).make()
    return str(path)


def _fill(token: str, out: str) -> str:
    """``token`` with its ``{...}`` placeholders filled in."""

    def sub(m: re.Match[str]) -> str:
        key = m.group(1)
        if key == "out":
            return out
        if key == "scratch":
            return str(api.IN_DIR)
        if key == "missing":
            return str(api.IN_DIR / "missing" / "nothing")
        if key == "file":  # a regular file where a folder may go (the call's own)
            path = Path(out) / "afile"
            path.write_bytes(b"x")
            return str(path)
        if key == "full":  # a folder that holds something
            path = Path(out) / "full"
            path.mkdir(exist_ok=True)
            (path / "keep.txt").write_text("x")
            return str(path)
        return _fixture(key)

    return re.sub(r"\{([\w./-]+)\}", sub, token)


# --------------------------------------------------------------------------- the call


def warm() -> None:
    """Import what the commands import lazily (torch, the task wings, Dask, matplotlib):
    the sandbox makes this call in every new worker before its first measured one
    (:meth:`~tests.fuzz.sandbox.Sandbox.warm`), so that no call pays for the imports --
    and no :data:`WORK_BUDGET` alarm stops one half-way, which would leave a module
    half-imported for every later call of that worker."""
    import importlib
    import tracemalloc

    import matplotlib

    tracemalloc.stop()  # imports traced run several times slower; a warm-up is not measured

    matplotlib.use("Agg")
    for name in ("matplotlib.pyplot", "torch", "torch.nn", "torch.optim", "torch._dynamo",
                 "robopercept.cli.main", "robopercept.nn.classification.run",
                 "robopercept.nn.detection.run", "robopercept.nn.segmentation.run",
                 "robopercept.nn.pose.run", "robopercept.nn.cloud.run", "robopercept.nn.predict",
                 "robopercept.pipelines.batch", "distributed"):  # fmt: skip
        importlib.import_module(name)
    from robopercept.cli.main import build_parser

    build_parser()


#: the warm-up call of the sandbox (see :func:`warm`)
WARM = ("tests.fuzz.cli:warm", (), {})


def run_cli(argv: Sequence[str], budget: float = WORK_BUDGET) -> int | None:
    """Run ``robopercept *argv`` in this process (the sandbox worker) and check its
    contract.

    Parameters
    ----------
    argv : sequence of str
        The command line, with ``{fixture}`` and ``{out}`` placeholders.
    budget : float
        Seconds the command may work; then it is stopped (the values were accepted).

    Returns
    -------
    int or None
        0, or None when the command was stopped at the budget.

    Raises
    ------
    Refused
        Exit 1 or 2 with a message (a typed outcome).
    CliContractError
        Exit 70 or any other status, a traceback, or a refusal without a message.
    """
    import tracemalloc

    from robopercept.cli.main import main

    # not traced: a command that trains runs several times slower under tracemalloc;
    # its memory stays bounded by the sandbox's address-space limit (kind "memory")
    tracemalloc.stop()
    cwd = api.WORKDIR / "cwd"
    cwd.mkdir(parents=True, exist_ok=True)
    here = os.getcwd()
    os.chdir(cwd)  # a relative output lands in the scratch folder
    api.OUT_DIR.mkdir(parents=True, exist_ok=True)
    out = tempfile.mkdtemp(prefix="cli-", dir=api.OUT_DIR)
    args = [_fill(a, out) for a in argv]
    # a LocalCluster (batch) starts worker processes: the sandbox worker is a daemon,
    # which multiprocessing forbids to have children; it is a disposable process
    multiprocessing.current_process()._config["daemon"] = False  # type: ignore[attr-defined]
    stdout, stderr = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    code: Any = None
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            signal.setitimer(signal.ITIMER_REAL, budget)
            try:
                code = main(args)
            except SystemExit as exc:  # --help, or a library calling sys.exit
                code = exc.code if isinstance(exc.code, int) else 1
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
    except _Budget:
        code = None
    finally:
        signal.signal(signal.SIGALRM, previous)
        shutil.rmtree(out, ignore_errors=True)
        os.chdir(here)
    err = stderr.getvalue()
    last = next((ln for ln in reversed(err.strip().splitlines()) if ln.strip()), "")
    # the budget's alarm may land in a finalizer, which prints it and goes on: not the
    # command's traceback
    traceback = "Traceback (most recent call last)" in err and "_Budget" not in err
    if traceback or "internal error" in err:
        raise CliContractError(f"exit {code}: {last}")
    if code in (0, None):
        return code
    if code in (1, 2):
        if not last.startswith("robopercept"):
            raise CliContractError(f"exit {code} without a message (stderr: {last!r})")
        raise Refused(f"exit {code}: {last}")
    raise CliContractError(f"exit {code}: {last}")


# --------------------------------------------------------------------------- the flags


@functools.cache
def command_flags(command: str) -> dict[str, bool]:
    """The flags of ``command`` read off its ``--help``: flag -> takes a value.

    Parameters
    ----------
    command : str
        A key of :data:`COMMANDS`.

    Returns
    -------
    dict
        ``{"--epochs": True, "--quiet": False, ...}`` (``-h``/``--help`` and
        ``--debug`` left out; a flag with a short and a long name under its long one).
    """
    from robopercept.cli.main import main

    base = COMMANDS[command]
    words = list(base[: len(command.split())])
    if words[:1] == ["nn"] and len(words) == 2 and words[1] in ("detect", "segment", "pose",
                                                                 "cloud"):  # fmt: skip
        words.append("x.png")  # the images form
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        try:
            main([*words, "--help"])
        except SystemExit:
            pass
    text = buf.getvalue()
    section = text.split("options:", 1)[-1]
    flags: dict[str, bool] = {}
    for m in re.finditer(
        r"^  (?:(-\w)(?: ([A-Z_\[\]]+))?, )?(--[\w-]+)(?: (\S+))?", section, re.MULTILINE
    ):
        name = m.group(3)
        if name in ("--help", "--debug"):
            continue
        takes = bool(m.group(4)) and not m.group(4).startswith("show")
        flags[name] = takes
    return flags


def flag_kind(command: str, flag: str) -> str:
    """What ``flag`` of ``command`` takes (:data:`FLAG_KINDS`).

    Raises
    ------
    LookupError
        A flag that the table does not know (a new flag: add it to FLAG_KINDS).
    """
    kind = FLAG_KINDS.get(f"{command}:{flag}") or FLAG_KINDS.get(flag)
    if kind is None:
        raise LookupError(f"{command} {flag}: unknown flag: add it to FLAG_KINDS in {__file__}")
    return kind


def _with_flag(base: tuple[str, ...], flag: str, value: str | None) -> tuple[str, ...]:
    """``base`` with ``flag``'s value replaced by ``value`` (added when absent); a
    switch (``value`` None) is removed when present, added when absent."""
    argv = list(base)
    aliases = {flag, {"--out": "-o", "--output": "-o", "--quiet": "-q"}.get(flag, flag)}
    at = next((i for i, a in enumerate(argv) if a in aliases), None)
    if value is None:
        if at is not None:
            del argv[at]
        else:
            argv.append(flag)
        return tuple(argv)
    if at is not None and at + 1 < len(argv):
        argv[at + 1] = value
        return tuple(argv)
    return (*argv, flag, value)


@dataclass(frozen=True)
class CliInput:
    """One fuzz input: the command line and what was made hostile."""

    command: str
    argv: tuple[str, ...]
    parameter: str
    value: str


def _positionals(command: str) -> list[tuple[int, str]]:
    """The base line's positional placeholders: (index, ``"path_in"`` or
    ``"path_out"``)."""
    base = COMMANDS[command]
    out = []
    for i, a in enumerate(base):
        if i >= len(command.split()) and a.startswith("{") and not base[i - 1].startswith("-"):
            out.append((i, "path_out" if a.startswith("{out}") else "path_in"))
    return out


def _input_strategy(command: str) -> st.SearchStrategy[CliInput]:
    base = COMMANDS[command]
    flags = command_flags(command)
    choices: list[tuple[str, str]] = [(f, flag_kind(command, f)) for f in flags]
    choices += [(f"#{i}", kind) for i, kind in _positionals(command)]
    choices += [("twice", "twice"), ("unknown", "unknown")]

    def build(pick: tuple[str, str], draw_value: Any) -> CliInput:
        param, kind = pick
        if kind == "switch":
            return CliInput(command, _with_flag(base, param, None), param, "(toggled)")
        if kind == "twice":
            flag = next((a for a in base if a.startswith("--")), "--quiet")
            again = (flag, *base[base.index(flag) + 1 :][:1]) if flags.get(flag) else (flag,)
            return CliInput(command, (*base, *again), "twice", flag)
        if kind == "unknown":
            return CliInput(command, (*base, "--bogus-flag", "1"), "--bogus-flag", "1")
        value = draw_value
        if param.startswith("#"):
            argv = list(base)
            argv[int(param[1:])] = value
            return CliInput(command, tuple(argv), param, value)
        return CliInput(command, _with_flag(base, param, value), param, value)

    def values(pick: tuple[str, str]) -> st.SearchStrategy[CliInput]:
        pool = HOSTILE.get(pick[1], ("",))
        return st.sampled_from(pool).map(lambda v, p=pick: build(p, v))

    return st.sampled_from(choices).flatmap(values)


def draw_inputs(command: str, n: int, seed_: int) -> list[CliInput]:
    """``n`` fuzz inputs of ``command``, deterministic in ``seed_``.

    Parameters
    ----------
    command : str
        A key of :data:`COMMANDS`.
    n : int
    seed_ : int

    Returns
    -------
    list of CliInput
    """
    if n <= 0:
        return []
    out: list[CliInput] = []
    strat = _input_strategy(command)

    @seed(seed_)
    @settings(
        max_examples=n,
        database=None,
        deadline=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(strat)
    def collect(v: CliInput) -> None:
        out.append(v)

    collect()
    return out[:n]


@dataclass
class CommandRun:
    """The base call's outcome and the tally of one command's fuzz inputs."""

    command: str
    baseline: Any
    tally: Tally


def run_command(
    command: str,
    sandbox: Any,
    n: int,
    seed_: int,
    *,
    baseline: bool = True,
    budget: float = WORK_BUDGET,
) -> CommandRun:
    """Run the base call of ``command`` and ``n`` hostile variants in ``sandbox``.

    Parameters
    ----------
    command : str
        A key of :data:`COMMANDS`.
    sandbox : Sandbox
        Its time limit must exceed ``budget`` (a call past the budget is stopped in
        the worker; one past the limit is a hang).
    n : int
    seed_ : int
    baseline : bool
        Also run the base call (not counted).
    budget : float
        :data:`WORK_BUDGET` of each call.

    Returns
    -------
    CommandRun
    """
    base = sandbox.run(run_cli, (COMMANDS[command], budget)) if baseline else None
    tally = Tally(f"flags: {command}", "flags")
    for item in draw_inputs(command, n, seed_):
        outcome = sandbox.run(run_cli, (item.argv, budget))
        tally.add(outcome, item.parameter, _show(item.value))
    return CommandRun(command, base, tally)


def _show(value: str) -> str:
    r = repr(value)
    return r if len(r) <= 60 else r[:57] + "..."


def run_flags_campaign(
    budget_s: float,
    seed_: int,
    sandbox: Any,
    *,
    commands: Sequence[str] | None = None,
    batch: int = 4,
    log: Callable[[str], None] | None = None,
) -> tuple[list[Tally], list[str]]:
    """Fuzz every command round-robin until ``budget_s`` seconds have passed.

    Parameters
    ----------
    budget_s : float
    seed_ : int
    sandbox : Sandbox
    commands : sequence of str, optional
        Keys of :data:`COMMANDS` (default all).
    batch : int
        Inputs per command per round.
    log : callable, optional

    Returns
    -------
    tallies : list of Tally
        One per command.
    broken : list of str
        Commands whose base call did not succeed.
    """
    start = time.monotonic()
    sandbox.warm([WARM])
    try:
        return _flags_rounds(start, budget_s, seed_, sandbox, commands, batch, log)
    finally:
        sandbox.warm([])  # the next campaign's workers need no torch


def _flags_rounds(
    start: float,
    budget_s: float,
    seed_: int,
    sandbox: Any,
    commands: Sequence[str] | None,
    batch: int,
    log: Callable[[str], None] | None,
) -> tuple[list[Tally], list[str]]:
    names = list(commands or COMMANDS)
    tallies = {c: Tally(f"flags: {c}", "flags") for c in names}
    broken = []
    active = []
    for c in names:
        b = sandbox.run(run_cli, (COMMANDS[c], WORK_BUDGET))
        if b.kind == "ok":
            active.append(c)
        else:
            broken.append(f"flags: {c}: base call gave {b.kind} {b.error}: {b.message[:160]}")
        if time.monotonic() - start > budget_s:
            break
    round_ = 0
    while active and time.monotonic() - start < budget_s:
        for c in active:
            if time.monotonic() - start >= budget_s:
                break
            r = run_command(c, sandbox, batch, api.plan_seed(seed_, c, round_), baseline=False)
            tallies[c].merge(r.tally)
        round_ += 1
        if log is not None:
            n = sum(t.inputs for t in tallies.values())
            log(f"flags round {round_}: {n} inputs, {time.monotonic() - start:.0f} s")
    return list(tallies.values()), broken
