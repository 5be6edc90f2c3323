"""The faults campaign in ``make test``: each fault of :mod:`tests.fuzz.faults` once.

The fast faults run here (``nn train`` of the digits stopped by Ctrl-C and by SIGTERM,
the two leaving the same files, a full disk under ``nn train``, and ``batch`` with a
killed worker, its scheduler gone, Ctrl-C while its cluster starts, SIGTERM mid-run);
the task trainers' signal faults (detect, segment, pose, cloud: a minute or more each)
run in ``make fuzz`` (``python -m tests.fuzz --only faults``). A fault still open is listed in
:data:`KNOWN_BROKEN` with its defect: an expected failure, strict, so that the entry
goes once it is fixed.
"""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from tests.fuzz import faults

pytest.importorskip("torch")
pytest.importorskip("distributed")

#: the faults of this file (the rest, tagged "slow", run in make fuzz)
FAST = tuple(name for name, f in faults.FAULTS.items() if "slow" not in f.tags)

#: faults that still break a promise (issue 47, being fixed): name -> the defect
KNOWN_BROKEN: dict[str, str] = {}


def test_every_task_trainer_has_a_signal_fault():
    trainers = {t.argv[1] for t in faults.TRAINERS.values() if t.argv[1] != "train"}
    assert trainers == {"detect", "segment", "pose", "cloud"}
    for name in faults.TRAINERS:
        assert f"train-sigterm:{name}" in faults.FAULTS


def test_outcomes_of_a_fault_are_classified(monkeypatch):
    def broken(workdir: Path, rng: random.Random) -> list[str]:
        assert (workdir / "launch.py").is_file()
        return ["exit 70, not 143"]

    def hangs(workdir: Path, rng: random.Random) -> list[str]:
        raise faults.FaultTimeout("no checkpoint.pt within 1 s")

    monkeypatch.setitem(faults.FAULTS, "broken", faults.Fault("broken", broken))
    monkeypatch.setitem(faults.FAULTS, "hangs", faults.Fault("hangs", hangs))
    monkeypatch.setitem(faults.FAULTS, "fine", faults.Fault("fine", lambda w, r: []))
    out = faults.run_fault("broken")
    assert (out.kind, out.error, out.message) == ("untyped", "promise", "exit 70, not 143")
    assert faults.run_fault("hangs").kind == "hang"
    assert faults.run_fault("fine").kind == "ok"
    tallies = faults.run_faults_campaign(0.0, 0, names=["broken", "fine"])
    assert [(t.target, t.inputs, t.untyped, t.ok) for t in tallies] == [
        ("fault: broken", 1, 1, 0),
        ("fault: fine", 1, 0, 1),
    ]


def test_disk_kind_is_one_of_the_two():
    assert faults.disk_kind() in ("tmpfs", "rlimit")


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(
            n,
            marks=pytest.mark.xfail(strict=True, reason=f"{KNOWN_BROKEN[n]} in progress")
            if n in KNOWN_BROKEN
            else (),
        )
        for n in FAST
    ],
)
def test_fault(name, tmp_path):
    outcome = faults.run_fault(name, seed_=0, workdir=tmp_path)
    assert outcome.kind == "ok", f"{name}: {outcome.kind} {outcome.error}: {outcome.message}"


def test_the_campaign_has_four_parts():
    from tests.fuzz.__main__ import PARTS, parse_args

    assert PARTS == ("api", "flags", "faults", "readers")
    for part in PARTS:
        assert parse_args(["--only", part, "--budget", "60"]).only == part
