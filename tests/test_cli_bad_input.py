"""Bad command lines (issue 15): every one is exit 2, names the option or path, and shows no traceback.

Output paths are checked before anything runs: a file where a folder is wanted, a
folder that cannot be written, a path under a file. Read-only folders are made with
``chattr +i`` (immutable), which binds root too (tests here may run as root, whom
permission bits do not stop); without it they fall back to ``chmod`` for other users
and are skipped for root. Numeric options give their valid range.

The cases run the command in-process (``main``), so each is far under a second: an
exception escaping ``main`` fails the test as a traceback would. Two cases run the
installed console script to show the same words reach a user's terminal.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from executive.cli.main import main

SCRIPT = Path(sys.executable).parent / "executive"


def _immutable(folder: Path, on: bool) -> bool:
    chattr = shutil.which("chattr")
    if chattr is None:
        return False
    done = subprocess.run([chattr, "+i" if on else "-i", str(folder)], capture_output=True)
    return done.returncode == 0


@pytest.fixture
def read_only(tmp_path: Path) -> Iterator[Path]:
    """A folder nobody, root included, can create files in (removed writable again after)."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    if _immutable(folder, True):
        yield folder
        _immutable(folder, False)
        return
    if os.geteuid() == 0:
        pytest.skip("root ignores permission bits and chattr +i is not available on this file system")
    folder.chmod(0o555)
    yield folder
    folder.chmod(0o755)


@pytest.fixture
def a_file(tmp_path: Path) -> Path:
    path = tmp_path / "a_file"
    path.write_text("not a folder\n")
    return path


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The default ``runs/`` would be made in the working folder: keep it in the test's own."""
    monkeypatch.chdir(tmp_path)


def _bad(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """Run ``executive argv``; assert exit 2, no traceback, every needle in stderr; return stderr."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own exit
        code = exc.code  # type: ignore[assignment]
    err = capsys.readouterr().err
    assert code == 2, (argv, code, err)
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, (needle, err)
    return err


def _nothing_ran(tmp_path: Path) -> None:
    assert not (tmp_path / "runs").exists()
    leftovers = [p for p in tmp_path.rglob(".executive-probe-*")]
    assert not leftovers, leftovers


# --- output paths ------------------------------------------------------------------------

OUT_COMMANDS = [["run", "book_transfer"], ["campaign", "book_transfer"], ["fidelity", "book_transfer"]]
FOLDER_OPTIONS = [[*cmd, "--out"] for cmd in OUT_COMMANDS] + [["plan", "book_transfer", "--plot"]]


@pytest.mark.parametrize("command", FOLDER_OPTIONS, ids=lambda c: f"{c[0]} {c[-1]}")
def test_a_folder_option_naming_a_file(
    command: list[str], a_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _bad([*command, str(a_file)], capsys, command[-1], str(a_file), "is a file, not a folder")
    _nothing_ran(tmp_path)
    assert a_file.read_text() == "not a folder\n"


@pytest.mark.parametrize("command", FOLDER_OPTIONS, ids=lambda c: f"{c[0]} {c[-1]}")
def test_a_folder_option_under_a_file(
    command: list[str], a_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = a_file / "sub" / "folder"
    _bad([*command, str(path)], capsys, command[-1], str(path), f"inside {a_file}, which is a file")
    _nothing_ran(tmp_path)


@pytest.mark.parametrize("command", FOLDER_OPTIONS, ids=lambda c: f"{c[0]} {c[-1]}")
@pytest.mark.parametrize("inside", [False, True], ids=["itself", "a new folder in it"])
def test_a_folder_option_read_only(
    command: list[str], inside: bool, read_only: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = read_only / "new" if inside else read_only
    _bad([*command, str(path)], capsys, command[-1], str(path), "not writable")
    _nothing_ran(tmp_path)
    assert list(read_only.iterdir()) == []


@pytest.mark.parametrize("command", FOLDER_OPTIONS, ids=lambda c: f"{c[0]} {c[-1]}")
def test_a_folder_option_through_a_loop_of_links(
    command: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    _bad([*command, str(loop / "x")], capsys, command[-1], "broken symbolic link (or a loop")


def test_the_default_run_folder_read_only(
    read_only: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(read_only)
    _bad(["run", "book_transfer"], capsys, "default run folder", "runs", "not writable")


def test_one_alternative_writes_no_run_folder_so_the_default_is_not_checked(
    read_only: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(read_only)  # the check passed: the next one, the alternative's name, speaks
    err = _bad(["run", "book_transfer", "--alternative", "juggle"], capsys, "no alternative 'juggle'")
    assert "run folder" not in err


FILE_OPTIONS = [["show", "book_transfer", "--png", "x.png"], ["run", "book_transfer", "--video", "v.gif"]]


@pytest.mark.parametrize("command", FILE_OPTIONS, ids=lambda c: c[2])
def test_a_file_option_in_a_read_only_folder(
    command: list[str], read_only: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = read_only / command[-1]
    _bad([*command[:-1], str(path)], capsys, command[2], str(path), "not writable")
    _nothing_ran(tmp_path)


@pytest.mark.parametrize("command", FILE_OPTIONS, ids=lambda c: c[2])
def test_a_file_option_whose_parent_is_a_file(
    command: list[str], a_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = a_file / command[-1]
    _bad([*command[:-1], str(path)], capsys, command[2], str(path), "which is a file")
    _nothing_ran(tmp_path)


@pytest.mark.parametrize("command", FILE_OPTIONS, ids=lambda c: c[2])
def test_a_file_option_naming_a_folder(
    command: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "pictures.gif"
    folder.mkdir()
    _bad([*command[:-1], str(folder)], capsys, command[2], str(folder), "is a folder")


@pytest.mark.parametrize("command", FILE_OPTIONS, ids=lambda c: c[2])
def test_a_file_option_with_a_nul_byte(
    command: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _bad([*command[:-1], "bad\0name.gif"], capsys, command[2], "NUL byte")


def test_a_read_only_existing_picture(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "old.png"
    png.write_bytes(b"old")
    if not _immutable(png, True):
        pytest.skip("chattr +i is not available on this file system")
    try:
        _bad(["show", "book_transfer", "--png", str(png)], capsys, "--png", str(png), "not writable")
    finally:
        _immutable(png, False)
    assert png.read_bytes() == b"old"


def test_a_video_that_is_not_a_gif(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _bad(["run", "book_transfer", "--video", "run.mp4"], capsys, "--video run.mp4", ".gif")
    _nothing_ran(tmp_path)


# --- numeric options ---------------------------------------------------------------------

NUMBERS = [
    (["run", "book_transfer", "--seed", "-1"], "--seed", "from 0 to 2**63-1"),
    (["campaign", "book_transfer", "--seed", "-1"], "--seed", "from 0 to 2**63-1"),
    (["fidelity", "book_transfer", "--seed", "-1"], "--seed", "from 0 to 2**63-1"),
    (["run", "book_transfer", "--seed", str(2**63)], "--seed", "from 0 to 2**63-1"),
    (["run", "book_transfer", "--seed", "1.5"], "--seed", "whole number"),
    (["show", "book_transfer", "--png", "x.png", "--width", "0"], "--width", "from 1 to 16384"),
    (["show", "book_transfer", "--png", "x.png", "--width", "-5"], "--width", "from 1 to 16384"),
    (["show", "book_transfer", "--png", "x.png", "--height", "0"], "--height", "from 1 to 16384"),
    (["show", "book_transfer", "--png", "x.png", "--height", "wide"], "--height", "whole number"),
    (["show", "book_transfer", "--png", "x.png", "--width", "99999"], "--width", "from 1 to 16384"),
    (["plan", "book_transfer", "--rollouts", "-1"], "--rollouts", "from 0 to 10000"),
    (["run", "book_transfer", "--rollouts", "-1"], "--rollouts", "from 0 to 10000"),
    (["campaign", "book_transfer", "--trials", "0"], "--trials", "from 1 to 1000000"),
    (["campaign", "book_transfer", "--jobs", "0"], "--jobs", "from 1 to 1024"),
    (["campaign", "book_transfer", "--task", "-1"], "--task", "from 0 to 10000"),
    (["fidelity", "book_transfer", "--jobs", "0"], "--jobs", "from 1 to 1024"),
    (["fidelity", "book_transfer", "--rollouts", "-1"], "--rollouts", "from 0 to 10000"),
]


@pytest.mark.parametrize(
    ("argv", "option", "valid"), NUMBERS, ids=lambda v: " ".join(v) if isinstance(v, list) else v
)
def test_a_number_out_of_range_gives_the_valid_range(
    argv: list[str], option: str, valid: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _bad(argv, capsys, f"argument {option}", valid)
    _nothing_ran(tmp_path)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--variants", "0"], "--variants must be at least 1"),
        (["--trials", "-3"], "--trials must be at least 1"),
    ],
)
def test_fidelity_counts_below_one(argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    """fidelity checks its counts itself (before any variant is made), with the same words."""
    _bad(["fidelity", "book_transfer", *argv], capsys, needle)


# --- the console script ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["show", "book_transfer", "--png", "x.png", "--width", "-5"], "--width"),
        (["run", "x", "--seed", "-1"], "--seed"),
    ],
)
def test_the_console_script_says_the_same(args: list[str], needle: str, tmp_path: Path) -> None:
    cmd = [str(SCRIPT), *args] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main", *args]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=60)
    assert done.returncode == 2
    assert needle in done.stderr and "Traceback" not in done.stderr


# --- after the run -----------------------------------------------------------------------


def test_a_picture_larger_than_the_offscreen_buffer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["show", "book_transfer", "--png", str(tmp_path / "big.png"), "--width", "16000"]
    _bad(argv, capsys, "picture size 16000x720", "--width", "offscreen buffer")
    assert not (tmp_path / "big.png").exists()


def test_a_video_that_cannot_be_saved_after_the_run_keeps_the_outcome(
    read_only: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The folder was writable when the run started and is not when it ends: the video is
    reported lost on stderr and the mission's exit code stands (no exception, no exit 1)."""
    from executive.cli.main import _save_video
    from executive.errors import ExecutiveError
    from executive.report.render import VideoRecorder
    from executive.scenario import load
    from executive.world.model import build

    world = build(load("book_transfer"))
    try:
        recorder = VideoRecorder(world, read_only / "run.gif", width=64, height=48)
    except ExecutiveError as exc:  # no OpenGL context here: nothing to record
        pytest.skip(f"offscreen rendering unavailable: {exc}")
    recorder.capture()
    _save_video(recorder)
    err = capsys.readouterr().err
    assert "the video was not saved" in err and str(read_only / "run.gif") in err
    assert "Traceback" not in err
    assert list(read_only.iterdir()) == []


def test_a_reader_that_goes_away_is_not_an_error() -> None:
    """``executive validate ... | head -1``: the broken pipe ends the command quietly, exit 0."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "executive.cli.main", "validate", "book_transfer"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None
    proc.stdout.readline()
    proc.stdout.close()  # the reader leaves after one line
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert b"Traceback" not in err and b"error" not in err
