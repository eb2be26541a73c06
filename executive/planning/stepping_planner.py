"""The quasi-static step planner: one step of a foot to a foothold, as five timed phases.

:class:`StepPlanner` plans on the *estimate* world's model, as the whole-body
:class:`~executive.planning.planner.Planner` does, and shares its IK problem
(:class:`~executive.planning.problem.PlanningProblem`: joint groups, joint bounds, the torso's tilt
and the pelvis height limits, collision pairs). Each phase
(:data:`~executive.planning.stepping_types.PHASES`) is an IK path of
:class:`~executive.planning.stepping_ik.StepIK` re-timed as any planned motion
(:func:`~executive.planning.timing.build_trajectory`). :mod:`executive.planning.stepping` is the
overview and the public entry.
"""

from __future__ import annotations

import time
from dataclasses import replace

import mink
import numpy as np
from numpy.typing import NDArray

from executive.planning.limits import GeomPairCollisionLimit, SupportPolygon
from executive.planning.problem import PlanningProblem
from executive.planning.stepping_geometry import circular_mean, foot_pose, foothold_of
from executive.planning.stepping_ik import PhaseGoal, StepIK, StepPlanningError
from executive.planning.stepping_types import Foothold, StepConfig, StepPhase, StepPlan
from executive.planning.timing import Frames, TimedJoints, Trajectory, build_trajectory
from executive.planning.types import PlannerConfig, PlanningError, PlanningInputError
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["StepPlanner"]

FloatArray = NDArray[np.float64]


class StepPlanner:
    """Plans quasi-static steps on a world's model (build once, then plan many steps).

    :meth:`plan_step` plans one step (the phases of :data:`PHASES`); :meth:`probe` drives a foot
    as far as it goes towards a foothold (what :func:`executive.planning.stepping.measure_reach`
    measures with).

    Args:
        world: the (estimate) world to plan on; its robot must have two feet.
        config: the step planner's tuning (defaults when None).
        planner_config: the whole-body planner's tuning (its IK step, timing and clearances);
            ignored when ``problem`` is given.
        problem: the whole-body planner's IK problem on ``world`` to share (built when None).
        carried: (hand side, object) held through the steps: the object moves with its hand and
            keeps its clearance from the scene and the body, as in a carry.

    Raises:
        PlanningInputError: when the robot does not have exactly two feet, or its base is not
            body 1 of the model (mink's CoM task).
    """

    def __init__(
        self,
        world: World,
        config: StepConfig | None = None,
        planner_config: PlannerConfig | None = None,
        problem: PlanningProblem | None = None,
        carried: tuple[str, str] | None = None,
    ) -> None:
        if len(world.profile.feet) != 2:
            raise PlanningInputError(
                f"stepping needs two feet; robot '{world.profile.name}' has {len(world.profile.feet)}"
            )
        self.world = world
        self.model = world.model
        self.config = config or StepConfig()
        self.problem = problem or PlanningProblem(world, planner_config or PlannerConfig())
        self.configuration = mink.Configuration(self.model)
        self.ik = StepIK(self.problem, self.configuration, self.config, carried)
        self.sides: tuple[str, ...] = tuple(world.profile.feet)

    # --- geometry of a configuration ---------------------------------------------------------

    def footholds(self, qpos: FloatArray) -> dict[str, Foothold]:
        """Each foot's foothold in the configuration ``qpos``, by side (leaves the planner's
        configuration there)."""
        self.configuration.update(np.array(qpos, dtype=float))
        data = self.configuration.data
        return {side: foothold_of(data, side, body) for side, body in self.ik.feet.items()}

    def pelvis(self, qpos: FloatArray) -> tuple[float, float, float]:
        """The pelvis's (x, y, yaw) on the floor in the configuration ``qpos``."""
        self.configuration.update(np.array(qpos, dtype=float))
        data, base = self.configuration.data, self.world.ids.base_body
        return float(data.xpos[base][0]), float(data.xpos[base][1]), yaw_of(data.xquat[base])

    def sole_polygon(self, sides: tuple[str, ...]) -> SupportPolygon:
        """The support polygon of the soles of ``sides`` in the planner's current configuration."""
        geoms = [g for s in sides for g in self.ik.sole_geoms[s]]
        return SupportPolygon.from_feet(self.model, self.configuration.data, geoms)

    def sole_margin(self, sole: SupportPolygon) -> float:
        """The CoM's margin (m) inside a stance sole ``sole`` in single support: the smaller of
        ``single_support_margin`` and ``single_support_fraction`` of the sole's half width (the
        distance from its middle to its nearest edge)."""
        c = self.config
        return min(c.single_support_margin, c.single_support_fraction * sole.margin(sole.centre))

    # --- one step -----------------------------------------------------------------------------

    def plan_step(self, q_start: FloatArray, swing: str, target: Foothold) -> StepPlan:
        """Plan one step of the ``swing`` foot to ``target`` from ``q_start`` (both feet on the floor).

        Args:
            q_start: the start configuration (full-model qpos), both feet flat on the floor.
            swing: the side of the foot that steps.
            target: where it goes (its ``side`` must be ``swing``).

        Returns:
            The step's plan: its five phases (shift, lift, swing, touchdown, shift_back) and the
            footholds.

        The support ankles keep their balance reserve (``StepConfig.balance_reserve``); a step
        that cannot keep it whole (a phase binds on it) is planned again keeping the CoP's part of
        it alone, then without it, as steps were before there was one.

        Raises:
            PlanningInputError: on a start of the wrong shape, a side the robot does not have or
                a target that is not finite.
            StepPlanningError: when a phase cannot reach its goal (naming the limits that bind)
                or its timed trajectory breaks a limit.
        """
        started = time.perf_counter()
        limit = self.ik.ankle_limit
        if limit is None:
            return self._plan_step(q_start, swing, target, started)
        full = limit.shift
        tries = [(True, full), (True, 0.0), (False, 0.0)] if full > 0.0 else [(True, 0.0), (False, 0.0)]
        try:
            for active, shift in tries[:-1]:
                limit.active, limit.shift = active, shift
                try:
                    return self._plan_step(q_start, swing, target, started)
                except StepPlanningError as exc:
                    if not any("balance reserve" in bind for bind in exc.binds):
                        raise
            limit.active, limit.shift = tries[-1]
            return self._plan_step(q_start, swing, target, started)
        finally:
            limit.active, limit.shift = True, full

    def _plan_step(self, q_start: FloatArray, swing: str, target: Foothold, started: float) -> StepPlan:
        """:meth:`plan_step` with the ankle reserve as it is set (``started``: its clock)."""
        stance = self._check(q_start, swing, target)
        start = self.footholds(q_start)
        data, c = self.configuration.data, self.config
        body = self.ik.feet[swing]
        standing = mink.SE3(np.concatenate([data.xquat[body], data.xpos[body]]))
        collisions, required = self.ik.collisions(swing)
        floor = np.minimum(collisions.distances(data), required)
        yaw0 = yaw_of(data.xquat[self.world.ids.base_body])
        yaw1 = circular_mean(start[stance].yaw, target.yaw)
        sole = self.sole_polygon((stance,))
        margin = self.sole_margin(sole)
        stand = self._stand(yaw0)
        feet = [
            ("lift", foot_pose(standing, start[swing], c.clearance), yaw0),
            ("swing", foot_pose(standing, target, c.clearance), yaw1),
            ("touchdown", foot_pose(standing, target), yaw1),
        ]
        try:
            phases = [self._run(self._shift("shift", (stance,), yaw0), collisions, floor)]
            for name, pose, yaw in feet:
                goal = PhaseGoal(name, (stance,), swing, pose, sole.centre, False, sole, margin, yaw)
                phases.append(self._run(goal, collisions, floor))
            back = self._shift("shift_back", self.sides, yaw1, stand)._replace(
                waist=q_start[self.ik.waist_qadr]
            )
            phases.append(self._run(back, collisions, floor))
        except StepPlanningError as exc:
            raise StepPlanningError(
                exc.name, f"{swing} foot step to {target.describe()}: {exc}", exc.binds, exc.iterations
            ) from exc
        footholds = dict(start) | {swing: target}
        return StepPlan(swing, stance, tuple(phases), start, footholds, margin, time.perf_counter() - started)

    def _check(self, q_start: FloatArray, swing: str, target: Foothold) -> str:
        """Raise PlanningInputError on a bad request; return the stance foot's side."""
        q = np.asarray(q_start)
        if q.shape != (self.model.nq,):
            raise PlanningInputError(
                f"q_start has shape {q.shape}; the world's model needs ({self.model.nq},)"
            )
        if swing not in self.sides:
            raise PlanningInputError(f"no foot '{swing}'; feet are: {', '.join(self.sides)}")
        if target.side != swing:
            raise PlanningInputError(f"the target is the {target.side} foot's, the step the {swing} foot's")
        if not np.all(np.isfinite([target.x, target.y, target.yaw])):
            raise PlanningInputError(f"the target {target} is not finite")
        return next(s for s in self.sides if s != swing)

    def _stand(self, yaw: float) -> FloatArray:
        """Where the CoM stands from the middle of the two-foot polygon in the configuration,
        in the frame turned by ``yaw`` (x, y; m): the robot's own stance."""
        data = self.configuration.data
        off = self.ik.loaded.position(data)[:2] - self.sole_polygon(self.sides).centre
        c, s = np.cos(yaw), np.sin(yaw)
        return np.array([c * off[0] + s * off[1], -s * off[0] + c * off[1]])

    def _shift(
        self, name: str, over: tuple[str, ...], yaw: float, stand: FloatArray | None = None
    ) -> PhaseGoal:
        """A weight shift on both feet: the CoM to the middle of the soles of ``over`` (one foot:
        the stance foot; both: the two-foot polygon, plus ``stand`` (:meth:`_stand`) turned by
        ``yaw``: the CoM where the robot stood over its feet before the step), inside the
        two-foot polygon; should a limit hold it back, it may end anywhere inside those soles
        by :meth:`sole_margin` of the stance sole (of both: the narrower of the two soles')."""
        both = self.sole_polygon(self.sides)
        region = self.sole_polygon(over) if len(over) < len(self.sides) else both
        goal = region.centre
        if stand is not None:
            c, s = np.cos(yaw), np.sin(yaw)
            goal = goal + np.array([c * stand[0] - s * stand[1], s * stand[0] + c * stand[1]])
        inside = min(self.sole_margin(self.sole_polygon((s,))) for s in over)
        margin = self.config.double_support_margin
        return PhaseGoal(name, self.sides, None, None, goal, True, both, margin, yaw, region, inside)

    def _run(self, goal: PhaseGoal, collisions: GeomPairCollisionLimit, floor: FloatArray) -> StepPhase:
        """Run one phase's IK from the configuration's state and time its path. A phase whose CoM
        the legs leave short, a support ankle at its balance reserve, is planned again with the
        torso leaning over the stance foot (the waist's roll at ``lean_cost``)."""
        start = self.configuration.q.copy()
        try:
            path, iterations = self.ik.path(goal, collisions)
            short = self.ik.short_at_reserve(goal)
        except StepPlanningError as exc:
            if self.ik.waist_roll_dof is None or not any("balance reserve" in b for b in exc.binds):
                raise
            short = True
        if short:
            self.configuration.update(start)
            path, iterations = self.ik.path(goal, collisions, lean=True)
        trajectory = self._timed(goal, np.array(path), collisions, floor, iterations)
        return StepPhase(goal.name, trajectory, goal.held)

    def _timed(
        self,
        goal: PhaseGoal,
        path: FloatArray,
        collisions: GeomPairCollisionLimit,
        floor: FloatArray,
        iterations: int,
    ) -> Trajectory:
        """The phase's IK path re-timed (:func:`build_trajectory`) with the phase's polygon, margin
        and shortest duration, the joints at ``speed_scale`` of their timed limits."""
        problem, c, ids = self.problem, self.config, self.world.ids
        shortest = c.shift_duration if len(goal.held) > 1 else c.foot_duration
        cfg = replace(problem.config, support_margin=goal.margin, min_duration=shortest)
        try:
            return build_trajectory(
                self.model,
                cfg,
                path,
                goal.name,
                TimedJoints(problem.timed_dofs, problem.timed_limits * c.speed_scale),
                Frames(dict(ids.hand_sites), ids.base_body, problem.quat_adr),
                None,
                None,
                goal.polygon,
                collisions,
                floor,
                self.ik.loaded,
            )
        except PlanningError as exc:  # the timing's: the same, as a step's error
            raise StepPlanningError(goal.name, f"step phase '{goal.name}': {exc}", (), iterations) from exc

    # --- reach ---------------------------------------------------------------------------------

    def probe(self, q_start: FloatArray, swing: str, goal: Foothold) -> tuple[Foothold, list[str]]:
        """Shift the weight onto the stance foot, then drive the ``swing`` foot along the floor
        towards ``goal`` until it arrives or stalls (no floor in the IK: the foot glides).

        Args:
            q_start: the start configuration, both feet on the floor.
            swing: the side of the foot that moves.
            goal: where it is driven.

        Returns:
            Where the foot got to, and what binds there (empty when it arrived or nothing does).

        Raises:
            StepPlanningError: when the weight shift itself fails.
        """
        stance = self._check(q_start, swing, goal)
        start = self.footholds(q_start)
        data = self.configuration.data
        body = self.ik.feet[swing]
        standing = mink.SE3(np.concatenate([data.xquat[body], data.xpos[body]]))
        collisions, _ = self.ik.collisions(swing)
        yaw0 = yaw_of(data.xquat[self.world.ids.base_body])
        self.ik.path(self._shift("shift", (stance,), yaw0), collisions)
        sole = self.sole_polygon((stance,))
        yaw = circular_mean(start[stance].yaw, goal.yaw)
        drive = PhaseGoal(
            "probe",
            (stance,),
            swing,
            foot_pose(standing, goal),
            sole.centre,
            False,
            sole,
            self.sole_margin(sole),
            yaw,
        )
        self.ik.path(drive, collisions, probe=True)
        reached = foothold_of(self.configuration.data, swing, body)
        binds = self.ik.binding(drive, collisions) if reached.distance(goal) != (0.0, 0.0) else []
        return reached, binds
