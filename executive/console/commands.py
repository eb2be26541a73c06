"""What the ``executive`` command does with the console: beside a run, or on its own.

* ``executive run SCENARIO --console``: :func:`open_for_run` starts the page before anything is
  planned (a missing extra is an error before any work); :meth:`RunConsole.approval` makes the
  page the approval channel (with ``--approve prompt`` on a terminal, the prompt as well:
  whichever answers first); :meth:`RunConsole.attach` follows the executive; the ticking loop
  calls :meth:`RunConsole.pace` so the bundled physics moves in real time, watchable.
* ``executive console RUN_OR_SCENARIO``: :func:`serve` shows a run folder's decisions, or plans a
  scenario's alternatives and shows them without executing anything, until Ctrl-C.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from executive.console.channel import EitherChannel
from executive.console.console import Console
from executive.console.live import RealTimePacer
from executive.console.server import ConsoleError
from executive.decision.approval import ApprovalChannel, make_channel

if TYPE_CHECKING:
    from executive.runtime.mission import Executive

__all__ = ["RunConsole", "is_run_folder", "open_for_run", "serve", "serve_replay"]


def _announce(console: Console, what: str) -> None:
    print(f"console   {console.url} ({what}; served on this machine only)", flush=True)


class RunConsole:
    """The console beside ``executive run``: its approval channel, the live view, real-time pacing."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.pacer = RealTimePacer()

    def approval(self, mode: str | None) -> ApprovalChannel | str:
        """The run's approval channel: the page (default and ``prompt``; a terminal's prompt too when
        there is one), or the ``auto``/``deny`` policy when asked for (the page then only shows)."""
        if mode in ("auto", "deny"):
            return mode
        if mode == "prompt" and sys.stdin.isatty() and sys.stdout.isatty():
            return EitherChannel([self.console.channel, make_channel("prompt", interactive=True)])
        return self.console.channel

    def attach(self, executive: Executive) -> None:
        self.console.attach(executive)

    def pace(self, executive: Executive) -> None:
        """After a tick: wait so that robot time keeps to the wall clock."""
        self.pacer.wait(executive.robot.time)

    def close(self) -> None:
        self.console.close()


def open_for_run(port: int, title: str) -> RunConsole:
    """Start the page for a run (port on 127.0.0.1) and print its address.

    Raises:
        ConsoleError: viser (the ``console`` extra) is not installed.
    """
    console = Console(port, title=title)
    _announce(console, "the run live; approve there")
    return RunConsole(console)


def is_run_folder(path: Path) -> bool:
    """A folder a run has written (it holds ``decisions.jsonl``)."""
    return path.is_dir() and (path / "decisions.jsonl").is_file()


def serve(target: str, port: int) -> int:
    """``executive console``: a run folder's decisions, or a scenario planned and not executed, until Ctrl-C.

    Args:
        target: a run folder, or a scenario (file or bundled name).
        port: TCP port on 127.0.0.1.

    Returns:
        0 once stopped with Ctrl-C.

    Raises:
        ConsoleError: viser is not installed, or the folder holds no run.
        ExecutiveError: the scenario is malformed.
    """
    path = Path(target)
    if is_run_folder(path):
        console = Console(port, title=f"run {path.name}")
        try:
            console.show_run(path)
            _announce(console, f"the decisions of {path}")
            return _wait(console)
        finally:
            console.close()
    if path.is_dir():
        raise ConsoleError(f"{target}: a folder but not a run folder (no decisions.jsonl in it)")
    from executive.scenario import load

    scenario = load(target)  # a bad scenario fails here, before any page starts
    console = Console(port, title=scenario.name)
    try:
        console.preview(scenario)
        _announce(console, f"{scenario.name} planned, nothing executed")
        return _wait(console)
    finally:
        console.close()


def serve_replay(run_dir: str, port: int, scenario: str | None = None) -> int:
    """``executive replay RUN_DIR --console``: the run's record with a time slider, and its decisions,
    until Ctrl-C.

    Raises:
        ConsoleError: viser is not installed, or the folder holds no run.
        RecordError: the folder has no readable per-tick record, or its scenario cannot be rebuilt.
    """
    path = Path(run_dir)
    console = Console(port, title=f"replay {path.name}")
    try:
        console.show_run(path, replay=True, scenario=scenario)
        _announce(console, f"the record of {path}, with a time slider")
        return _wait(console)
    finally:
        console.close()


def _wait(console: Console) -> int:
    print("          Ctrl-C to stop", flush=True)
    try:
        console.wait()
    except KeyboardInterrupt:
        pass
    return 0
