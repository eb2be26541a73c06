"""The console as an approval channel: a request waits on the page until the operator answers it there.

Like :class:`executive.decision.approval.HostChannel`, :meth:`ConsoleChannel.submit` only keeps
the request (it never blocks the tick); the page shows it with its countdown and buttons, and
a button calls :meth:`ConsoleChannel.answer`, which answers ``pending`` (first answer wins,
:class:`executive.decision.approval.PendingApproval`). Answers are made ``by`` ``console:<user>``,
the account that started the console: the page is served on 127.0.0.1 only, so whoever
answers is on this machine.

:class:`EitherChannel` submits every request to several channels at once (the console and a
terminal prompt): whichever answers first decides, the others see it answered.
"""

from __future__ import annotations

import getpass
import threading
from collections.abc import Callable, Sequence

from executive.decision.approval import ApprovalChannel, ApprovalDecision, Decision, PendingApproval
from executive.decision.audit import now_iso

__all__ = ["ConsoleChannel", "EitherChannel", "operator_name"]


def operator_name() -> str:
    """The account running this process (``unknown`` when the environment names none)."""
    try:
        return getpass.getuser()
    except Exception:  # no user name in the environment or the password database
        return "unknown"


class ConsoleChannel:
    """Approval requests answered on the console's page.

    Args:
        user: who answers (default: the account running the console); logged as ``console:<user>``.
    """

    def __init__(self, user: str | None = None) -> None:
        self.by = f"console:{user or operator_name()}"
        self.name = "console"
        self._lock = threading.Lock()
        self._all: list[PendingApproval] = []
        #: Called (in the submitting thread, so they must not block) with every new request.
        self.listeners: list[Callable[[PendingApproval], None]] = []

    def submit(self, pending: PendingApproval) -> None:
        with self._lock:
            self._all.append(pending)
        for listener in self.listeners:
            listener(pending)

    @property
    def waiting(self) -> PendingApproval | None:
        """The latest request still waiting for an answer (None: nothing to answer)."""
        with self._lock:
            for pending in reversed(self._all):
                if pending.decision is None:
                    return pending
        return None

    def answer(
        self, pending: PendingApproval, decision: Decision, alternative: str | None = None, note: str = ""
    ) -> bool:
        """Answer ``pending`` as the operator; True if this answer was taken (not one before it).

        Raises:
            ValueError: approving an alternative the request does not offer as feasible.
        """
        return pending.answer(ApprovalDecision(decision, alternative, by=self.by, at=now_iso(), note=note))


class EitherChannel:
    """Every request goes to each of ``channels``; the first answer decides."""

    def __init__(self, channels: Sequence[ApprovalChannel]) -> None:
        if not channels:
            raise ValueError("EitherChannel needs at least one channel")
        self.channels = tuple(channels)
        self.name = "+".join(c.name for c in self.channels)

    def submit(self, pending: PendingApproval) -> None:
        for channel in self.channels:
            channel.submit(pending)
