"""The approval section of the console's page: the request, its countdown and the operator's buttons.

Shown while a request submitted to the page's :class:`executive.console.channel.ConsoleChannel`
waits: the task and the reason, the seconds left before the request is aborted, and the
buttons: approve the recommended alternative, choose another (a list of the feasible ones)
and approve it, re-plan, deny, abort. A button answers the request through the channel
(``by`` ``console:<user>``) and the section hides; an answer given elsewhere first (the
terminal, the timeout, a halt) hides it as well.
"""

from __future__ import annotations

import math
import threading
from typing import TYPE_CHECKING, Any

from executive.console.channel import ConsoleChannel
from executive.decision.approval import PendingApproval

if TYPE_CHECKING:
    import viser

__all__ = ["ApprovalPanel", "countdown_text"]


def countdown_text(pending: PendingApproval) -> str:
    """The line that counts down to the request's timeout."""
    remaining = pending.remaining_s
    if remaining is None:
        return "no timeout: the robot holds until answered"
    return f"**{math.ceil(remaining):d} s** left to answer (then abort)"


class ApprovalPanel:
    """The page's approval section for ``channel``'s requests.

    Args:
        server: the console's viser server.
        channel: the console's approval channel.
        order: where the section sits in the panel (smaller is higher).
    """

    def __init__(self, server: viser.ViserServer, channel: ConsoleChannel, order: float) -> None:
        self.server, self.channel = server, channel
        self.folder = server.gui.add_folder("APPROVAL NEEDED", order=order, visible=False)
        self.pending: PendingApproval | None = None
        self._lock = threading.Lock()
        self._widgets: list[Any] = []
        self._countdown: Any = None

    def refresh(self) -> None:
        """Show the channel's waiting request (a new one is laid out), update its countdown, or hide."""
        waiting = self.channel.waiting
        with self._lock:
            if waiting is None:
                if self.pending is not None:
                    self._clear()
                return
            if waiting is not self.pending:
                self._clear()
                self._layout(waiting)
            if self._countdown is not None:
                text = countdown_text(waiting)
                if self._countdown.content != text:
                    self._countdown.content = text

    def _clear(self) -> None:
        for widget in self._widgets:
            widget.remove()
        self._widgets, self._countdown, self.pending = [], None, None
        self.folder.visible = False

    def _layout(self, pending: PendingApproval) -> None:
        request = pending.request
        gui = self.server.gui
        feasible = [a.name for a in request.alternatives if a.feasible]
        with self.folder:
            add = self._widgets.append
            add(gui.add_markdown(f"**{request.task}**  \n{request.reason}"))
            self._countdown = gui.add_markdown(countdown_text(pending))
            add(self._countdown)
            if request.recommended is not None:
                approve = gui.add_button(f"Approve {request.recommended}", color="green")
                approve.on_click(lambda _: self._answer(pending, "approve", request.recommended))
                add(approve)
            if len(feasible) > 1:
                others = [n for n in feasible if n != request.recommended] or feasible
                choice = gui.add_dropdown("Choose another", tuple(others), initial_value=others[0])
                chosen = gui.add_button("Approve the chosen one", color="teal")
                chosen.on_click(
                    lambda _: self._answer(pending, "approve", choice.value, "chosen by the operator")
                )
                add(choice)
                add(chosen)
            replan = gui.add_button("Re-plan", color="blue")
            replan.on_click(lambda _: self._answer(pending, "replan"))
            deny = gui.add_button("Deny", color="orange")
            deny.on_click(lambda _: self._answer(pending, "deny"))
            abort = gui.add_button("Abort", color="red")
            abort.on_click(lambda _: self._answer(pending, "abort"))
            for button in (replan, deny, abort):
                add(button)
        self.pending = pending
        self.folder.visible = True

    def _answer(
        self, pending: PendingApproval, decision: Any, alternative: str | None = None, note: str = ""
    ) -> None:
        """A button's answer (runs in viser's callback thread); the section hides at once."""
        try:
            self.channel.answer(pending, decision, alternative, note)
        except ValueError as exc:  # not a feasible alternative: say so, keep the request open
            with self.folder:
                self._widgets.append(self.server.gui.add_markdown(f"not taken: {exc}"))
            return
        self.refresh()
