"""The running alternative's re-planner: what follows a walk inside it, planned again where the robot stands.

A selector that starts an alternative puts a :class:`SelectorReplanner` on the blackboard
(:func:`behaviours.restance.install_replanner`); a :class:`behaviours.restance.Restance` after a
walk asks it to re-plan the rest from the measured stance. The work goes where the selector's
planning goes (:class:`~executive.decision.selector_planning.PlanningLink`): to its planning worker
(the ticks go on, the robot holds) or, planning in the tick, at once. The rest's risk is checked
against what was approved (:class:`~executive.decision.restance.Approval`), and every answer is an
audit log line ``restance``.
"""

from __future__ import annotations

from executive.decision.audit import AuditLog
from executive.decision.planning_job import EstimateState, RestanceJob
from executive.decision.planning_worker import WorkerLost
from executive.decision.restance import Approval
from executive.decision.selector_planning import PlanningLink
from executive.planning.restance import RestanceRequest, RestanceResult, restance_fields
from executive.world.model import World

__all__ = ["SelectorReplanner"]


class SelectorReplanner:
    """A :class:`executive.planning.restance.Replanner` for one selector's running alternative.

    Args:
        name: the selector's name (its planner; the log lines' ``task``).
        alternative: the running alternative.
        link: the selector's planning link (its worker, or its planning in the tick).
        estimate: the estimate world (its state goes with the job).
        log: the audit log.
        approval: what was approved of the alternative.
    """

    def __init__(
        self,
        name: str,
        alternative: str,
        link: PlanningLink,
        estimate: World,
        log: AuditLog,
        approval: Approval,
    ) -> None:
        self.name = name
        self.alternative = alternative
        self.link = link
        self.estimate = estimate
        self.log = log
        self.approval = approval
        self._request: RestanceRequest | None = None
        self._ticket: int | None = None
        self._result: RestanceResult | None = None

    def submit(self, request: RestanceRequest) -> None:
        """Send the re-plan to the selector's worker, or (planning in the tick) work it out now."""
        self._request, self._ticket, self._result = request, None, None
        job = RestanceJob(self.name, request, EstimateState.of(self.estimate), self.approval)
        link = self.link
        if not link.background:
            link.setup()
            assert link.local is not None
            self._result = link.local.restance(job)
        elif link.worker is None:
            self._result = RestanceResult(reason="no planning worker to re-plan the rest")
        else:
            try:
                self._ticket = link.worker.submit(job)
            except WorkerLost as lost:
                self._result = RestanceResult(reason=str(lost))

    def poll(self) -> RestanceResult | None:
        """The answer once it has come (logged as a ``restance`` line), else None."""
        if self._result is None and self._ticket is not None:
            assert self.link.worker is not None
            try:
                answer = self.link.worker.poll(self._ticket)
            except WorkerLost as lost:
                answer = RestanceResult(reason=str(lost))
            if answer is None:
                return None
            assert isinstance(answer, RestanceResult)
            self._result, self._ticket = answer, None
        result, self._result = self._result, None
        if result is not None and self._request is not None:
            fields = restance_fields(self._request, result)
            self.log.record("restance", task=self.name, alternative=self.alternative, **fields)
        return result

    def cancel(self) -> None:
        """Forget the request (the behaviour was stopped): a late answer is thrown away."""
        if self._ticket is not None and self.link.worker is not None:
            self.link.worker.forget(self._ticket)
        self._request, self._ticket, self._result = None, None, None
