"""The risk gate of one selector: the approval request above the threshold, the answers, the invariant.

:class:`ApprovalGate` builds and logs the request when even the lowest-risk alternative is above
``risk.threshold`` (:meth:`ApprovalGate.escalate`), logs each answer and remembers what it approved
(:meth:`ApprovalGate.answered`), and refuses to start an alternative above the threshold that no
answer approved (:meth:`ApprovalGate.check`). The selector holds the pending request and polls it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from executive.decision.approval import AlternativeRisk as RequestRow
from executive.decision.approval import ApprovalChannel, ApprovalDecision, ApprovalRequest, PendingApproval
from executive.decision.assessment import AlternativeRisk
from executive.decision.audit import AuditLog
from executive.decision.physics_check import physics_text
from executive.errors import ExecutiveError

__all__ = ["ApprovalGate"]


class ApprovalGate:
    """What needs an operator's approval in one selector's decisions, and what was approved.

    Args:
        task: the selector's name (the ``task`` of its log lines).
        channel: where approval requests go.
        log: the audit log.
        ordering: the scenario's ordering quantity (``risk.ordering``).
        threshold: the scenario's ``risk.threshold``.
        timeout_s: approval timeout (None: wait forever).
        clock: the clock of the requests' deadlines.
    """

    def __init__(
        self,
        task: str,
        *,
        channel: ApprovalChannel,
        log: AuditLog,
        ordering: str,
        threshold: float,
        timeout_s: float | None,
        clock: Callable[[], float],
    ) -> None:
        self.task = task
        self.channel = channel
        self.log = log
        self.ordering, self.threshold = ordering, threshold
        self.timeout_s = timeout_s
        self.clock = clock
        self.approved: set[str] = set()  # alternatives an answer approved in this decision run

    def reset(self) -> None:
        """Forget the approvals (a new run of the task)."""
        self.approved = set()

    def escalate(
        self,
        label: str,
        feasible: Sequence[AlternativeRisk],
        results: Sequence[AlternativeRisk],
        ranking: list[dict[str, Any]],
    ) -> PendingApproval:
        """Log the escalation and the request for the ranked ``feasible`` (lowest first); not yet submitted.

        Args:
            label: the task as the request names it.
            feasible: the feasible alternatives, lowest value first (the first is recommended).
            results: every alternative of the planning (the infeasible ones are listed too).
            ranking: the ``selection`` line's ranking.

        Returns:
            The pending request; the caller hands it to :attr:`channel` once it waits for it.
        """
        best = feasible[0]
        assert best.risk is not None
        value = best.risk.value(self.ordering)
        reason = f"lowest {self.ordering} {value:.4g} ({best.name}) is above the threshold {self.threshold:g}"
        request = ApprovalRequest(
            task=label,
            alternatives=tuple(
                RequestRow(
                    name=a.name,
                    feasible=a.risk is not None,
                    risk=a.risk.as_dict() if a.risk is not None else {},
                    value=a.risk.value(self.ordering) if a.risk is not None else None,
                    reason=a.error,
                    physics=physics_text(a.physics) if a.physics is not None and a.feasible else "",
                )
                for a in [*feasible, *(r for r in results if r.risk is None)]
            ),
            recommended=best.name,
            threshold=self.threshold,
            ordering=self.ordering,
            reason=reason,
        )
        self.log.record(
            "selection", task=self.task, chosen=None, ranking=ranking, reason=reason + ": escalated"
        )
        self.log.record(
            "approval_request", task=self.task, request=request.as_dict(), channel=self.channel.name
        )
        return PendingApproval(request, self.timeout_s, clock=self.clock)

    def answered(self, decision: ApprovalDecision) -> None:
        """Log an answer; an approval of an alternative lets it start above the threshold."""
        self.log.record("approval", task=self.task, **decision.as_dict())
        if decision.decision == "approve" and decision.alternative is not None:
            self.approved.add(decision.alternative)

    def check(self, name: str, value: float) -> None:
        """Raise ExecutiveError if ``name`` (of ``value``) is above the threshold and not approved.

        The invariant of the risk gate; reaching it is a bug, never an operator's choice.
        """
        if value > self.threshold and name not in self.approved:
            raise ExecutiveError(
                f"{name} ({self.ordering} {value:.4g}) is above the threshold without approval"
            )
