"""SIGTERM and SIGHUP as a safe stop, exactly like Ctrl-C, for the ``executive`` command.

Inside :func:`stop_signals_as_interrupt` a SIGTERM or SIGHUP raises :class:`Terminated` (a
``KeyboardInterrupt``) in the main thread, where Ctrl-C raises its ``KeyboardInterrupt``:
every path that handles Ctrl-C (a run's :meth:`executive.runtime.mission.Executive.stop`, a
campaign keeping its trials) handles them too. Only the command installs this: importing the
library changes no signal handler (docs/embedding.md says what a host does instead).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = [
    "STOP_SIGNALS",
    "Terminated",
    "interrupted_text",
    "interrupts_held",
    "stop_reason",
    "stop_signals_as_interrupt",
]

#: The signals that stop the command as Ctrl-C does (besides SIGINT, Python's own).
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGHUP)


class Terminated(KeyboardInterrupt):
    """A stop signal, raised as Ctrl-C raises ``KeyboardInterrupt``; ``name`` says which (``SIGTERM``)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.name = signal.Signals(signum).name
        super().__init__(self.name)


def _raise(signum: int, frame: object) -> None:
    raise Terminated(signum)


@contextlib.contextmanager
def stop_signals_as_interrupt() -> Iterator[None]:
    """Within: SIGTERM and SIGHUP raise :class:`Terminated` in the main thread.

    A signal this process inherited as ignored (``nohup`` ignores SIGHUP) stays ignored, and so
    does one a host set a handler of its own for; the handlers before are put back on leaving.
    Outside the main thread (or where there are no signals) this does nothing.
    """
    previous: dict[signal.Signals, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            if signal.getsignal(signum) is signal.SIG_DFL:
                with contextlib.suppress(ValueError, OSError):
                    previous[signum] = signal.signal(signum, _raise)
    try:
        yield
    finally:
        for held_signal, handler in previous.items():
            signal.signal(held_signal, handler)


@contextlib.contextmanager
def interrupts_held() -> Iterator[list[KeyboardInterrupt]]:
    """Within: Ctrl-C, SIGTERM and SIGHUP, where they would raise, are held instead; the first one
    is put in the list yielded, for the caller to raise once it can stop safely (a run being built).

    Handlers are put back on leaving; outside the main thread this holds nothing.
    """
    held: list[KeyboardInterrupt] = []

    def hold(signum: int, frame: object) -> None:
        if not held:
            held.append(KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum))

    previous: dict[signal.Signals, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, *STOP_SIGNALS):
            if callable(signal.getsignal(signum)):  # a handler that raises (not ignored, not the default)
                previous[signum] = signal.signal(signum, hold)
    try:
        yield held
    finally:
        for held_signal, handler in previous.items():
            signal.signal(held_signal, handler)


def stop_reason(interrupt: KeyboardInterrupt) -> tuple[str, str | None]:
    """The run's stop reason for ``interrupt``, and who answers a request still awaiting approval
    (None: :meth:`executive.runtime.mission.Executive.stop` 's default for Ctrl-C)."""
    if isinstance(interrupt, Terminated):
        return (
            f"stopped by {interrupt.name} (as Ctrl-C): tree halted, robot holding",
            f"signal:{interrupt.name}",
        )
    return "interrupted by the operator (Ctrl-C): tree halted, robot holding", None


def interrupted_text(interrupt: KeyboardInterrupt) -> str:
    """How the command says it was interrupted: ``interrupted`` (Ctrl-C) or ``interrupted by SIGTERM``."""
    return f"interrupted by {interrupt.name}" if isinstance(interrupt, Terminated) else "interrupted"
