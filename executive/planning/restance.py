"""The rest of an alternative re-planned from where the robot stands after a walk inside it.

An alternative whose plan walks between its phases (a transfer's side-step: pick, walk, place)
is planned at once before the robot moves, so the phases after the walk are planned from the
stance the walk was planned to end in. The robot does not stand exactly there: its footholds
land off their plan and the errors add up over a walk. After the walk's last touchdown the robot
measures where its base stands (:func:`executive.world.observation.measure_base`: odometry, with
the scenario's ``uncertainty.base_position`` / ``base_yaw``), and the rest of the composition is
planned again from there with the same whole-body planner before it runs (:func:`replan_rest`):

* the start is the rest's planned start with the base, and every object a hand holds, moved by
  the stance's offset (:class:`StanceOffset`); the joints are as planned;
* a hand target fixed in the world (:class:`HandTarget` ``frame`` ``world``: an object's place, a
  lane over the table) stays where it is: the arm reaches it from where the base stands;
* a target fixed to the body (``frame`` ``base``: a home pose) moves with the base.

A :class:`Replanner` does the work for the behaviour that asks
(:class:`behaviours.restance.Restance`): :class:`LocalReplanner` in the ticking process, or the
selector's planning worker (:mod:`executive.decision.selector_restance`); either may check the
re-plan's risk against what was approved (a :class:`RestCheck`). docs/task_kinds.md ("Acting
from the measured stance") has the rule and the measurements.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import AlternativePlan, held_at_start
from executive.planning.planner import HandTarget, Planner, PlanningError, Trajectory
from executive.schema.types import Scenario
from executive.world.model import World, build

__all__ = [
    "LocalReplanner",
    "Replanner",
    "RestCheck",
    "RestanceRequest",
    "RestanceResult",
    "Stance",
    "StanceOffset",
    "defect",
    "planned_start",
    "replan",
    "replan_rest",
    "rest_after",
    "restance_fields",
    "stance_of",
]

FloatArray = NDArray[np.float64]
#: Where the base stands on the floor: x, y (m) and heading (rad).
Stance = tuple[float, float, float]


def _yaw(quat: FloatArray) -> float:
    """The z-y-x Euler yaw (rad) of a unit quaternion (w x y z)."""
    w, x, y, z = (float(v) for v in quat)
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def stance_of(position: FloatArray, quat: FloatArray) -> Stance:
    """The stance of a base pose: its x, y and the yaw of its orientation (w x y z)."""
    return float(position[0]), float(position[1]), _yaw(np.asarray(quat, dtype=float))


@dataclass(frozen=True)
class StanceOffset:
    """How far the base stands from where it was planned to: a turn about the planned base, then a shift.

    ``planned``, ``measured``: the base's stance as planned and as the robot measured it.
    """

    planned: Stance
    measured: Stance

    @property
    def turn(self) -> float:
        """The heading's error (rad, in (-pi, pi])."""
        d = self.measured[2] - self.planned[2]
        return float(math.atan2(math.sin(d), math.cos(d)))

    @property
    def distance(self) -> float:
        """How far (m) the base stands from its planned place on the floor."""
        return float(math.hypot(self.measured[0] - self.planned[0], self.measured[1] - self.planned[1]))

    def point(self, p: FloatArray) -> FloatArray:
        """``p`` (x y z, m) moved with the base from its planned to its measured stance."""
        c, s = math.cos(self.turn), math.sin(self.turn)
        p = np.asarray(p, dtype=float)
        dx, dy = p[0] - self.planned[0], p[1] - self.planned[1]
        return np.array([self.measured[0] + c * dx - s * dy, self.measured[1] + s * dx + c * dy, p[2]])

    def quat(self, q: FloatArray) -> FloatArray:
        """An orientation (w x y z) turned with the base."""
        out = np.empty(4)
        turn = np.array([math.cos(self.turn / 2), 0.0, 0.0, math.sin(self.turn / 2)])
        mujoco.mju_mulQuat(out, turn, np.asarray(q, dtype=float))
        return out

    def target(self, t: HandTarget) -> HandTarget:
        """A hand target where it is now: one fixed to the body moves with the base, one fixed in
        the world stays."""
        if t.frame != "base":
            return t
        return HandTarget(t.side, self.point(t.position), self.quat(t.quat), t.frame)

    def qpos(self, world: World, q: FloatArray, held: Iterable[str]) -> FloatArray:
        """``q`` with the base and the objects in ``held`` (rigid with the hands) moved with the base."""
        out = np.array(q, dtype=float)
        for adr in [world.base_qpos.start, *(world.ids.object_qpos[name] for name in held)]:
            out[adr : adr + 3] = self.point(out[adr : adr + 3])
            out[adr + 3 : adr + 7] = self.quat(out[adr + 3 : adr + 7])
        return out

    def as_dict(self) -> dict[str, Any]:
        """For the log: both stances (x, y m; yaw deg), the offset and its size."""
        return {
            "planned": [self.planned[0], self.planned[1], math.degrees(self.planned[2])],
            "measured": [self.measured[0], self.measured[1], math.degrees(self.measured[2])],
            "offset_m": [self.measured[0] - self.planned[0], self.measured[1] - self.planned[1]],
            "distance_m": self.distance,
            "turn_deg": math.degrees(self.turn),
        }


def rest_after(plan: AlternativePlan, walk: str) -> AlternativePlan | None:
    """The steps of ``plan`` after its walk step ``walk`` up to the next walk, with their planned
    trajectories, as a plan of their own (named as ``plan``); None when none of them moves a hand."""
    names = [s.name for s in plan.steps]
    steps = []
    for step in plan.steps[names.index(walk) + 1 :]:
        if step.kind == "step":
            break
        steps.append(step)
    trajectories = {s.name: plan.trajectories[s.name] for s in steps if s.name in plan.trajectories}
    if not trajectories:
        return None
    return AlternativePlan(plan.name, plan.task, tuple(steps), trajectories)


def planned_start(rest: AlternativePlan) -> FloatArray:
    """The configuration ``rest`` was planned from: its first motion's first knot."""
    first = next(s.name for s in rest.steps if s.name in rest.trajectories)
    return rest.trajectories[first].qpos[0]


@dataclass(frozen=True)
class RestanceRequest:
    """What is asked after a walk: the rest of the alternative as planned (:func:`rest_after`), and
    where the base stands against where it was planned to (``offset``). ``walk``: the walk's step
    name; ``waited_s``: how long the robot stood after the walk before it measured (``still``:
    whether its base had come to rest by then)."""

    rest: AlternativePlan
    walk: str
    offset: StanceOffset
    waited_s: float = 0.0
    still: bool = True

    @property
    def start(self) -> FloatArray:
        """The configuration the rest was planned from (the walk's planned end)."""
        return planned_start(self.rest)


@dataclass(frozen=True)
class RestanceResult:
    """The rest re-planned (``trajectories``, by step name) or why not (``reason``; then none).

    ``risk``: the risk check's record (None: not checked); ``plan_s``: wall time of the re-plan.
    """

    trajectories: dict[str, Trajectory] = field(default_factory=dict)
    reason: str = ""
    risk: dict[str, Any] | None = None
    plan_s: float = 0.0

    @property
    def ok(self) -> bool:
        """Whether the rest may run as re-planned."""
        return not self.reason

    def native(self) -> RestanceResult:
        """This result with its arrays of NumPy's own float64 (a result just unpickled: the live
        guard keys its memo by the identity of the array it checks; see ``PlanningResult.native``)."""
        trajectories = {
            name: dataclasses.replace(
                t,
                times=np.asarray(t.times, dtype=float),
                qpos=np.asarray(t.qpos, dtype=float),
                hand_paths={side: np.asarray(p, dtype=float) for side, p in t.hand_paths.items()},
                com_path=np.asarray(t.com_path, dtype=float),
            )
            for name, t in self.trajectories.items()
        }
        return dataclasses.replace(self, trajectories=trajectories)


class RestCheck(Protocol):
    """A check of a re-planned rest against the rest as planned (e.g. their risk against what was
    approved): ``""`` to accept, else why not; and its record for the log."""

    def __call__(
        self, world: World, planned: AlternativePlan, replanned: AlternativePlan
    ) -> tuple[str, dict[str, Any]]: ...


class Replanner(Protocol):
    """Re-plans the rest of an alternative for the behaviour that asks (one request at a time).

    :meth:`submit` a request, then :meth:`poll` each tick until it answers; :meth:`cancel`
    forgets an unanswered request (the behaviour was stopped).
    """

    def submit(self, request: RestanceRequest) -> None: ...

    def poll(self) -> RestanceResult | None: ...

    def cancel(self) -> None: ...


def replan_rest(planner: Planner, world: World, request: RestanceRequest) -> dict[str, Trajectory]:
    """Plan every motion of ``request.rest`` again, in order, from the measured stance (module docstring).

    Raises:
        PlanningError: a motion the planner cannot make from there (naming the step).
    """
    offset, rest = request.offset, request.rest
    q = offset.qpos(world, request.start, held_at_start(rest.steps).values())
    trajectories: dict[str, Trajectory] = {}
    for step in rest.steps:
        if step.name not in rest.trajectories:
            continue
        traj = planner.move(
            q,
            [offset.target(t) for t in step.targets],
            name=step.name,
            carried=step.carried,
            allow_contact=step.allow_contact,
            rest=step.kind == "home",
            straight=step.straight,
        )
        trajectories[step.name] = traj
        q = traj.qpos[-1]
    return trajectories


def replan(
    planner: Planner, world: World, request: RestanceRequest, check: RestCheck | None = None
) -> RestanceResult:
    """:func:`replan_rest`, then ``check`` (None: none): the result, or why the rest may not run."""
    t0 = time.perf_counter()
    try:
        trajectories = replan_rest(planner, world, request)
    except PlanningError as exc:
        return RestanceResult(reason=f"the rest does not plan from the measured stance: {exc}")
    plan_s = time.perf_counter() - t0
    if check is None:
        return RestanceResult(trajectories, plan_s=plan_s)
    replanned = dataclasses.replace(request.rest, trajectories=trajectories)
    reason, risk = check(world, request.rest, replanned)
    return RestanceResult({} if reason else trajectories, reason, risk, plan_s)


def defect(exc: BaseException) -> RestanceResult:
    """The answer to a re-plan whose code raised (a defect, not a reason of the plan's): refused."""
    raised = f"{type(exc).__name__}: {exc}"
    return RestanceResult(reason=f"re-planning raised {raised} (a defect: please report it)")


class LocalReplanner:
    """A :class:`Replanner` in the ticking process: :meth:`submit` re-plans at once (the tick blocks).

    Args:
        estimate: the estimate world to plan on, or the scenario whose estimate is built when
            first asked (a run that never walks mid-composition builds nothing).
        planner: the whole-body planner of ``estimate`` (None: built when first asked).
        check: the re-plan's check (None: none; the rest must only plan).
    """

    def __init__(
        self, estimate: World | Scenario, planner: Planner | None = None, check: RestCheck | None = None
    ) -> None:
        self._estimate = estimate
        self._planner = planner
        self.check = check
        self._result: RestanceResult | None = None

    def submit(self, request: RestanceRequest) -> None:
        try:
            if not isinstance(self._estimate, World):
                self._estimate = build(self._estimate)
            if self._planner is None:
                self._planner = Planner(self._estimate)
            self._result = replan(self._planner, self._estimate, request, self.check)
        except Exception as exc:  # a defect: the rest must not run on it
            self._result = defect(exc)

    def poll(self) -> RestanceResult | None:
        result, self._result = self._result, None
        return result

    def cancel(self) -> None:
        self._result = None


def restance_fields(request: RestanceRequest, result: RestanceResult | None) -> dict[str, Any]:
    """The log's record of a re-plan after a walk: the stances, what became of the rest and why.

    ``outcome``: ``replanned``, ``refused`` (the robot holds: ``reason``), or ``open_loop`` (no
    re-planner: the rest runs as planned).
    """
    out: dict[str, Any] = {"walk": request.walk, **request.offset.as_dict()}
    out["waited_s"], out["still"] = request.waited_s, request.still
    out["steps"] = [s.name for s in request.rest.steps if s.name in request.rest.trajectories]
    if result is None:
        out["outcome"] = "open_loop"
        return out
    out["outcome"] = "replanned" if result.ok else "refused"
    if result.reason:
        out["reason"] = result.reason
    if result.risk is not None:
        out["risk"] = result.risk
    out["plan_s"] = result.plan_s
    if result.ok:
        planned = sum(t.duration for t in request.rest.trajectories.values())
        replanned = sum(t.duration for t in result.trajectories.values())
        out["duration_s"] = {"planned": planned, "replanned": replanned}
    return out
