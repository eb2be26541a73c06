"""RiskSelector: a py_trees composite that runs the lowest-risk alternative of a task.

On entry the selector plans and assesses every alternative of its task on the
current estimate (:func:`executive.decision.assessment.assess_task`) in a worker thread,
so ticks keep returning RUNNING (the robot holds) while it plans. It then:

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

The estimate follows the objects (:mod:`executive.world.observation`): the selector looks
through the robot and updates the estimate after every failure (``after_failure``; a re-plan
that follows at once starts from that look), before a re-plan an operator asked for
(``before_replan``) and when its task ends after acting (``after_task``, unless it has just
looked), each time with an ``observation`` line in the log.
   A fall or unstable simulation ends the task at once: nothing is re-tried on a
   robot that may not be standing.

The worker thread does all the heavy work of a decision: it plans and assesses,
builds every feasible alternative's subtree (and runs its ``setup``), and lets the
live risk monitor (``/executive/live_risk``, if any) compute the guarded motions'
planned distances of the lowest-risk alternative. The tick that sees the planning
done only logs, ranks and swaps the ready subtrees in.

Every step is a line in the audit log (:class:`executive.decision.audit.AuditLog`) before
it is acted on; no alternative above the threshold starts without an approval
line naming it (checked in :meth:`RiskSelector._start`).
"""

from __future__ import annotations

import concurrent.futures
import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import mujoco
import numpy as np
import py_trees

from behaviours.guard import LIVE_RISK_KEY, RiskGuard
from behaviours.robot_access import NAMESPACE
from executive.decision.approval import AlternativeRisk as RequestRow
from executive.decision.approval import ApprovalChannel, ApprovalDecision, ApprovalRequest, PendingApproval
from executive.decision.assessment import AlternativeRisk, assess_task
from executive.decision.audit import AuditLog
from executive.decision.physics_check import PhysicsCheck, PhysicsVerdict, physics_text
from executive.errors import ExecutiveError
from executive.planning.planner import Planner
from executive.risk.collision import CollisionModel, breach_summary
from executive.tasks.base import Task
from executive.tasks.registry import get as task_kind
from executive.world.model import World
from executive.world.observation import refresh

__all__ = ["RiskSelector", "task_label"]

Status = py_trees.common.Status
FloatArray = np.ndarray
#: What the planning thread hands the tick: every alternative's assessment (after the physics
#: check), the check's verdict (None without one), and the ready (set up) subtrees of the
#: feasible ones by name.
Planned = tuple[list[AlternativeRisk], PhysicsVerdict | None, dict[str, py_trees.behaviour.Behaviour]]

#: Failure modes after which nothing is re-tried.
TERMINAL_MODES = ("fall", "unstable")


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
            only where the caller checks plans in physics itself.
        background: plan in a worker thread (ticks never block); False plans inside the
            tick (blocking, for batch use).
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
        self._planner: Planner | None = None
        self._collision: CollisionModel | None = None
        self._pool: concurrent.futures.ThreadPoolExecutor | None = None
        self._future: concurrent.futures.Future[Planned] | None = None
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
        """Heavy work once: the planner and the collision model of the estimate."""
        if self._planner is None:
            self._planner = Planner(self.estimate)
            self._collision = CollisionModel(
                self.estimate, self.estimate.scenario.risk, uncertainty=self.estimate.scenario.uncertainty
            )

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
            if self._future is not None:
                self._future.cancel()
        super().stop(new_status)

    def shutdown(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

    # --- states ---------------------------------------------------------------------------

    def _reset(self) -> None:
        self.phase, self.outcome, self.failure = "idle", None, None
        self.chosen, self.chosen_risk, self.approval, self.pending = None, None, None, None
        self.ranking, self.results, self.tried, self._approved = [], [], [], set()

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

        monitor = self.bb.get(LIVE_RISK_KEY) if self.guard and self.bb.exists(LIVE_RISK_KEY) else None
        if self.physics is not None:
            self.physics.pool.warm()  # the workers start (or are reused) while the planner works

        def work() -> Planned:
            assert self._planner is not None and self._collision is not None
            results = assess_task(self.estimate, task, self._planner, self._collision, q_start=q)
            verdict = None
            if self.physics is not None:
                results, verdict = self.physics.check(self.estimate, results, q_start=q)
            return results, verdict, self._subtrees(results, monitor)

        if self.background:
            if self._pool is None:
                self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix=f"plan-{self.name}")
            self._future = self._pool.submit(work)
        else:
            future: concurrent.futures.Future[Planned] = concurrent.futures.Future()
            try:
                future.set_result(work())
            except Exception as exc:
                future.set_exception(exc)
            self._future = future

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
            assert self._future is not None
            if not self._future.done():
                self.feedback_message = f"planning {self.name}"
                return Status.RUNNING
            try:
                results, verdict, subtrees = self._future.result()
            except ExecutiveError as exc:
                return self._finish("failed", {"mode": "planning", "detail": str(exc)})
            except Exception as exc:  # a defect in planning must still end in the log
                detail = f"planning raised {type(exc).__name__}: {exc} (a defect: please report it)"
                return self._finish("failed", {"mode": "planning", "detail": detail})
            self._log_physics(results, verdict)
            return self._decide(results, subtrees)
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
        feasible = self._ranked(results)
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

    def _ranked(self, results: Sequence[AlternativeRisk]) -> list[AlternativeRisk]:
        """The feasible alternatives, lowest ordering value first."""
        return sorted(
            (a for a in results if a.risk is not None),
            key=lambda a: a.risk.value(self.ordering) if a.risk else 0.0,
        )

    def _subtrees(
        self, results: Sequence[AlternativeRisk], monitor: Any
    ) -> dict[str, py_trees.behaviour.Behaviour]:
        """Build and set up the feasible alternatives' subtrees (runs in the planning thread).

        With a live risk ``monitor``, the lowest-risk alternative's guarded motions have
        their planned distances computed now (:meth:`behaviours.guard.RiskGuard.prepare`);
        any other alternative's guards compute theirs as they run.
        """
        subtrees: dict[str, py_trees.behaviour.Behaviour] = {}
        for i, alt in enumerate(self._ranked(results)):
            assert alt.plan is not None
            subtree = self.kind.subtree(alt.plan, guard=self.guard)
            subtree.setup_with_descendants()
            if monitor is not None and i == 0:
                for node in subtree.iterate():
                    if isinstance(node, RiskGuard):
                        node.prepare(monitor)
            subtrees[alt.name] = subtree
        return subtrees

    def _swap_children(
        self, ranked: Sequence[AlternativeRisk], subtrees: dict[str, py_trees.behaviour.Behaviour]
    ) -> None:
        """Make the ready subtrees the children, lowest risk first (nothing built in the tick)."""
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
        if failure["mode"] in TERMINAL_MODES:
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
        mode = (
            "guard"
            if message.startswith("guard:")
            else message.split(":", 1)[0]
            if ":" in message
            else "failed"
        )
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
