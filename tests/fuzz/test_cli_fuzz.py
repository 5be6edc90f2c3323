"""The flags fuzzer in ``make test``: a few fixed hostile command lines per command.

Each command of :data:`tests.fuzz.cli.COMMANDS` gets its base call (it must succeed:
otherwise the hostile lines would test nothing) and :data:`EXAMPLES` hostile lines,
drawn with a fixed seed, each run in the sandbox worker through the real parser: every
one must exit 0, 1 or 2 with a message -- never 70 (the command's internal error), a
traceback, a crash or a hang. A command still breaking this is listed in
:data:`KNOWN_UNTYPED` with its defect (strict: the entry goes once it is fixed). The
long campaign is ``make fuzz`` (``python -m tests.fuzz --only flags``).
"""

from __future__ import annotations

import os

import pytest

from tests.fuzz import cli
from tests.fuzz.report import format_findings
from tests.fuzz.sandbox import Sandbox

pytest.importorskip("torch")

#: hostile command lines per command in `make test`
EXAMPLES = 2
#: the seed of the fixed lines
SEED = 47
#: seconds per call before it counts as a hang (the calls stop themselves at
#: cli.WORK_BUDGET); ROBOPERCEPT_FUZZ_TIMEOUT overrides it on a slow machine
TIMEOUT = max(cli.WORK_BUDGET + 30.0, float(os.environ.get("ROBOPERCEPT_FUZZ_TIMEOUT", "40")))

#: commands whose fixed lines still break the contract (issue 47, being fixed)
KNOWN_UNTYPED: dict[str, str] = {}


@pytest.fixture(scope="module")
def sandbox():
    with Sandbox(timeout=TIMEOUT, memory_mb=4096.0) as box:
        box.warm([cli.WARM])
        yield box


def test_every_flag_has_a_kind():
    for command in cli.COMMANDS:
        flags = cli.command_flags(command)
        assert flags, f"{command}: no flag read off its --help"
        for flag in flags:
            assert cli.flag_kind(command, flag) in (*cli.HOSTILE, "switch")


def test_the_scheduler_addresses_of_issue_47_are_tried():
    for address in ("tls://x", "ucx://x", "tcp://host", "tcp://h:99999", "foo://x"):
        assert address in cli.HOSTILE["scheduler"]
    inputs = cli.draw_inputs("batch", 300, 0)
    assert {i.value for i in inputs if i.parameter == "--scheduler"} >= {"tls://x", "ucx://x"}
    assert {i.parameter for i in inputs} >= {"--workers", "--retries", "--output", "#2", "twice"}


def test_a_line_changes_one_thing():
    base = cli.COMMANDS["nn train"]
    for item in cli.draw_inputs("nn train", 40, 1):
        changed = set(item.argv) ^ set(base)
        assert len(item.argv) <= len(base) + 2 and len(changed) <= 3, item


def test_exit_codes_are_classified():
    assert cli.run_cli(("nn", "models", "--kind", "detect")) == 0
    with pytest.raises(cli.Refused, match=r"exit 2: robopercept nn models: argument --kind"):
        cli.run_cli(("nn", "models", "--kind", "bogus"))
    with pytest.raises(cli.Refused, match=r"exit 1: robopercept: error: "):
        cli.run_cli(("nn", "predict", "{missing}.pt", "{image.png}"))


@pytest.mark.parametrize("command", list(cli.COMMANDS))
def test_flags_fuzz(command, sandbox):
    run = cli.run_command(command, sandbox, EXAMPLES, SEED + len(command))
    base = run.baseline
    assert base.kind == "ok", f"{command}: base call gave {base.kind} {base.error}: {base.message}"
    bad = run.tally.bad
    if command in KNOWN_UNTYPED:
        assert bad, f"{command} breaks no contract any more: remove it from KNOWN_UNTYPED"
        pytest.xfail(f"{KNOWN_UNTYPED[command]}:\n{format_findings([run.tally])}")
    assert not bad, f"{command}:\n{format_findings([run.tally])}"
