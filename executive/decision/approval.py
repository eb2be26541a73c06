"""Operator approval when even the lowest-risk alternative is above the threshold.

The executive never blocks inside a tick, so approval is asynchronous:

1. the selector builds an :class:`ApprovalRequest` (the task, every alternative with
   its risk components, the threshold, the reason) and wraps it in a
   :class:`PendingApproval` with the scenario's timeout;
2. it hands it to an :class:`ApprovalChannel` with ``submit()``, which returns at once;
3. every tick it polls ``pending.decision``: None while waiting (the robot holds);
   an :class:`ApprovalDecision` (approve an alternative, re-plan, deny, abort) once
   answered; an abort "by timeout" once the deadline passes unanswered.

``deny`` (the risk is refused: by the ``deny`` policy, or an operator's ``d``) and
``abort`` (the run is given up: ``q``, end of input, Ctrl-C, a timeout, a halt) both end
the task ``aborted``; the audit log keeps which it was and by whom.

Channels: :class:`PolicyChannel` (``auto`` approves the recommended alternative,
``deny`` denies), :class:`CallbackChannel` (a host function answers now or later),
:class:`HostChannel` (requests wait for the host to answer), :class:`TerminalChannel`
(an interactive prompt in a background thread). :func:`make_channel` picks one
from a mode name.
"""

from __future__ import annotations

import getpass
import math
import os
import select
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import IO, Any, Literal, Protocol

from executive.schema.failure_modes import failure_modes, mode_names

__all__ = [
    "AlternativeRisk",
    "ApprovalChannel",
    "ApprovalDecision",
    "ApprovalRequest",
    "CallbackChannel",
    "HostChannel",
    "PendingApproval",
    "PolicyChannel",
    "TerminalChannel",
    "make_channel",
]

Decision = Literal["approve", "replan", "deny", "abort"]
DECISIONS = ("approve", "replan", "deny", "abort")
MODES = ("prompt", "auto", "deny")


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class AlternativeRisk:
    """One row of a request: an alternative and its predicted risk."""

    name: str
    feasible: bool
    risk: Mapping[str, float] = field(default_factory=dict)
    value: float | None = None  # the ordering quantity (None when infeasible)
    reason: str = ""  # why infeasible
    physics: str = ""  # what the dry run and the rollouts showed, in a line

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "feasible": self.feasible,
            "risk": dict(self.risk),
            "value": self.value,
            "reason": self.reason,
            "physics": self.physics,
        }


@dataclass(frozen=True)
class ApprovalRequest:
    task: str
    alternatives: tuple[AlternativeRisk, ...]  # ranked, lowest value first
    recommended: str | None
    threshold: float
    ordering: str
    reason: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "task": self.task,
            "alternatives": [a.as_dict() for a in self.alternatives],
            "recommended": self.recommended,
            "threshold": self.threshold,
            "ordering": self.ordering,
            "reason": self.reason,
        }

    def feasible(self, name: str) -> bool:
        return any(a.name == name and a.feasible for a in self.alternatives)


@dataclass(frozen=True)
class ApprovalDecision:
    decision: Decision
    alternative: str | None  # the approved alternative (approve only)
    by: str  # policy:auto, policy:deny, timeout, halt, operator:<user>, operator:interrupt, host:<name>, ...
    at: str  # ISO 8601 UTC
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {
            "decision": self.decision,
            "alternative": self.alternative,
            "by": self.by,
            "at": self.at,
            "note": self.note,
        }


class PendingApproval:
    """A request waiting for its decision; thread-safe, the first answer wins."""

    def __init__(
        self, request: ApprovalRequest, timeout_s: float | None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.request = request
        self.timeout_s = timeout_s
        self._clock = clock
        self._deadline = None if timeout_s is None else clock() + timeout_s
        self._lock = threading.Lock()
        self._decision: ApprovalDecision | None = None
        self.resolved = threading.Event()

    def answer(self, decision: ApprovalDecision) -> bool:
        """Record ``decision`` unless one was recorded already; True if it was taken."""
        if decision.decision not in DECISIONS:
            raise ValueError(f"decision must be one of {', '.join(DECISIONS)}, not {decision.decision!r}")
        if decision.decision == "approve":
            if decision.alternative is None or not self.request.feasible(decision.alternative):
                names = [a.name for a in self.request.alternatives if a.feasible]
                raise ValueError(f"cannot approve {decision.alternative!r}; feasible: {', '.join(names)}")
        with self._lock:
            if self._decision is not None:
                return False
            self._decision = decision
        self.resolved.set()
        return True

    @property
    def decision(self) -> ApprovalDecision | None:
        """None while waiting; an abort by ``timeout`` once the deadline has passed unanswered."""
        if self._decision is None and self._deadline is not None and self._clock() >= self._deadline:
            self.answer(
                ApprovalDecision(
                    "abort", None, by="timeout", at=_now(), note=f"no answer in {self.timeout_s:g} s"
                )
            )
        return self._decision

    @property
    def remaining_s(self) -> float | None:
        return None if self._deadline is None else max(0.0, self._deadline - self._clock())

    def cancel(self, by: str) -> None:
        self.answer(ApprovalDecision("abort", None, by=by, at=_now(), note="cancelled"))


class ApprovalChannel(Protocol):
    name: str

    def submit(self, pending: PendingApproval) -> None: ...


class PolicyChannel:
    """Batch policies: ``auto`` approves the recommended alternative, ``deny`` denies (logged ``deny``)."""

    def __init__(self, mode: str) -> None:
        if mode not in ("auto", "deny"):
            raise ValueError(f"policy must be auto or deny, not {mode!r}")
        self.mode = mode
        self.name = f"policy:{mode}"

    def submit(self, pending: PendingApproval) -> None:
        recommended = pending.request.recommended
        if self.mode == "auto" and recommended is not None:
            pending.answer(ApprovalDecision("approve", recommended, by=self.name, at=_now()))
        elif self.mode == "auto":  # nothing feasible to approve
            note = "no feasible alternative to approve"
            pending.answer(ApprovalDecision("abort", None, by=self.name, at=_now(), note=note))
        else:
            pending.answer(ApprovalDecision("deny", None, by=self.name, at=_now()))


class CallbackChannel:
    """``fn(request)`` answers at once (a decision) or later (None, then ``pending.answer``)."""

    def __init__(
        self, fn: Callable[[ApprovalRequest], ApprovalDecision | None], name: str = "callback"
    ) -> None:
        self.fn = fn
        self.name = f"callback:{name}"
        self.submitted: list[PendingApproval] = []

    def submit(self, pending: PendingApproval) -> None:
        self.submitted.append(pending)
        decision = self.fn(pending.request)
        if decision is not None:
            pending.answer(decision)


class HostChannel:
    """Requests wait in ``pending`` until the host answers them."""

    def __init__(self, name: str = "host") -> None:
        self.name = f"host:{name}"
        self._all: list[PendingApproval] = []

    @property
    def pending(self) -> list[PendingApproval]:
        return [p for p in self._all if p.decision is None]

    def submit(self, pending: PendingApproval) -> None:
        self._all.append(pending)

    def approve(
        self, pending: PendingApproval, alternative: str | None = None, by: str | None = None
    ) -> None:
        pending.answer(
            ApprovalDecision(
                "approve", alternative or pending.request.recommended, by=by or self.name, at=_now()
            )
        )

    def abort(self, pending: PendingApproval, by: str | None = None) -> None:
        pending.answer(ApprovalDecision("abort", None, by=by or self.name, at=_now()))

    def deny(self, pending: PendingApproval, by: str | None = None) -> None:
        pending.answer(ApprovalDecision("deny", None, by=by or self.name, at=_now()))


def request_table(request: ApprovalRequest) -> str:
    """The request as the operator sees it."""
    lines = [
        f"APPROVAL NEEDED for {request.task}",
        f"  {request.reason}",
        f"  {'#':>2} {'alternative':<15}"
        + "".join(f"{m.label:>10}" for m in failure_modes())
        + f"{'P(any)':>10}{'exp. loss':>10}",
    ]
    for i, alt in enumerate(request.alternatives, 1):
        mark = "*" if alt.name == request.recommended else " "
        if not alt.feasible:
            lines.append(f"{mark} {i:>2} {alt.name:<15}infeasible: {alt.reason}")
            continue
        r = alt.risk
        lines.append(
            f"{mark} {i:>2} {alt.name:<15}"
            + "".join(_cell(r.get(k)) for k in (*mode_names(), "combined", "expected_loss"))
        )
        if alt.physics:
            lines.append(f"       {alt.physics}")
    lines.append(f"  * recommended (lowest {request.ordering}); threshold {request.threshold:g}")
    return "\n".join(lines)


def _cell(value: float | None) -> str:
    """One number of the prompt's table; ``-`` where the request has none (a mode registered
    after the request was built)."""
    return f"{'-':>10}" if value is None else f"{value:>10.4f}"


class TerminalChannel:
    """An interactive prompt on a terminal, answered in a background thread.

    Enter or ``a``: approve the recommended; a row number or a name: approve that one;
    ``r``: re-plan; ``d``/``deny``: deny; ``q``/``abort``: abort; end of input: abort.

    On a terminal the thread waits for input with ``select`` in short slices, so once the
    request is resolved some other way (timeout, halt, another channel) it stops at once
    without swallowing the operator's next line. Prompts of one channel are shown one at a
    time. Streams without a file descriptor (tests) are read with a plain ``readline``.

    With a timeout, a line above the prompt counts down the seconds left; on a terminal it
    is redrawn in place every second (cursor saved, moved up, restored), so what the
    operator is typing stays where it is. A display that prints on the same terminal sets
    ``wait_for_display`` and calls :meth:`screen_free` once it has printed what precedes a
    request (its risk table): the prompt is drawn after that, never under it.
    """

    PROMPT = "approve [Enter/a] | choose [# or name] | re-plan [r] | deny [d] | abort [q] > "
    POLL_S = 0.05
    DISPLAY_WAIT_S = 5.0  # longest wait for the display before the prompt is drawn anyway

    def __init__(
        self,
        input_stream: IO[str] | None = None,
        output_stream: IO[str] | None = None,
        operator: str | None = None,
    ) -> None:
        self.input = input_stream if input_stream is not None else sys.stdin
        self.output = output_stream if output_stream is not None else sys.stdout
        if operator is None:
            try:
                operator = getpass.getuser()
            except Exception:  # no user name in the environment or the password database
                operator = "unknown"
        self.by = f"operator:{operator}"
        self.name = "prompt"
        self.threads: list[threading.Thread] = []
        self._one_at_a_time = threading.Lock()
        self.wait_for_display = False
        self._screen = threading.Condition()
        self._free_for: list[PendingApproval] = []

    def submit(self, pending: PendingApproval) -> None:
        thread = threading.Thread(target=self._run, args=(pending,), name="approval-prompt", daemon=True)
        self.threads.append(thread)
        thread.start()

    def screen_free(self, pending: PendingApproval) -> None:
        """The display has printed everything before ``pending``: its prompt may be drawn."""
        with self._screen:
            if pending not in self._free_for:
                self._free_for.append(pending)
            self._screen.notify_all()

    def _await_display(self, pending: PendingApproval) -> None:
        if not self.wait_for_display:
            return
        deadline = time.monotonic() + self.DISPLAY_WAIT_S
        with self._screen:
            while pending not in self._free_for and pending.decision is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._screen.wait(min(left, self.POLL_S))

    def _say(self, text: str) -> None:
        self.output.write(text)
        self.output.flush()

    def parse(self, request: ApprovalRequest, line: str) -> ApprovalDecision | str:
        """A decision, or the message to show when the answer is not valid."""
        answer = line.strip()
        names = [a.name for a in request.alternatives]
        if answer.lower() in ("", "a", "approve", "y", "yes"):
            if request.recommended is None:
                return "nothing to approve: no alternative is feasible (r to re-plan, d to deny, q to abort)"
            return ApprovalDecision("approve", request.recommended, by=self.by, at=_now())
        if answer.lower() in ("r", "replan", "re-plan"):
            return ApprovalDecision("replan", None, by=self.by, at=_now())
        if answer.lower() in ("d", "deny", "n", "no"):
            return ApprovalDecision("deny", None, by=self.by, at=_now())
        if answer.lower() in ("q", "quit", "abort"):
            return ApprovalDecision("abort", None, by=self.by, at=_now())
        row = answer.isascii() and answer.isdigit() and 1 <= int(answer) <= len(names)
        chosen = names[int(answer) - 1] if row else answer
        if chosen in names:
            if not request.feasible(chosen):
                return f"{chosen} is infeasible and cannot be approved"
            return ApprovalDecision("approve", chosen, by=self.by, at=_now(), note="chosen by the operator")
        return f"not understood: {answer!r}; valid: Enter/a, 1-{len(names)}, {', '.join(names)}, r, d, q"

    @staticmethod
    def countdown_text(remaining_s: float) -> str:
        """The line above the prompt while a request with a timeout waits."""
        return f"  {math.ceil(remaining_s):d} s left to answer (then abort)"

    def _is_tty(self, stream: IO[str]) -> bool:
        try:
            return os.isatty(stream.fileno())
        except (AttributeError, OSError, ValueError):  # no descriptor (StringIO) or closed
            return False

    def _tick_countdown(self, pending: PendingApproval, shown: list[int]) -> None:
        """Redraw the countdown line above the prompt when its whole second changes."""
        remaining = pending.remaining_s
        if remaining is None or not shown:
            return
        second = math.ceil(remaining)
        if second != shown[0]:
            shown[0] = second
            self._say("\x1b7\x1b[1A\r\x1b[2K" + self.countdown_text(remaining) + "\x1b8")

    def _readable(self, pending: PendingApproval, shown: list[int]) -> bool:
        """Wait until a line can be read (True) or the request is resolved otherwise (False)."""
        if not self._is_tty(self.input):
            return pending.decision is None
        fd = self.input.fileno()
        while pending.decision is None:
            try:
                ready, _, _ = select.select([fd], [], [], self.POLL_S)
            except (OSError, ValueError):  # select cannot watch it (e.g. Windows console)
                return True
            if ready:
                return True
            self._tick_countdown(pending, shown)
        return False

    def _run(self, pending: PendingApproval) -> None:
        while not self._one_at_a_time.acquire(timeout=self.POLL_S):
            if pending.decision is not None:  # resolved while an earlier prompt was showing
                return
        try:
            self._await_display(pending)
            self._ask(pending)
        except (OSError, ValueError) as exc:  # the terminal went away (closed, hung up)
            note = f"terminal error: {exc}"
            pending.answer(ApprovalDecision("abort", None, by=self.by, at=_now(), note=note))
        finally:
            self._one_at_a_time.release()

    def _prompt(self, pending: PendingApproval, shown: list[int]) -> None:
        """The countdown line (with a timeout) and the prompt."""
        remaining = pending.remaining_s
        if remaining is not None:
            live = self._is_tty(self.output)
            shown[:] = [math.ceil(remaining)] if live else []
            self._say(self.countdown_text(remaining) + "\n")
        self._say(self.PROMPT)

    def _ask(self, pending: PendingApproval) -> None:
        request = pending.request
        if pending.decision is not None:
            return
        timeout = f" (abort in {pending.timeout_s:g} s without an answer)" if pending.timeout_s else ""
        self._say("\n" + request_table(request) + timeout + "\n")
        shown: list[int] = []
        while pending.decision is None:
            self._prompt(pending, shown)
            if not self._readable(pending, shown):
                break
            line = self.input.readline()
            if pending.decision is not None:  # resolved meanwhile (timeout, halt)
                break
            if line == "":
                pending.answer(ApprovalDecision("abort", None, by=self.by, at=_now(), note="end of input"))
                break
            result = self.parse(request, line)
            if isinstance(result, str):
                self._say(result + "\n")
                continue
            pending.answer(result)
        decision = pending.decision
        if decision is not None:
            alt = f" {decision.alternative}" if decision.alternative else ""
            lead = "" if decision.by == self.by else "\n"  # the prompt line is still open
            self._say(f"{lead}{decision.decision}{alt} by {decision.by}\n")


def make_channel(mode: str, *, interactive: bool | None = None, fallback: str = "deny") -> ApprovalChannel:
    """``prompt`` (a terminal prompt only when stdin and stdout are terminals, else ``fallback``),
    ``auto`` or ``deny``."""
    if mode not in MODES:
        raise ValueError(f"unknown approval mode {mode!r}; valid: {', '.join(MODES)}")
    if fallback not in ("auto", "deny"):
        raise ValueError(f"unknown approval fallback {fallback!r}; valid: auto, deny")
    if mode == "prompt":
        if interactive is None:
            interactive = sys.stdin.isatty() and sys.stdout.isatty()
        if interactive:
            return TerminalChannel()
        return PolicyChannel(fallback)
    return PolicyChannel(mode)
