"""RiskSelector: a py_trees composite that runs the lowest-risk alternative of a task.

On entry the selector plans and assesses every alternative of its task on the
current estimate (:func:`executive.decision.assessment.assess_task`) in a planning worker
process (:mod:`executive.decision.planning_worker`), so ticks keep returning RUNNING (the
robot holds) while it plans, and keep their period. It then:

1. ranks the feasible alternatives by the scenario's ordering quantity
   (``risk.ordering``: ``weighted_sum``, ``probability`` or ``expected_loss``) and
   makes their subtrees its children, lowest first;
2. if the lowest value is above ``risk.threshold``, escalates: an
   :class:`executive.decision.approval.ApprovalRequest` goes to the approval channel, and the
   selector waits (RUNNING, holding) for the decision: approve (the recommended or
   another alternative), re-plan, or abort (also what a timeout gives);
3. ticks the chosen child. If it fails, the selector re-plans from the current
   state (the robot's measured joints, the objects where the robot now observes
   them) without the alternatives already tried, and goes on with the next.
   A terminal failure (a fall or an unstable simulation: the failure-mode table's
   ``terminal``) ends the task at once: nothing is re-tried on a
   robot that may not be standing.

The estimate follows the objects (:mod:`executive.world.observation`): the selector looks
through the robot and updates the estimate after every failure (``after_failure``; a re-plan
that follows at once starts from that look), before a re-plan an operator asked for
(``before_replan``) and when its task ends after acting (``after_task``, unless it has just
looked), each time with an ``observation`` line in the log.

The worker process does all the heavy work of a decision
(:class:`executive.decision.planning_job.Planning`): it plans and assesses, dry-runs and
rolls out in physics, and computes the planned distances of the lowest-risk alternative's
guarded motions. What comes back is plain data (plans as arrays); the ticks that follow
take it in a piece a tick (:meth:`RiskSelector._swap_pieces`: its log lines, one subtree,
one guarded motion's prepared distances for the live risk monitor ``/executive/live_risk``),
then rank, select and swap the subtrees in; the chosen one is ticked from the next tick on.
A worker that dies or hangs is logged (``planning_worker``) and replaced, and the task
re-plans from where the robot holds. ``background=False`` does the same work inside the
tick instead (blocking: for batch use and tests).

Every step is a line in the audit log (:class:`executive.decision.audit.AuditLog`) before
it is acted on; no alternative above the threshold starts without an approval
line naming it (checked in :meth:`RiskSelector._start`).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import py_trees

from behaviours.guard import LIVE_RISK_KEY, RiskGuard
from behaviours.robot_access import NAMESPACE
from executive.decision.approval import AlternativeRisk as RequestRow
from executive.decision.approval import ApprovalChannel, ApprovalDecision, ApprovalRequest, PendingApproval
from executive.decision.assessment import AlternativeRisk
from executive.decision.audit import AuditLog
from executive.decision.physics_check import PhysicsCheck, PhysicsVerdict, physics_text
from executive.decision.planning_job import (
    EstimateState,
    Planning,
    PlanningJob,
    PlanningResult,
    PreparedKnots,
    ranked,
)
from executive.decision.planning_worker import PlanningWorker, WorkerLost
from executive.errors import ExecutiveError
from executive.execution.runner import behaviour_failure
from executive.risk.collision import breach_summary
from executive.schema.failure_modes import failure_mode, mode_of_verdict
from executive.tasks.base import Task
from executive.tasks.registry import get as task_kind
from executive.world.model import World
from executive.world.observation import refresh

if TYPE_CHECKING:
    from executive.planning.plan import AlternativePlan

__all__ = ["RiskSelector", "task_label"]

Status = py_trees.common.Status
FloatArray = np.ndarray

#: Planning workers lost in one decision before the task fails (each is replaced and re-planned).
MAX_WORKER_LOSSES = 3


def task_label(task: Task) -> str:
    """One line naming the task (its kind's label)."""
    return task.label()


def risk_row(alt: AlternativeRisk, ordering: str) -> dict[str, Any]:
    """One alternative's line for the log and the approval request."""
    row: dict[str, Any] = {"name": alt.name, "feasible": alt.feasible}
    if alt.physics is not None:
        row["physics"] = alt.physics
    if alt.risk is None:
        row["reason"] = alt.error
        return row
    row["risk"] = alt.risk.as_dict()
    breach = breach_summary(alt.risk.components["collision"]) if "collision" in alt.risk.components else None
    if breach is not None:  # touching a breach obstacle (category breach), apart from any collision
        row["breach"] = breach
    row["value"] = alt.risk.value(ordering)
    row["planned_duration_s"] = alt.plan.duration if alt.plan is not None else None
    row["plan_s"], row["assess_s"] = alt.plan_s, alt.assess_s
    return row


class RiskSelector(py_trees.composites.Composite):
    """Plan, rank, gate and run the alternatives of one task (see the module docstring).

    Args:
        task: the transfer task.
        estimate: the estimate world (planning and risk see only this).
        channel: where approval requests go.
        log: the audit log.

    The robot comes from the blackboard (``/executive/robot``, see
    :mod:`behaviours.robot_access`): its measured ``data.qpos`` (same layout as the
    estimate's model) is where re-planning starts, and its ``observe_objects()`` (if it
    has one) where the objects are.
        timeout_s: approval timeout (None: wait forever).
        guard: wrap motions in live risk guards.
        physics: the physics check (dry runs, rollouts) every decision goes through; None
            only where the caller checks plans in physics itself. With a worker, the worker's
            own check runs (the same rule, its own rollout processes).
        background: plan in a planning worker process (ticks never block); False plans
            inside the tick (blocking, for batch use).
        worker: the planning worker to use (shared by a mission's selectors); None with
            ``background``: the selector starts one of its own on its first decision.
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
        self.worker = worker
        self._own_worker = False  # whether this selector started (and closes) its worker
        self._local: Planning | None = None  # the in-tick work (background False)
        self._job: PlanningJob | None = None  # the decision being worked out
        self._ticket: int | None = None  # its ticket with the worker
        self._lost: WorkerLost | None = None  # the worker was found gone when the job was sent
        self._losses = 0  # workers lost in this decision
        self._result: PlanningResult | None = None  # its result, once received
        self._built: dict[str, py_trees.behaviour.Behaviour] = {}  # subtrees built from it so far
        self._swap: list[Callable[[], None]] | None = None  # what is left of taking the result in
        self._approved: set[str] = set()
        self._by_name: dict[str, py_trees.behaviour.Behaviour] = {}
        self._last_look: float | None = None  # robot time of the last observation
        self.bb = self.attach_blackboard_client(name=name, namespace=NAMESPACE)
        self.bb.register_key("robot", access=py_trees.common.Access.READ)
        self.bb.register_key("holding", access=py_trees.common.Access.WRITE)
        self.bb.register_key(LIVE_RISK_KEY, access=py_trees.common.Access.READ)

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
        return np.array(robot.data.qpos, dtype=float), objects

    # --- py_trees life cycle --------------------------------------------------------------

    def setup(self, **kwargs: Any) -> None:
        """Heavy work once: planning inside the tick (``background`` False) builds its planner and
        collision model of the estimate now; a worker builds its own. The behaviours a subtree is
        made of are imported now: subtrees are built in ticks."""
        import behaviours.gripper
        import behaviours.handover
        import behaviours.push  # noqa: F401

        if not self.background and self._local is None:
            self._local = Planning(self.estimate, self.physics)
            self._local.tools(self.name)

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
            if self._ticket is not None and self.worker is not None:
                self.worker.forget(self._ticket)
                self._ticket = None
        super().stop(new_status)

    def shutdown(self) -> None:
        if self._own_worker and self.worker is not None:
            self.worker.close()
            self.worker, self._own_worker = None, False

    # --- states ---------------------------------------------------------------------------

    def _reset(self) -> None:
        self.phase, self.outcome, self.failure = "idle", None, None
        self.chosen, self.chosen_risk, self.approval, self.pending = None, None, None, None
        self.ranking, self.results, self.tried, self._approved = [], [], [], set()
        self._job, self._ticket, self._lost, self._result, self._built = None, None, None, None, {}
        self._losses = 0

    def _start_planning(self, observe: str | None = None) -> None:
        """Plan from the measured joints; ``observe``: first update the estimate, for this reason."""
        self.setup()
        if observe is not None:
            self._observe(observe)
        q, observed = self.measured_state()
        q = np.array(q, dtype=float)
        self._refresh_estimate(q, observed)
        remaining = tuple(a for a in self.names if a not in self.tried)
        task = self.task.restricted(remaining)
        self.log.record(
            "planning",
            task=self.name,
            alternatives=list(remaining),
            replan=bool(self.tried),
            object=self._object_state(),
        )
        self.phase = "planning"
        self._job = PlanningJob(
            self.name,
            task,
            q,
            EstimateState.of(self.estimate),
            physics=self.physics is not None,
            guard=self._monitor() is not None,
        )
        self._submit()

    def _monitor(self) -> Any:
        """The live risk monitor the guards use (None: guards off, or none installed)."""
        return self.bb.get(LIVE_RISK_KEY) if self.guard and self.bb.exists(LIVE_RISK_KEY) else None

    def _submit(self) -> None:
        """Hand the decision's job to the worker, or (``background`` False) work it out now."""
        assert self._job is not None
        self._ticket, self._lost, self._result, self._built, self._swap = None, None, None, {}, None
        if not self.background:
            self.setup()
            assert self._local is not None
            self._local.monitor = self._monitor()
            self._result = self._local.run(self._job)
            return
        if self.worker is None:  # a selector on its own: its own worker
            jobs = self.physics.pool.jobs if self.physics is not None else 0
            self.worker, self._own_worker = PlanningWorker(self.estimate.scenario, jobs), True
        try:
            self._ticket = self.worker.submit(self._job)
        except WorkerLost as lost:  # gone while idle: the next poll replaces it
            self._lost = lost

    def _object_state(self) -> dict[str, Any] | None:
        if not self.task.object:  # a task that moves no object (a press)
            return None
        pos, quat = self.estimate.object_pose(self.task.object)
        return {"name": self.task.object, "position": pos, "quat": quat}

    def _observe(self, reason: str) -> None:
        """Update the estimate from one look through the robot and log it (``observation``).

        The robot's grasp record (``holding``) loses a hand whose touch no longer holds its object.
        """
        robot = self.bb.robot
        fields = refresh(self.estimate, robot, dict(self.bb.holding), reason)
        self.bb.holding = dict(fields["holding"])
        self._last_look = robot.time
        self.log.record("observation", task=self.name, **fields)

    def _refresh_estimate(self, q: FloatArray, observed: dict[str, tuple[FloatArray, FloatArray]]) -> None:
        """Objects the robot observes are put where it sees them; the others stay estimated."""
        world = self.estimate
        for name, adr in world.ids.object_qpos.items():
            if name in observed:
                pos, quat = observed[name]
                world.data.qpos[adr : adr + 3] = pos
                world.data.qpos[adr + 3 : adr + 7] = quat
            q[adr : adr + 7] = world.data.qpos[adr : adr + 7]
        mujoco.mj_kinematics(world.model, world.data)

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
        """Wait for the decision's result; then take it in a piece a tick (:meth:`_swap_pieces`),
        decide, and tick the chosen subtree from the next tick on (all in one tick when planning
        in the tick)."""
        spread = self.background  # from a worker: keep every tick short
        if self._result is None:
            try:
                self._result = self._receive()
            except WorkerLost as lost:
                return self._on_worker_lost(lost)
            if self._result is None:
                self.feedback_message = f"planning {self.name}"
                return Status.RUNNING
            self._losses = 0
        if self._swap is None:
            failure = self._result.failure
            if failure is not None:
                return self._finish("failed", {"mode": "planning", "detail": failure.detail()})
            self._swap = self._swap_pieces(self._result)
            if spread:
                return Status.RUNNING
        while self._swap:
            self._swap.pop(0)()
            if spread:
                return Status.RUNNING
        decided = self._decide(self._result.results, self._built)
        if decided is None and spread:  # the chosen subtree's first tick (its motion's set-up) is the next
            return Status.RUNNING
        return decided

    def _swap_pieces(self, result: PlanningResult) -> list[Callable[[], None]]:
        """Taking ``result`` in, in pieces of at most about a millisecond: its physics lines, each
        feasible alternative's subtree, and per guarded motion of the lowest-risk one its prepared
        knot distances and its collision pairs (what the guard's first check would build)."""
        feasible = ranked(result.results, self.ordering)
        pieces: list[Callable[[], None]] = [lambda: self._log_physics(result.results, result.verdict)]
        pieces += [functools.partial(self._build, alt) for alt in feasible]
        monitor = self._monitor()
        best = feasible[0].plan if feasible else None
        if monitor is not None and best is not None:
            pieces += [functools.partial(self._adopt, monitor, best, knots) for knots in result.knots]
            pieces.append(functools.partial(self._prime_guards, monitor, feasible[0].name))
        return pieces

    def _prime_guards(self, monitor: Any, name: str) -> None:
        """Have the guards of ``name``'s subtree work out their allowed contacts now (each motion's
        first tick would)."""
        for node in self._built[name].iterate():
            if isinstance(node, RiskGuard):
                node.allow(monitor)

    def _build(self, alt: AlternativeRisk) -> None:
        """Build ``alt``'s subtree (kept for the decision)."""
        assert alt.plan is not None
        subtree = self.kind.subtree(alt.plan, guard=self.guard)
        subtree.setup_with_descendants()
        self._built[alt.name] = subtree
        self.feedback_message = f"planning {self.name}: {alt.name} ready"

    def _receive(self) -> PlanningResult | None:
        """The worker's result if it has come (None: not yet); raises WorkerLost."""
        if self._lost is not None:
            raise self._lost
        assert self.worker is not None and self._ticket is not None
        result = self.worker.poll(self._ticket)
        if result is not None:
            self._ticket = None
        return result

    def _on_worker_lost(self, lost: WorkerLost) -> Status:
        """Log the lost worker, start a fresh one and re-plan from where the robot holds."""
        assert self.worker is not None
        self._losses += 1
        fields = {"event": "lost", "reason": lost.reason, "pid": lost.pid, "losses": self._losses}
        if self._losses > MAX_WORKER_LOSSES:
            self.log.record("planning_worker", task=self.name, **fields, action="fail the task")
            detail = f"the planning worker was lost {self._losses} times in a decision; last it {lost.reason}"
            return self._finish("failed", {"mode": "planning", "detail": detail})
        replacement = self.worker.replace()
        self.log.record(
            "planning_worker", task=self.name, **fields, action="replaced", replacement=replacement
        )
        self._start_planning()  # the robot held meanwhile: re-plan from where it is
        return Status.RUNNING

    def _adopt(self, monitor: Any, plan: AlternativePlan, knots: PreparedKnots) -> None:
        """Hand the worker's prepared knot distances of one guarded motion of ``plan`` to ``monitor``."""
        trajectory = plan.trajectories.get(knots.step)
        if trajectory is not None:
            monitor.adopt(
                trajectory.qpos,
                carried=knots.carried,
                allow=knots.allow,
                distances=knots.distances,
                names=knots.names,
            )

    def _log_physics(self, results: Sequence[AlternativeRisk], verdict: PhysicsVerdict | None) -> None:
        """One ``dry_run`` line per alternative run in physics, and a ``rollouts`` line if any ran."""
        if verdict is None:
            return
        for alt in results:
            if alt.physics is not None:
                dry = alt.physics["dry_run"]
                self.log.record(
                    "dry_run", task=self.name, name=alt.name, ok=alt.feasible, reason=alt.error, **dry
                )
        if verdict.stopped != "off":
            per_alt = {a.name: a.physics for a in results if a.physics is not None and a.feasible}
            self.log.record("rollouts", task=self.name, **verdict.as_dict(), alternatives=per_alt)

    def _decide(
        self, results: Sequence[AlternativeRisk], subtrees: dict[str, py_trees.behaviour.Behaviour]
    ) -> Status | None:
        for alt in results:
            self.log.record("plan", task=self.name, **risk_row(alt, self.ordering))
        feasible = ranked(results, self.ordering)
        self.ranking = feasible
        self.results = list(results)
        self._swap_children(feasible, subtrees)
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
        ranking = [
            {"name": a.name, "value": a.risk.value(self.ordering) if a.risk else None} for a in feasible
        ]
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
        reason = f"lowest {self.ordering} {value:.4g} ({best.name}) is above the threshold {self.threshold:g}"
        request = ApprovalRequest(
            task=f"{self.name}: {task_label(self.task)}",
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
            "selection", task=self.name, chosen=None, ranking=ranking, reason=reason + ": escalated"
        )
        self.log.record(
            "approval_request", task=self.name, request=request.as_dict(), channel=self.channel.name
        )
        self.pending = PendingApproval(request, self.timeout_s, clock=self.clock)
        self.phase = "awaiting_approval"
        self.channel.submit(self.pending)
        self.feedback_message = f"waiting for approval: {reason}"
        return Status.RUNNING

    def _on_decision(self, decision: ApprovalDecision) -> Status | None:
        self.approval = decision
        self.log.record("approval", task=self.name, **decision.as_dict())
        if decision.decision == "approve" and decision.alternative is not None:
            self._approved.add(decision.alternative)
            return self._start(decision.alternative)
        if decision.decision == "replan":
            self._start_planning(observe="before_replan")
            return Status.RUNNING
        if decision.decision == "deny":  # the risk is refused: the task ends as an abort does
            return self._finish("aborted", {"mode": "denied", "detail": f"denied by {decision.by}"})
        return self._finish("aborted", {"mode": "aborted", "detail": f"aborted by {decision.by}"})

    def _swap_children(
        self, ranked: Sequence[AlternativeRisk], subtrees: dict[str, py_trees.behaviour.Behaviour]
    ) -> None:
        """Make the built subtrees the children, lowest risk first."""
        for child in list(self.children):
            self.remove_child(child)
        self._by_name = {}
        for alt in ranked:
            subtree = subtrees[alt.name]
            self.add_child(subtree)
            self._by_name[alt.name] = subtree

    def _start(self, name: str) -> Status | None:
        alt = next(a for a in self.ranking if a.name == name)
        assert alt.risk is not None
        value = alt.risk.value(self.ordering)
        if value > self.threshold and name not in self._approved:
            # The invariant of the risk gate; reaching this is a bug, never an operator's choice.
            raise ExecutiveError(
                f"{name} ({self.ordering} {value:.4g}) is above the threshold without approval"
            )
        self.chosen, self.chosen_risk = name, risk_row(alt, self.ordering)
        self.current_child = self._by_name[name]
        self.tried.append(name)
        self.log.record(
            "execute", task=self.name, alternative=name, value=value, approved=name in self._approved
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
            placed = self._check_placed()
            if placed is not None:
                self.log.record("failure", task=self.name, alternative=child.name, **placed)
                self._observe("after_failure")
                return self._finish("failed", placed)
            return self._finish("success", None)
        failure = self._failure_of(child)
        self.log.record("failure", task=self.name, alternative=child.name, **failure)
        self._observe("after_failure")  # the re-plan below starts from this look
        mode = mode_of_verdict(failure["mode"])
        if mode is not None and failure_mode(mode).terminal:
            return self._finish("failed", failure)
        left = [a for a in self.names if a not in self.tried]
        if not left:
            return self._finish("failed", failure)
        self.failure = failure
        # The verdict is logged; the next attempt starts from the state the failure left.
        self.bb.robot.detector.acknowledge()
        self._start_planning()
        return Status.RUNNING

    def _check_placed(self) -> dict[str, Any] | None:
        """The task kind's check of what the subtree did (None: done as asked, or nothing to ask)."""
        detector = getattr(self.bb.robot, "detector", None)
        if detector is None:
            return None
        verdict = self.kind.verify(self.task, self.estimate, detector)
        if verdict is None:
            return None
        if verdict.ok:
            self.log.record(verdict.event, task=self.name, **verdict.fields)
            return None
        return verdict.fields

    def _failure_of(self, child: py_trees.behaviour.Behaviour) -> dict[str, Any]:
        """The detectors' verdict if they flagged one, else the failed behaviour's own message."""
        tip = child.tip()
        message = tip.feedback_message if tip is not None else ""
        found = self.bb.robot.failure
        if found is not None:
            return {
                "mode": found.mode,
                "detail": found.detail,
                "behaviour": tip.name if tip else "",
                "time": found.time,
                "bodies": list(found.bodies),
                "force": found.force,
            }
        mode = behaviour_failure(tip, 0.0).mode
        return {"mode": mode, "detail": message, "behaviour": tip.name if tip else ""}

    def _finish(self, outcome: str, failure: dict[str, Any] | None) -> Status:
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
            closest_call=self._closest_call(),
        )
        return Status.SUCCESS if outcome == "success" else Status.FAILURE

    def _closest_call(self) -> dict[str, Any] | None:
        """The detectors' near-miss record of the run so far (None: no detector keeps one)."""
        call = getattr(getattr(self.bb.robot, "detector", None), "closest_call", None)
        if call is None:
            return None
        return {
            "distance": call.distance if math.isfinite(call.distance) else None,  # m; None: beyond horizon
            "bodies": list(call.distance_bodies),
            "time": call.distance_time,
            "ignored_force": call.ignored_force,
            "ignored_bodies": list(call.ignored_bodies),
            "self_contacts": call.self_contacts,
            "summary": call.describe(),
        }
