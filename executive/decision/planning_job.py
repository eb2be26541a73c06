"""One decision's heavy work as plain data in and out: a :class:`PlanningJob` and its :class:`PlanningResult`.

A selector's decision needs: every alternative of its task planned (mink) and assessed
(analytic risk) on the estimate, the feasible ones dry-run and rolled out in physics, and the
lowest-risk one's guarded motions given their planned knots' distances (coal) so that the
ticks that execute it compute none. A :class:`RestanceJob` is the smaller work of re-planning
what follows a walk inside the running alternative from where the robot measured it stands.
:class:`Planning` does all of that for the selectors of one
scenario, on one estimate world, with one planner and collision model per selector (built on
first use and kept). It runs in a planning worker process
(:mod:`executive.decision.planning_worker`), or in the ticking process for a synchronous
selector (``background=False``).

The job carries what the estimate is *now* in the process that ticks (the estimate's ``qpos``,
which hand holds which object and how: :class:`EstimateState`) and the robot's measured joints;
the result carries numbers only: the assessed alternatives (plans as numpy arrays), the
physics check's verdict, and the prepared knot distances (:class:`PreparedKnots`). Both
pickle; nothing in them refers to a MuJoCo object. An error in the work comes back as a
:class:`PlanningFailure` (its text), never as an exception object.
"""

from __future__ import annotations

import dataclasses
import os
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.decision.assessment import AlternativeRisk, assess_task
from executive.decision.physics_check import PhysicsCheck, PhysicsVerdict
from executive.decision.restance import Approval, RiskRecheck
from executive.errors import ExecutiveError
from executive.planning.restance import RestanceRequest, RestanceResult, defect, replan
from executive.schema.types import Task
from executive.world.model import Grip, World

if TYPE_CHECKING:
    from executive.monitoring.live_risk import LiveRiskMonitor
    from executive.planning.planner import Planner
    from executive.risk.collision import CollisionModel
    from executive.schema.types import Scenario

__all__ = [
    "EstimateState",
    "Planning",
    "PlanningFailure",
    "PlanningJob",
    "PlanningResult",
    "PreparedKnots",
    "RestanceJob",
    "ranked",
]

FloatArray = NDArray[np.float64]


def ranked(results: Sequence[AlternativeRisk], ordering: str) -> list[AlternativeRisk]:
    """The feasible alternatives of ``results``, lowest ``ordering`` value first (stable)."""
    return sorted(
        (a for a in results if a.risk is not None),
        key=lambda a: a.risk.value(ordering) if a.risk else 0.0,
    )


@dataclass(frozen=True)
class EstimateState:
    """What of an estimate world changes while a mission runs: its ``qpos`` (the objects where the
    robot last saw them), which hand holds which object (``World.held``) and how (``World.grips``).

    Copies, so the state stays as it was when taken.
    """

    qpos: FloatArray
    held: dict[str, str] = field(default_factory=dict)
    grips: dict[str, Grip] = field(default_factory=dict)
    follows_base: bool = False

    @classmethod
    def of(cls, world: World) -> EstimateState:
        """The state of ``world`` now."""
        grips = {
            name: Grip(g.side, np.array(g.position, dtype=float), np.array(g.quat, dtype=float), g.looks)
            for name, g in world.grips.items()
        }
        return cls(np.array(world.data.qpos, dtype=float), dict(world.held), grips, world.follows_base)

    def apply(self, world: World) -> None:
        """Put ``world`` (an estimate of the same scenario) in this state, kinematics included."""
        world.data.qpos[:] = self.qpos
        held = dict(self.held)
        grips = {
            name: Grip(g.side, np.array(g.position, dtype=float), np.array(g.quat, dtype=float), g.looks)
            for name, g in self.grips.items()
        }
        world.held.clear()
        world.held.update(held)
        world.grips.clear()
        world.grips.update(grips)
        world.follows_base = self.follows_base
        mujoco.mj_kinematics(world.model, world.data)


@dataclass(frozen=True)
class PlanningJob:
    """One decision to work out.

    selector: the selector asking (its planner and collision model are kept by this name).
    task: the task, restricted to the alternatives not yet tried.
    q_start: the robot's measured joints (the full ``qpos`` of the estimate's model).
    estimate: the estimate's state to plan on.
    physics: dry-run and roll out the feasible alternatives (the selector's physics check).
    guard: prepare the lowest-risk alternative's guarded knots (a live risk monitor is on).
    """

    selector: str
    task: Task
    q_start: FloatArray
    estimate: EstimateState
    physics: bool = True
    guard: bool = True


@dataclass(frozen=True)
class RestanceJob:
    """The rest of an alternative to re-plan from the measured stance after a walk inside it.

    selector: the selector asking (its planner and collision model are used).
    request: what to re-plan and from where (:class:`executive.planning.restance.RestanceRequest`).
    estimate: the estimate's state to plan on.
    approval: what was approved of the alternative (its risk is re-checked against it); None:
        not checked.
    """

    selector: str
    request: RestanceRequest
    estimate: EstimateState
    approval: Approval | None = None


@dataclass(frozen=True)
class PreparedKnots:
    """The planned knots' guard distances of one motion step, computed ahead for the live guard.

    step: the step's name (its trajectory is ``plan.trajectories[step]``); carried, allow: the
    guard's memo key besides the knots (:meth:`executive.monitoring.live_risk.LiveRiskMonitor.adopt`);
    distances, names: per knot, the guard's distance and the closest bodies.
    """

    step: str
    carried: str | None
    allow: frozenset[tuple[str, str]]
    distances: FloatArray
    names: list[tuple[str, str]]


@dataclass(frozen=True)
class PlanningFailure:
    """The work raised: ``executive`` True for an :class:`ExecutiveError` (a reason for the log), else
    a defect; ``text`` its message (a defect's with its exception type), ``trace`` the traceback."""

    executive: bool
    text: str
    trace: str = ""

    def detail(self) -> str:
        """The failure's ``detail`` for the log (a defect asks to be reported)."""
        if self.executive:
            return self.text
        return f"planning raised {self.text} (a defect: please report it)"


@dataclass(frozen=True)
class PlanningResult:
    """What a decision's work found: every alternative assessed (after the physics check), the
    check's verdict (None without one), and the lowest-risk alternative's prepared knots.

    ``failure`` set: the work raised (the other fields are empty). ``pid``: the process that
    did the work; ``work_s``: its wall time there.
    """

    results: list[AlternativeRisk]
    verdict: PhysicsVerdict | None
    knots: tuple[PreparedKnots, ...] = ()
    failure: PlanningFailure | None = None
    pid: int = 0
    work_s: float = 0.0

    def native(self) -> PlanningResult:
        """This result with every plan's arrays of NumPy's own float64 (views, no copies): for
        a result just unpickled.

        An unpickled array's dtype is equal to, but not, NumPy's float64 descriptor, and
        ``np.asarray(a, dtype=float)`` then makes a new view on every call (NumPy 2). The live
        guard keys its memo of planned distances by the identity of that array, so it would
        compute them again on every tick.
        """
        return dataclasses.replace(self, results=[_native_alternative(a) for a in self.results])


def _native(array: FloatArray) -> FloatArray:
    return np.asarray(array, dtype=float)


def _native_alternative(alt: AlternativeRisk) -> AlternativeRisk:
    if alt.plan is None:
        return alt
    trajectories = {
        name: dataclasses.replace(
            t,
            times=_native(t.times),
            qpos=_native(t.qpos),
            hand_paths={side: _native(p) for side, p in t.hand_paths.items()},
            com_path=_native(t.com_path),
        )
        for name, t in alt.plan.trajectories.items()
    }
    return dataclasses.replace(alt, plan=dataclasses.replace(alt.plan, trajectories=trajectories))


class Planning:
    """The heavy work of the decisions of one scenario's selectors, on one estimate world.

    Args:
        estimate: the estimate world the plans are made on (each job first puts it in the job's state).
        physics: the physics check (dry runs, rollouts); None: jobs asking for one get none.
        monitor: a live risk monitor on ``estimate`` that prepares the guards' knots; None: no
            knots are prepared.

    Use :meth:`run` per job; :meth:`close` ends the physics check's worker processes.
    """

    def __init__(
        self, estimate: World, physics: PhysicsCheck | None = None, monitor: LiveRiskMonitor | None = None
    ) -> None:
        self.estimate = estimate
        self.physics = physics
        self.monitor = monitor
        self._tools: dict[str, tuple[Planner, CollisionModel]] = {}

    @classmethod
    def of_scenario(cls, scenario: Scenario, jobs: int, physics: PhysicsCheck | None = None) -> Planning:
        """Everything built once for ``scenario``: its estimate world, a live risk monitor on it,
        and a physics check whose ``jobs`` worker processes are started now (0: no physics check).

        ``physics``: keep this physics check (its processes are warm and take any scenario's jobs)
        instead of starting another.
        """
        from executive.monitoring.live_risk import LiveRiskMonitor
        from executive.world.model import build

        estimate = build(scenario)
        if physics is None and jobs > 0:
            physics = PhysicsCheck(jobs)
            physics.pool.warm()  # the rollout processes start while the first plans are made
        return cls(estimate, physics, LiveRiskMonitor(estimate, scenario.risk.guard))

    def tools(self, selector: str) -> tuple[Planner, CollisionModel]:
        """The planner and collision model of ``selector`` (built on first use, then kept)."""
        tools = self._tools.get(selector)
        if tools is None:
            from executive.planning.planner import Planner
            from executive.risk.collision import CollisionModel

            world = self.estimate
            collision = CollisionModel(world, world.scenario.risk, uncertainty=world.scenario.uncertainty)
            tools = self._tools[selector] = (Planner(world), collision)
        return tools

    def run(self, job: PlanningJob) -> PlanningResult:
        """Plan, assess, check in physics and prepare the knots of ``job`` (see the module docstring)."""
        t0 = time.perf_counter()
        try:
            job.estimate.apply(self.estimate)
            planner, collision = self.tools(job.selector)
            results = assess_task(self.estimate, job.task, planner, collision, q_start=job.q_start)
            verdict = None
            if job.physics and self.physics is not None:
                results, verdict = self.physics.check(self.estimate, results, q_start=job.q_start)
            ordering = self.estimate.scenario.risk.ordering
            knots = self._prepare(job.task, ranked(results, ordering)) if job.guard else ()
        except Exception as exc:
            executive = isinstance(exc, ExecutiveError)
            text = str(exc) if executive else f"{type(exc).__name__}: {exc}"
            failure = PlanningFailure(executive, text, traceback.format_exc())
            return PlanningResult([], None, failure=failure, pid=os.getpid(), work_s=time.perf_counter() - t0)
        return PlanningResult(results, verdict, knots, pid=os.getpid(), work_s=time.perf_counter() - t0)

    def serve(self, job: PlanningJob | RestanceJob) -> PlanningResult | RestanceResult:
        """Work out ``job``: a decision (:meth:`run`) or a rest to re-plan (:meth:`restance`)."""
        return self.restance(job) if isinstance(job, RestanceJob) else self.run(job)

    def restance(self, job: RestanceJob) -> RestanceResult:
        """Re-plan the rest of ``job`` from the measured stance with the selector's planner, its risk
        checked against the approval (:func:`executive.planning.restance.replan`)."""
        try:
            job.estimate.apply(self.estimate)
            planner, collision = self.tools(job.selector)
            check = RiskRecheck(job.approval, collision) if job.approval is not None else None
            return replan(planner, self.estimate, job.request, check)
        except Exception as exc:  # a defect: the rest must not run on it
            return defect(exc)

    def _prepare(self, task: Task, feasible: list[AlternativeRisk]) -> tuple[PreparedKnots, ...]:
        """The guard distances of the lowest-risk alternative's planned knots, per motion step.

        Its subtree is built here as the selector builds it, so every guard asks the monitor
        for exactly the knots and allowances it will check.
        """
        from behaviours.guard import RiskGuard
        from executive.tasks.registry import get as task_kind

        monitor = self.monitor
        if monitor is None or not feasible or feasible[0].plan is None:
            return ()
        plan = feasible[0].plan
        step_of = {id(traj.qpos): name for name, traj in plan.trajectories.items()}
        out = []
        seen: set[tuple[str, str | None, frozenset[tuple[str, str]]]] = set()
        for node in task_kind(task.kind).subtree(plan, guard=True).iterate():
            if not isinstance(node, RiskGuard):
                continue
            node.prepare(monitor)
            qpos = node.motion.trajectory.qpos
            step = step_of.get(id(qpos))
            if step is None:  # a motion not among the plan's trajectories: its guard computes its own
                continue
            for carried, allow, dist, names in monitor.memo(qpos):
                if (step, carried, allow) not in seen:  # a walk's footsteps share its knots
                    seen.add((step, carried, allow))
                    out.append(PreparedKnots(step, carried, allow, dist, names))
        return tuple(out)

    def close(self) -> None:
        """End the physics check's worker processes."""
        if self.physics is not None:
            self.physics.close()
