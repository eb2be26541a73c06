"""Property: any command line at all gets exit 0, 1 or 2 and never a traceback (issue 15).

Command lines are drawn from the parser's own subcommands and options (so a new option
is covered without touching this file), mixed with garbage tokens, numbers of every
size and sign, and paths of every awkward kind: missing, a file where a folder is
wanted, under a file, read-only (``chattr +i``, which binds root too), with a NUL byte.
No physics runs: the commands that would plan or execute (``run``, ``plan``,
``campaign``, ``fidelity``, ``show``) are given scenarios that do not load, so each
example ends in argument parsing, the output path checks or the scenario loader;
``validate`` and ``list`` are given the bundled scenario too. The commands run
in-process: an exception escaping ``main`` fails the property as a traceback would.
Nothing may be left in the working folder (no ``runs/``, no probe files).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from executive.cli.main import _parser, main

LIGHT = ("validate", "list")  # cheap with a valid scenario: no physics


PATH_OPTIONS = {"out", "plot", "png", "video"}


def _options() -> dict[str, dict[str, tuple[str, list[str]]]]:
    """Per subcommand, its options: option string -> (kind, choices); kind is flag, number,
    path, choice or text (help options left out: the generator adds them now and then)."""
    parser = _parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    table: dict[str, dict[str, tuple[str, list[str]]]] = {}
    for name, sub in subs.choices.items():
        options: dict[str, tuple[str, list[str]]] = {}
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if action.nargs == 0:
                kind = "flag"
            elif action.choices:
                kind = "choice"
            elif action.dest in PATH_OPTIONS:
                kind = "path"
            else:
                kind = "number" if action.type is not None else "text"
            for opt in action.option_strings:
                options[opt] = (kind, [str(c) for c in action.choices or ()])
        table[name] = options
    return table


OPTIONS = _options()


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A working folder with awkward things in it; the tests run there."""
    root = tmp_path_factory.mktemp("cli_properties")
    (root / "a_file").write_text("not a folder\n")
    (root / "empty.yaml").write_text("")
    (root / "garbage.yaml").write_text("{{{{ not: [yaml\n")
    (root / "wrong.yaml").write_text("name: x\nrobot: humanoid\nscene: 3\n")
    (root / "a_folder.yaml").mkdir()
    (root / "read_only").mkdir()
    chattr = shutil.which("chattr")
    locked = chattr is not None and subprocess.run([chattr, "+i", str(root / "read_only")]).returncode == 0
    before = os.getcwd()
    os.chdir(root)
    try:
        yield root
    finally:
        os.chdir(before)
        if locked:
            assert chattr is not None
            subprocess.run([chattr, "-i", str(root / "read_only")], check=True)


BAD_SCENARIOS = [
    "no_such_scenario",
    "book_transfr",
    "missing/scene.yaml",
    "a_file",
    "empty.yaml",
    "garbage.yaml",
    "wrong.yaml",
    "a_folder.yaml",
    "read_only",
    "",
    "-",
    "bad\0name",
]
PATHS = [
    "a_file",
    "a_file/sub",
    "a_file/x.png",
    "read_only",
    "read_only/new",
    "read_only/x.gif",
    "missing/deeper/x.gif",
    "a_folder.yaml",
    "/",
    "",
    "bad\0path",
    "~no_such_user_here/x",
    "x" * 300,
]
WORDS = [
    "auto",
    "prompt",
    "deny",
    "local",
    "ray",
    "left,right",
    ",,",
    "left,juggle",
    "-",
    "--",
    "-h",
    "--help",
]

numbers = st.one_of(
    st.integers(min_value=0, max_value=20).map(str),
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(str),
    st.sampled_from(["0", "-1", "1", "1e308", "0x10", " 3", "3 ", "+2", "1_000", "٣"]),
)
values = st.one_of(numbers, st.sampled_from(PATHS), st.sampled_from(WORDS), st.text(max_size=12))


def _value(draw: st.DrawFn, kind: str, choices: list[str]) -> str:
    """A value for an option of ``kind``: mostly of its kind, sometimes anything."""
    if draw(st.integers(0, 7)) == 0:
        return draw(values)
    if kind == "number":
        return draw(numbers)
    if kind == "path":
        return draw(st.sampled_from(PATHS))
    if kind == "choice":
        return draw(st.sampled_from([*choices, "nope", ""]))
    return draw(st.sampled_from(WORDS) | st.text(max_size=12))


@st.composite
def command_lines(draw: st.DrawFn) -> list[str]:
    """A subcommand (or garbage), a scenario, and some of its options with values of any kind."""
    if draw(st.integers(0, 19)) == 0:  # no subcommand at all, or a made-up one
        return draw(st.lists(st.one_of(st.text(max_size=10), st.sampled_from(WORDS)), max_size=4))
    command = draw(st.sampled_from(sorted(OPTIONS)))
    argv = [command]
    if command in LIGHT and draw(st.integers(0, 2)) == 0:
        argv.append("book_transfer")
    elif command != "list" or draw(st.integers(0, 4)) == 0:
        argv.append(draw(st.sampled_from(BAD_SCENARIOS)))
    options = OPTIONS[command]
    if options:
        for option in draw(st.lists(st.sampled_from(sorted(options)), max_size=4, unique=True)):
            kind, choices = options[option]
            argv.append(option)
            if kind != "flag" and draw(st.integers(0, 19)) > 0:
                argv.append(_value(draw, kind, choices))
    if draw(st.integers(0, 19)) == 0:  # a stray token: an unknown option, help, anything
        argv.insert(
            draw(st.integers(1, len(argv))), draw(st.sampled_from(["--no-such-option", "-h"]) | values)
        )
    return argv


def _run(argv: list[str]) -> tuple[object, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code: object = main(argv)
        except SystemExit as exc:  # argparse's own exit (usage errors, --help)
            code = exc.code if exc.code is not None else 0
    return code, err.getvalue()


def _stage(argv: list[str], err: str) -> str:
    """Where a command line stopped, for ``--hypothesis-show-statistics``."""
    if "usage:" in err:
        return "argument parsing"
    if any(opt in err for opt in ("--out", "--plot", "--png", "--video", "default run folder")):
        return "output path check"
    if "error:" in err:
        return "scenario or option check"
    return "help" if {"-h", "--help"} & set(argv) else argv[0]


@settings(
    max_examples=800,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(argv=command_lines())
def test_any_command_line_exits_0_1_or_2_without_a_traceback(workdir: Path, argv: list[str]) -> None:
    before = sorted(p.name for p in workdir.iterdir())
    code, err = _run(argv)
    event(f"exit {code}: {_stage(argv, err)}")
    assert code in (0, 1, 2), (argv, code, err)
    assert "Traceback" not in err, (argv, err)
    if code == 2:
        assert err.strip(), (argv, "exit 2 without a word")
    assert sorted(p.name for p in workdir.iterdir()) == before, (argv, "left something behind")
    assert list((workdir / "read_only").iterdir()) == []


def test_the_generator_reaches_every_command_and_option() -> None:
    """The parser the property draws from has every subcommand and the options issue 15 names."""
    assert {"list", "validate", "show", "plan", "run", "campaign", "fidelity"} <= set(OPTIONS)
    wanted = [("run", "--seed", "number"), ("run", "--video", "path"), ("show", "--width", "number")]
    wanted += [("plan", "--plot", "path"), ("campaign", "--out", "path"), ("fidelity", "--seed", "number")]
    for command, option, kind in wanted:
        assert OPTIONS[command][option][0] == kind, (command, option)
