"""RiskSelector: a py_trees composite that plans, ranks, gates and runs the alternatives of one task.

On entry it plans every alternative of its task on the current estimate, in a planning worker
process (ticks return RUNNING, the robot holds) or in the tick (``background=False``), and takes
the result in a piece a tick. It runs the lowest-risk feasible alternative (``risk.ordering``);
if even that is above ``risk.threshold`` it asks the approval channel first. A failed alternative
makes it look through the robot and re-plan the ones left; a terminal failure ends the task.
Every step is an audit log line before it is acted on.

Its parts: :mod:`~executive.decision.selector_planning` (the job's round trip),
:mod:`~executive.decision.selector_swap` (the result taken in), :mod:`~executive.decision.selector_gate`
(approval), :mod:`~executive.decision.selector_failure` (an ended alternative),
:mod:`~executive.decision.selector_rows` (log rows). How it works: ``docs/selector.md``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
import py_trees

from behaviours.guard import LIVE_RISK_KEY
from behaviours.restance import REPLANNER_KEY
from behaviours.robot_access import NAMESPACE
from executive.decision.approval import ApprovalChannel, ApprovalDecision, PendingApproval
from executive.decision.assessment import AlternativeRisk
from executive.decision.audit import AuditLog
from executive.decision.physics_check import PhysicsCheck
from executive.decision.planning_job import EstimateState, PlanningJob, ranked
from executive.decision.planning_worker import PlanningWorker, WorkerLost
from executive.decision.restance import Approval
from executive.decision.selector_failure import check_placed, closest_call, failure_of, is_terminal
from executive.decision.selector_gate import ApprovalGate
from executive.decision.selector_planning import (
    MAX_WORKER_LOSSES,
    PlanningLink,
    object_state,
    refresh_estimate,
)
from executive.decision.selector_restance import SelectorReplanner
from executive.decision.selector_rows import ranking_rows, risk_row, task_label
from executive.decision.selector_swap import ResultSwap, swap_children
from executive.errors import ExecutiveError
from executive.tasks.base import Task
from executive.tasks.registry import get as task_kind
from executive.world.model import World
from executive.world.observation import measured_qpos, refresh

__all__ = ["MAX_WORKER_LOSSES", "RiskSelector", "risk_row", "task_label"]

Status = py_trees.common.Status
FloatArray = np.ndarray


class RiskSelector(py_trees.composites.Composite):
    """Plan, rank, gate and run the alternatives of one task (see the module docstring).

    Args:
        task: the transfer task.
        estimate: the estimate world (planning and risk see only this).
        channel: where approval requests go.
        log: the audit log.
        timeout_s: approval timeout (None: wait forever).
        guard: wrap motions in live risk guards.
        physics: the physics check (dry runs, rollouts) every decision goes through; None
            only where the caller checks plans in physics itself. With a worker, the worker's
            own check runs (the same rule, its own rollout processes).
        background: plan in a planning worker process (ticks never block); False plans
            inside the tick (blocking, for batch use).
        worker: the planning worker to use (shared by a mission's selectors); None with
            ``background``: the selector starts one of its own on its first decision.
        clock: the clock of approval deadlines.

    The robot comes from the blackboard (``/executive/robot``, see
    :mod:`behaviours.robot_access`): its measured ``data.qpos`` (same layout as the
    estimate's model) is where re-planning starts, and its ``observe_objects()`` (if it
    has one) where the objects are.
    """

    def __init__(
        self,
        name: str,
        task: Task,
        *,
        estimate: World,
        channel: ApprovalChannel,
        log: AuditLog,
        timeout_s: float | None = 60.0,
        guard: bool = True,
        physics: PhysicsCheck | None = None,
        background: bool = True,
        worker: PlanningWorker | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(name=name)
        self.task = task
        self.kind = task_kind(task.kind)
        self.estimate = estimate
        self.channel = channel
        self.log = log
        self.timeout_s = timeout_s
        self.guard = guard
        self.physics = physics
        self.background = background
        self.clock = clock
        risk = estimate.scenario.risk
        self.ordering, self.threshold = risk.ordering, risk.threshold
        self.phase = "idle"  # idle planning awaiting_approval executing done
        self.outcome: str | None = None  # success | failed | aborted
        self.failure: dict[str, Any] | None = None
        self.chosen: str | None = None
        self.chosen_risk: dict[str, Any] | None = None
        self.approval: ApprovalDecision | None = None
        self.pending: PendingApproval | None = None
        self.ranking: list[AlternativeRisk] = []  # feasible, lowest value first
        self.results: list[AlternativeRisk] = []  # every alternative of the last planning
        self.tried: list[str] = []
        self._link = PlanningLink(name, estimate, physics, background=background, worker=worker)
        self._swap = ResultSwap(name, self.kind, guard=guard, log=log)
        self._gate = ApprovalGate(
            name,
            channel=channel,
            log=log,
            ordering=self.ordering,
            threshold=self.threshold,
            timeout_s=timeout_s,
            clock=clock,
        )
        self._by_name: dict[str, py_trees.behaviour.Behaviour] = {}
        self._last_look: float | None = None  # robot time of the last observation
        self._walked = False  # an alternative that walks has run: the base is measured again
        self.bb = self.attach_blackboard_client(name=name, namespace=NAMESPACE)
        self.bb.register_key("robot", access=py_trees.common.Access.READ)
        self.bb.register_key("holding", access=py_trees.common.Access.WRITE)
        self.bb.register_key(LIVE_RISK_KEY, access=py_trees.common.Access.READ)
        self.bb.register_key(REPLANNER_KEY, access=py_trees.common.Access.WRITE)

    @property
    def worker(self) -> PlanningWorker | None:
        """The planning worker the selector uses (None: none yet, or planning in the tick)."""
        return self._link.worker

    @property
    def names(self) -> tuple[str, ...]:
        """The alternatives of the task in the estimate as it stands (the kind's, the scenario's choice)."""
        return tuple(a.name for a in self.kind.alternatives(self.task, self.estimate))

    def measured_state(self) -> tuple[FloatArray, dict[str, tuple[FloatArray, FloatArray]]]:
        """The robot's measured qpos, and the objects as the estimate has them (name -> pose).

        The estimate follows the robot's observations (:meth:`_observe`); this reads, it does not look.
        """
        robot = self.bb.robot
        objects = {name: self.estimate.object_pose(name) for name in self.estimate.ids.object_bodies}
        return measured_qpos(self.estimate, robot), objects

    # --- py_trees life cycle --------------------------------------------------------------

    def setup(self, **kwargs: Any) -> None:
        """Heavy work once: planning inside the tick (``background`` False) builds its planner and
        collision model of the estimate now; a worker builds its own. The behaviours a subtree is
        made of are imported now: subtrees are built in ticks."""
        import behaviours.gripper
        import behaviours.handover
        import behaviours.push  # noqa: F401

        self._link.setup()

    def tick(self) -> Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            self._reset()
            self._start_planning()
        new = self._step()
        if new is None:  # executing: tick the chosen child
            child = self.current_child
            assert child is not None
            yield from child.tick()
            new = self._after_child(child)
        if new != Status.RUNNING:
            self.phase = "done"
            self.stop(new)
        self.status = new
        yield self

    def stop(self, new_status: Status = Status.INVALID) -> None:
        for child in self.children:
            if child.status == Status.RUNNING:
                child.stop(Status.INVALID)
        if new_status == Status.INVALID:
            # halted from above (the run is stopped): answer nothing more, plan nothing more
            if self.pending is not None and self.pending.decision is None:
                self.pending.cancel(by="halt")
            self._link.forget()
        super().stop(new_status)

    def shutdown(self) -> None:
        self._link.close()

    # --- states ---------------------------------------------------------------------------

    def _reset(self) -> None:
        self.phase, self.outcome, self.failure = "idle", None, None
        self.chosen, self.chosen_risk, self.approval, self.pending = None, None, None, None
        self.ranking, self.results, self.tried = [], [], []
        self._link.reset()
        self._swap.reset()
        self._gate.reset()

    def _start_planning(self, observe: str | None = None) -> None:
        """Plan from the measured joints; ``observe``: first update the estimate, for this reason."""
        self.setup()
        if observe is not None:
            self._observe(observe)
        q, observed = self.measured_state()
        q = np.array(q, dtype=float)
        refresh_estimate(self.estimate, q, observed)
        remaining = tuple(a for a in self.names if a not in self.tried)
        task = self.task.restricted(remaining)
        self.log.record(
            "planning",
            task=self.name,
            alternatives=list(remaining),
            replan=bool(self.tried),
            object=object_state(self.estimate, self.task),
        )
        self.phase = "planning"
        monitor = self._monitor()
        job = PlanningJob(
            self.name,
            task,
            q,
            EstimateState.of(self.estimate),
            physics=self.physics is not None,
            guard=monitor is not None,
        )
        self._swap.reset()
        self._link.submit(job, monitor)

    def _monitor(self) -> Any:
        """The live risk monitor the guards use (None: guards off, or none installed)."""
        return self.bb.get(LIVE_RISK_KEY) if self.guard and self.bb.exists(LIVE_RISK_KEY) else None

    def _observe(self, reason: str) -> None:
        """Update the estimate from one look through the robot and log it (``observation``).

        The robot's grasp record (``holding``) loses a hand whose touch no longer holds its object.
        """
        robot = self.bb.robot
        follow = self.kind.moves_base or self._walked  # after (part of) a walk: the base measured again
        fields = refresh(self.estimate, robot, dict(self.bb.holding), reason, follow_base=follow)
        self.bb.holding = dict(fields["holding"])
        self._last_look = robot.time
        self.log.record("observation", task=self.name, **fields)

    def _step(self) -> Status | None:
        """Advance the planning/approval state machine; None means: tick the chosen child."""
        if self.phase == "planning":
            return self._planning_step()
        if self.phase == "awaiting_approval":
            assert self.pending is not None
            decision = self.pending.decision
            if decision is None:
                self.feedback_message = f"waiting for approval: {self.pending.request.reason}"
                return Status.RUNNING
            return self._on_decision(decision)
        if self.phase == "executing":
            return None
        raise ExecutiveError(f"{self.name}: tick in phase '{self.phase}'")

    def _planning_step(self) -> Status | None:
        """Wait for the decision's result; then take it in a piece a tick (:class:`ResultSwap`),
        decide, and tick the chosen subtree from the next tick on (all in one tick when planning
        in the tick)."""
        spread = self.background  # from a worker: keep every tick short
        link, swap = self._link, self._swap
        result = link.result
        if result is None:
            try:
                result = link.receive()
            except WorkerLost as lost:
                return self._on_worker_lost(lost)
            if result is None:
                self.feedback_message = f"planning {self.name}"
                return Status.RUNNING
        if swap.pieces is None:
            failure = result.failure
            if failure is not None:
                return self._finish("failed", {"mode": "planning", "detail": failure.detail()})
            swap.begin(result, self.ordering, self._monitor())
            if spread:
                return Status.RUNNING
        while swap.pieces:
            note = swap.step()
            if note is not None:
                self.feedback_message = note
            if spread:
                return Status.RUNNING
        decided = self._decide(result.results, swap.built)
        if decided is None and spread:  # the chosen subtree's first tick (its motion's set-up) is the next
            return Status.RUNNING
        return decided

    def _on_worker_lost(self, lost: WorkerLost) -> Status:
        """Log the lost worker, start a fresh one and re-plan from where the robot holds."""
        losses = self._link.count_loss()
        fields = {"event": "lost", "reason": lost.reason, "pid": lost.pid, "losses": losses}
        if losses > MAX_WORKER_LOSSES:
            self.log.record("planning_worker", task=self.name, **fields, action="fail the task")
            detail = f"the planning worker was lost {losses} times in a decision; last it {lost.reason}"
            return self._finish("failed", {"mode": "planning", "detail": detail})
        replacement = self._link.replace()
        self.log.record(
            "planning_worker", task=self.name, **fields, action="replaced", replacement=replacement
        )
        self._start_planning()  # the robot held meanwhile: re-plan from where it is
        return Status.RUNNING

    def _decide(
        self, results: Sequence[AlternativeRisk], subtrees: dict[str, py_trees.behaviour.Behaviour]
    ) -> Status | None:
        """Log the plans, rank them and make them the children; start the lowest, or escalate."""
        for alt in results:
            self.log.record("plan", task=self.name, **risk_row(alt, self.ordering))
        feasible = ranked(results, self.ordering)
        self.ranking = feasible
        self.results = list(results)
        self._by_name = swap_children(self, feasible, subtrees)
        if not feasible:
            reasons = "; ".join(f"{a.name}: {a.error}" for a in results) or "no alternatives left"
            self.log.record(
                "selection", task=self.name, chosen=None, reason=f"no feasible alternative ({reasons})"
            )
            return self._finish(
                "failed", {"mode": "planning", "detail": f"no feasible alternative: {reasons}"}
            )
        best = feasible[0]
        assert best.risk is not None
        value = best.risk.value(self.ordering)
        ranking = ranking_rows(feasible, self.ordering)
        if value <= self.threshold:
            self.log.record(
                "selection",
                task=self.name,
                chosen=best.name,
                ordering=self.ordering,
                value=value,
                threshold=self.threshold,
                ranking=ranking,
                reason=f"lowest {self.ordering} {value:.4g} is within the threshold {self.threshold:g}",
            )
            return self._start(best.name)
        label = f"{self.name}: {task_label(self.task)}"
        self.pending = self._gate.escalate(label, feasible, results, ranking)
        self.phase = "awaiting_approval"
        self.channel.submit(self.pending)
        self.feedback_message = f"waiting for approval: {self.pending.request.reason}"
        return Status.RUNNING

    def _on_decision(self, decision: ApprovalDecision) -> Status | None:
        self.approval = decision
        self._gate.answered(decision)
        if decision.decision == "approve" and decision.alternative is not None:
            return self._start(decision.alternative)
        if decision.decision == "replan":
            self._start_planning(observe="before_replan")
            return Status.RUNNING
        if decision.decision == "deny":  # the risk is refused: the task ends as an abort does
            return self._finish("aborted", {"mode": "denied", "detail": f"denied by {decision.by}"})
        return self._finish("aborted", {"mode": "aborted", "detail": f"aborted by {decision.by}"})

    def _start(self, name: str) -> Status | None:
        alt = next(a for a in self.ranking if a.name == name)
        assert alt.risk is not None
        value = alt.risk.value(self.ordering)
        self._gate.check(name, value)  # the risk gate's invariant: raises ExecutiveError
        self.chosen, self.chosen_risk = name, risk_row(alt, self.ordering)
        self._walked = self._walked or bool(alt.plan is not None and any(alt.plan.walks.values()))
        # What follows a walk inside it is re-planned from the measured stance, within this approval.
        approval = Approval.of(value, self.threshold, self.ordering)
        replanner = SelectorReplanner(self.name, name, self._link, self.estimate, self.log, approval)
        self.bb.set(REPLANNER_KEY, replanner)
        self.current_child = self._by_name[name]
        self.tried.append(name)
        self.log.record(
            "execute", task=self.name, alternative=name, value=value, approved=name in self._gate.approved
        )
        self.phase = "executing"
        self.feedback_message = f"executing {name}"
        return None

    def _after_child(self, child: py_trees.behaviour.Behaviour) -> Status:
        status = child.status
        if status == Status.RUNNING:
            tip = child.tip()
            self.feedback_message = f"{child.name}: {tip.feedback_message if tip else ''}"
            return Status.RUNNING
        if status == Status.SUCCESS:
            placed = check_placed(self.kind, self.task, self.estimate, self.bb.robot, self.log, self.name)
            if placed is not None:
                self.log.record("failure", task=self.name, alternative=child.name, **placed)
                self._observe("after_failure")
                return self._finish("failed", placed)
            return self._finish("success", None)
        failure = failure_of(child, self.bb.robot)
        self.log.record("failure", task=self.name, alternative=child.name, **failure)
        self._observe("after_failure")  # the re-plan below starts from this look
        if is_terminal(failure):
            return self._finish("failed", failure)
        left = [a for a in self.names if a not in self.tried]
        if not left:
            return self._finish("failed", failure)
        self.failure = failure
        # The verdict is logged; the next attempt starts from the state the failure left.
        self.bb.robot.detector.acknowledge()
        self._start_planning()
        return Status.RUNNING

    def _finish(self, outcome: str, failure: dict[str, Any] | None) -> Status:
        self.bb.set(REPLANNER_KEY, None)
        self.outcome = outcome
        if failure is not None:
            self.failure = failure
        if self.tried and self._last_look != self.bb.robot.time:  # the robot acted: look again
            self._observe("after_task")
        self.log.record(
            "outcome",
            task=self.name,
            outcome=outcome,
            chosen=self.chosen,
            failure=self.failure,
            closest_call=closest_call(self.bb.robot),
        )
        return Status.SUCCESS if outcome == "success" else Status.FAILURE
