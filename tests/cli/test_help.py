"""Help texts of the ``robopercept`` command (issue 48): every option and argument says
what it does, every default worth showing is shown (once, by
:class:`~robopercept.cli._args.DefaultsHelpFormatter`), and ``nn --help`` lists all its
tasks."""

from __future__ import annotations

import argparse
import contextlib
import io
import re

import pytest

from robopercept.cli._args import DefaultsHelpFormatter, default_text
from robopercept.cli.main import _Parser, build_parser, main
from robopercept.cli.nn import cloud, detect, pose, segment

#: actions that carry argparse's own help
_OWN = (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)


def _parsers() -> list[argparse.ArgumentParser]:
    """Every parser of the command: the tree of subcommands, and the forms of
    ``nn detect|segment|pose|cloud`` (built only when those commands run)."""
    seen: list[argparse.ArgumentParser] = []

    def visit(p: argparse.ArgumentParser) -> None:
        seen.append(p)
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sub in dict.fromkeys(a.choices.values()):
                    visit(sub)

    visit(build_parser())
    for task in (detect, segment, pose, cloud):
        for form in task._parsers(_Parser).values():
            visit(form)
    return seen


PARSERS = _parsers()


def _actions() -> list[tuple[str, argparse.Action]]:
    return [
        (p.prog, a)
        for p in PARSERS
        for a in p._actions
        if not isinstance(a, _OWN) and a.help is not argparse.SUPPRESS
    ]


def _name(prog: str, a: argparse.Action) -> str:
    return f"{prog} {'/'.join(a.option_strings) or a.dest}"


def test_the_walk_reaches_every_command() -> None:
    progs = {p.prog for p in PARSERS}
    for prog in ("robopercept track", "robopercept learn classify", "robopercept nn train"):
        assert prog in progs
    for prog in ("robopercept nn detect train", "robopercept nn cloud eval"):
        assert prog in progs
    assert len(_actions()) > 400


def test_every_option_and_argument_has_help() -> None:
    missing = [_name(prog, a) for prog, a in _actions() if not (a.help or "").strip()]
    assert not missing, f"{len(missing)} without help text:\n" + "\n".join(missing)


def test_every_default_is_shown() -> None:
    """An option with a default worth showing (not None, False or empty) says it in its
    rendered help: by hand ("default 3", "%(default)s") or by the shared formatter."""
    hidden = []
    for p in PARSERS:
        formatter = p._get_formatter()
        assert isinstance(formatter, DefaultsHelpFormatter), p.prog
        for a in p._actions:
            if isinstance(a, _OWN) or a.help is argparse.SUPPRESS or a.nargs == 0:
                continue
            if default_text(a.default) is None:
                continue
            text = formatter._expand_help(a)
            if "default" not in text.lower():
                hidden.append(_name(p.prog, a))
    assert not hidden, "defaults not shown:\n" + "\n".join(hidden)


def test_written_defaults_match_the_real_ones() -> None:
    """A number written after "default" in a help text is the option's default (a help
    written by hand must not drift from the code)."""
    wrong = []
    for prog, a in _actions():
        help_text = a.help or ""
        if "%(default)" in help_text or isinstance(a.default, bool):
            continue
        if not isinstance(a.default, (int, float)):
            continue
        m = re.search(r"\bdefault:?\s+([-+]?\d[\d.]*(?:e[-+]?\d+)?)", help_text)
        if m and float(m.group(1).rstrip(".")) != pytest.approx(float(a.default)):
            wrong.append(f"{_name(prog, a)}: help says {m.group(1)}, default is {a.default}")
    assert not wrong, "\n".join(wrong)


def test_every_help_renders() -> None:
    """Each parser's help formats (no stray % in a help text) and shows no "None"."""
    for p in PARSERS:
        text = p.format_help()
        assert "(default: None)" not in text and "(default: False)" not in text, p.prog


# --------------------------------------------------------------------------- the formatter
def _help_of(*args: object, **kwargs: object) -> str:
    p = argparse.ArgumentParser(prog="x", formatter_class=DefaultsHelpFormatter)
    p.add_argument(*args, **kwargs)
    return " ".join(p.format_help().split())


def test_formatter_appends_the_default_once() -> None:
    assert "--min-hits MIN_HITS matches (default: 3)" in _help_of(
        "--min-hits", type=int, default=3, help="matches"
    )
    written = _help_of("--cell", type=int, default=8, help="cell size (default: 8)")
    assert written.count("default") == 1


def test_formatter_shows_no_none_false_or_switch_defaults() -> None:
    assert "default" not in _help_of("--gate", type=float, default=None, help="gate")
    assert "default" not in _help_of("--json", action="store_true", help="json")
    assert "default" not in _help_of("--no-x", dest="x", action="store_false", help="no x")
    assert "default" not in _help_of("--pass", action="append", default=[], help="p")
    assert "default" not in _help_of("image", help="input image")


def test_formatter_writes_values_as_typed() -> None:
    assert "(default: 45,35,35)" in _help_of("--hsv-low", default=(45, 35, 35), help="box")
    assert "(default: 1)" in _help_of("--square", type=float, default=1.0, help="side")
    assert "(default: 0.02)" in _help_of("--rate", type=float, default=0.02, help="alpha")
    assert "(default: 0)" in _help_of("--min-disparity", type=int, default=0, help="d")
    assert "(default: 50%)" in _help_of("--share", default="50%", help="share")  # % kept


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (None, None),
        (False, None),
        ([], None),
        ((), None),
        (argparse.SUPPRESS, None),
        (0, "0"),
        (0.0, "0"),
        (2.5, "2.5"),
        (1e-3, "0.001"),
        ("iou", "iou"),
        ((1, 8, 8), "1,8,8"),
        ([0.7, 0.15, 0.15], "0.7,0.15,0.15"),
    ],
)
def test_default_text(value: object, text: str | None) -> None:
    assert default_text(value) == text


def test_track_help_shows_the_flags_of_the_issue() -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main(["track", "--help"])
    text = " ".join(out.getvalue().split())
    for flag, default in (("--min-hits", "3"), ("--max-age", "5"), ("--cost", "iou")):
        assert re.search(rf"{flag} \S+ (?:(?! --).)+? \(default: {default}\)", text), flag


# --------------------------------------------------------------------------- nn --help
def test_nn_help_lists_every_task_with_one_line() -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main(["nn", "--help"])
    text = out.getvalue()
    nn = next(
        a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)
    ).choices["nn"]
    tasks = next(a for a in nn._actions if isinstance(a, argparse._SubParsersAction))
    names = list(tasks.choices)
    for name in ("train", "eval", "predict", "summary", "models"):
        assert name in names
    for name in ("detect", "segment", "pose", "cloud"):
        assert name in names
    helps = {c.dest: c.help for c in tasks._choices_actions}
    for name in names:
        assert helps.get(name), f"nn {name} has no one-line help"
        assert re.search(rf"^\s+{name}\s+\S", text, re.M), f"nn --help does not list {name}"
    # the description speaks of every kind of network, not only the classifiers
    for word in ("classifiers", "detect", "segment", "pose", "cloud"):
        assert word in text
