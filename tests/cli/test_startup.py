"""Start-up of the ``robopercept`` command (issue 48): building the parser imports no
heavy library, so ``robopercept --help`` and ``--version`` answer at once.

The command modules import the library inside their run functions; the names the parser
needs before any command runs (``choices``, limits in help texts) come from
:mod:`robopercept.cli._constants`, which must equal the library's originals. Wall times
are measured in ``benchmarks/``, not here.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from robopercept import __version__
from robopercept.cli import _constants

#: modules that building the parser must not import: each costs from a tenth of a
#: second (NumPy) to a second or more (scikit-learn, torch, numba) at every call
HEAVY = (
    "numpy",
    "numba",
    "torch",
    "sklearn",
    "scipy",
    "matplotlib",
    "dask",
    "distributed",
    "cv2",
    "open3d",
    "PIL",
    "pandas",
    "tqdm",
)

#: the robopercept modules the parser may load: the package, the CLI and the errors
ALLOWED_OWN = ("robopercept", "robopercept.errors")


def _loaded_after(code: str) -> dict[str, list[str]]:
    """Run ``code`` in a fresh interpreter and return the heavy modules and the
    robopercept modules outside the CLI that it left in ``sys.modules``."""
    probe = (
        "import json, sys\n"
        f"{code}\n"
        f"heavy = [m for m in {HEAVY!r} if m in sys.modules]\n"
        "own = sorted(m for m in sys.modules if m.startswith('robopercept')\n"
        "             and not m.startswith('robopercept.cli')\n"
        f"             and m not in {ALLOWED_OWN!r})\n"
        "print(json.dumps({'heavy': heavy, 'own': own}))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=False
    )
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_building_the_parser_imports_nothing_heavy() -> None:
    found = _loaded_after("from robopercept.cli.main import build_parser\nbuild_parser()")
    assert found == {"heavy": [], "own": []}, (
        "building the parser imported these; import them inside the command's run "
        f"function, and take parse-time names from robopercept.cli._constants: {found}"
    )


@pytest.mark.parametrize("flag", ["--version", "--help"])
def test_version_and_help_import_nothing_heavy(flag: str) -> None:
    code = (
        "import contextlib, io\n"
        "from robopercept.cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n"
        f"        main([{flag!r}])\n"
        "    except SystemExit:\n"
        "        pass\n"
    )
    assert _loaded_after(code) == {"heavy": [], "own": []}


def test_version_and_help_run() -> None:
    for flag, expect in (("--version", f"robopercept {__version__}"), ("--help", "COMMAND")):
        r = subprocess.run(
            [sys.executable, "-m", "robopercept.cli.main", flag],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        assert r.returncode == 0 and expect in r.stdout and not r.stderr, (flag, r)


def test_parse_time_constants_equal_the_library() -> None:
    """The copies the parser uses are the library's values (change both together)."""
    from robopercept.pipelines.batch import JOBS, MAX_WORKERS
    from robopercept.sources import DISTRACTORS, MOTIONS

    assert _constants.BATCH_JOBS == tuple(JOBS)
    assert _constants.BATCH_MAX_WORKERS == MAX_WORKERS
    assert _constants.SCENE_MOTIONS == tuple(MOTIONS)
    assert _constants.SCENE_DISTRACTORS == tuple(DISTRACTORS)


def test_parser_choices_use_the_constants() -> None:
    """``batch JOB`` and the scene flags offer exactly the library's names."""
    from robopercept.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    batch = sub.choices["batch"]
    job = next(a for a in batch._actions if a.dest == "job")
    assert tuple(job.choices) == _constants.BATCH_JOBS
    for command in ("demo", "plane-track", "synth-rgbd"):
        p = sub.choices[command]
        by_dest = {a.dest: a for a in p._actions}
        assert tuple(by_dest["motion"].choices) == _constants.SCENE_MOTIONS
        assert tuple(by_dest["distractor"].choices) == _constants.SCENE_DISTRACTORS
