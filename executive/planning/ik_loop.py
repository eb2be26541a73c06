"""The differential-IK loop of one move: QP steps until the hands are at their goals.

:class:`IKLoop` steps a :class:`~executive.planning.problem.MoveQP` from the planner's
configuration: each step points the hand tasks a bounded way ahead (:func:`~executive.planning.route.lead`),
solves the QP, integrates it (halved while a collision pair cuts in), projects the feet back and
moves a hand on to the next goal of its route once near its via point; a stall relaxes the posture
task, and a stall at the relaxation's floor fails naming what binds (the step's active set,
:func:`~executive.planning.active_set.active_limits`). The planner
(:class:`~executive.planning.planner.Planner`) re-times the path it returns.
"""

from __future__ import annotations

import math
import time
from typing import NoReturn

import mink
import numpy as np
from numpy.typing import NDArray

from executive.planning.active_set import active_limits
from executive.planning.limits import GeomPairCollisionLimit
from executive.planning.problem import MoveQP, PlanningProblem
from executive.planning.rotation import rotation_angle
from executive.planning.route import lead
from executive.planning.types import PlanningError, Relative, attach_object, site_quat

__all__ = ["IKLoop"]

FloatArray = NDArray[np.float64]


class IKLoop:
    """The IK steps of a move on ``problem``'s tasks and limits, integrated on ``configuration``.

    Build once per planner; :meth:`path` runs one move. ``lowest`` is the lowest pelvis height (m)
    of the last path, kept also when it failed (the planner then asks whether the safe posture's
    pelvis limit held the hands back).

    Args:
        problem: the world's IK problem.
        configuration: the configuration the steps are integrated on (the planner's).
    """

    def __init__(self, problem: PlanningProblem, configuration: mink.Configuration) -> None:
        self.problem = problem
        self.config = problem.config
        self.configuration = configuration
        self.lowest = math.inf

    def path(
        self, name: str, goals: dict[str, list[mink.SE3]], qp: MoveQP, floor: FloatArray
    ) -> tuple[list[FloatArray], int, float]:
        """IK steps from the current configuration until every hand is at the last of its goals.

        Args:
            name: the motion's name (for errors).
            goals: each moving hand's route (via points, then its target), by side.
            qp: the move's QP, its tasks set at the current configuration.
            floor: per collision pair, the distance (m) a step may not cut below.

        Returns:
            The path (qpos per step, the start first), the iterations and the time spent in
            the QP (s).

        Raises:
            PlanningError: on the iteration budget or a stall (:meth:`_fail`), and when the QP
                has no solution.
        """
        self.lowest = math.inf
        cfg, conf, problem = self.config, self.configuration, self.problem
        tasks, limits, constraints, collisions = qp.tasks, qp.limits, qp.constraints, qp.collisions
        stage = {side: 0 for side in goals}
        active = {side: route[0] for side, route in goals.items()}
        path = [conf.q]
        errors = self._errors(active)
        history = [max(p + a for p, a in errors.values())]
        ik_time = 0.0
        iterations = 0
        relax = 1.0  # scale of the posture task's cost (idle arms excepted)
        while not (self._arrived(errors) and all(stage[s] == len(goals[s]) - 1 for s in goals)):
            if iterations >= cfg.max_iterations:
                self._fail(name, errors, iterations, qp, active)
            if relax > cfg.relax_floor and self._stalled(history, cfg.relax_iterations):
                # Short of the floor a short stall relaxes; at the floor only a long stall fails.
                relax *= cfg.relax_factor
                problem.posture.set_cost(np.where(qp.idle_dofs, qp.posture_cost, qp.posture_cost * relax))
                history = history[-1:]
            elif self._stalled(history, cfg.stall_iterations):
                self._fail(name, errors, iterations, qp, active)
            lead(problem.hands, conf.data, problem.world.ids.hand_sites, active, cfg)
            tick = time.perf_counter()
            try:
                velocity = self._solve(tasks, limits, constraints, collisions)
            except mink.NoSolutionFound as exc:
                raise self._no_solution(name, errors, iterations, exc) from exc
            ik_time += time.perf_counter() - tick
            self._step(velocity, qp.relative, collisions, floor)
            iterations += 1
            path.append(conf.q)
            self.lowest = min(self.lowest, float(conf.q[problem.base_z_adr]))
            errors = self._errors(active)
            if self._pass_vias(errors, goals, stage, active):
                errors = self._errors(active)
                history = []
            history.append(max(p + a for p, a in errors.values()))
        return path, iterations, ik_time

    def _pass_vias(
        self,
        errors: dict[str, tuple[float, float]],
        goals: dict[str, list[mink.SE3]],
        stage: dict[str, int],
        active: dict[str, mink.SE3],
    ) -> bool:
        """Aim each hand near its via point at the next goal of its route (a via point is
        passed, not reached); ``stage`` and ``active`` are updated. Returns whether any moved on."""
        moved = False
        for side, (pos, _ang) in errors.items():
            if stage[side] < len(goals[side]) - 1 and pos < self.config.via_tolerance:
                stage[side] += 1
                active[side] = goals[side][stage[side]]
                self.problem.hands[side].set_target(active[side])
                moved = True
        return moved

    def _no_solution(
        self, name: str, errors: dict[str, tuple[float, float]], iterations: int, exc: Exception
    ) -> PlanningError:
        """The error of a step whose QP has no solution, naming the hand farthest from its goal."""
        side, (pos, ang) = max(errors.items(), key=lambda kv: kv[1][0])
        return PlanningError(
            name,
            side,
            pos,
            ang,
            iterations,
            f"motion '{name}': the IK QP has no solution after {iterations} iterations ({exc}); "
            f"{side} hand {pos:.3f} m and {np.degrees(ang):.1f} deg from its target",
        )

    def _solve(
        self,
        tasks: list[mink.Task],
        limits: list[mink.Limit],
        constraints: list[mink.Task],
        collisions: GeomPairCollisionLimit,
    ) -> FloatArray:
        """One IK step's QP. Should pushing pairs back out to their clearance (the collision
        rows' recovery) leave no solution, solve again with the rows only holding them."""
        cfg, joints = self.config, self.problem.joints
        try:
            return joints.solve(self.configuration, tasks, cfg.ik_dt, cfg.damping, limits, constraints)
        except mink.NoSolutionFound:
            if collisions.recovery == 0.0:
                raise
        collisions.recovery = 0.0
        try:
            return joints.solve(self.configuration, tasks, cfg.ik_dt, cfg.damping, limits, constraints)
        finally:
            collisions.recovery = cfg.collision_recovery

    def _step(
        self,
        velocity: FloatArray,
        relative: Relative | None,
        collisions: GeomPairCollisionLimit,
        floor: FloatArray,
    ) -> FloatArray:
        """Integrate one IK step, halving it while a pair ends up closer than ``floor``.

        The collision rows bound the approach to first order only; near a box's edge a
        long step can still cut in by millimetres. ``floor`` is fixed for the move (the
        required clearance, or the start distance of a pair that starts closer, less
        ``step_slack``), not the last step's distance: a pair sliding along a surface at
        its clearance drifts by second-order amounts each step, and a floor that ratchets
        with it would halve every step. Returns the pairs' distances after the step.
        """
        conf, cfg = self.configuration, self.config
        q_prev = conf.q.copy()
        alpha = 1.0
        for attempt in range(cfg.backtrack_steps + 1):
            conf.integrate_inplace(velocity * alpha, cfg.ik_dt)
            conf.update()
            self._project_feet()
            if relative is not None:
                attach_object(conf.data, relative)
                conf.update()
            after = collisions.distances(conf.data)
            if attempt == cfg.backtrack_steps or not np.any(after < floor):
                return after
            conf.update(q_prev)
            alpha *= 0.5
        return after  # not reached

    def _project_feet(self) -> None:
        """Remove the feet's second-order drift after a step: the least-norm dq with the feet rows exact.

        The same QP as a step (mink.solve_ik) with no task but the damping, so its solution is the
        minimum-norm correction of the linearised feet constraints; each pass squares the error.
        """
        cfg = self.config
        self.problem.project_drift(self.configuration, self.problem.feet, cfg.feet_tolerance, cfg.ik_dt)

    def _errors(self, goals: dict[str, mink.SE3]) -> dict[str, tuple[float, float]]:
        """Per hand: distance (m) and rotation angle (rad) from its goal."""
        data = self.configuration.data
        out = {}
        for side, goal in goals.items():
            site = self.problem.world.ids.hand_sites[side]
            pos = float(np.linalg.norm(data.site_xpos[site] - goal.wxyz_xyz[4:]))
            out[side] = (pos, rotation_angle(goal.wxyz_xyz[:4], site_quat(data, site)))
        return out

    def _arrived(self, errors: dict[str, tuple[float, float]]) -> bool:
        cfg = self.config
        return all(p <= cfg.position_tolerance and a <= cfg.angle_tolerance_rad for p, a in errors.values())

    def _stalled(self, history: list[float], n: int) -> bool:
        return len(history) > n and history[-n - 1] - history[-1] < self.config.stall_improvement

    def _fail(
        self,
        name: str,
        errors: dict[str, tuple[float, float]],
        iterations: int,
        qp: MoveQP,
        goals: dict[str, mink.SE3],
    ) -> NoReturn:
        """Raise the error of a move that stops short: the hand farthest from its goal (relative
        to the tolerances) and what binds there (the next step's QP's active set)."""
        cfg, problem = self.config, self.problem
        side, (pos, ang) = max(
            errors.items(),
            key=lambda kv: max(kv[1][0] / cfg.position_tolerance, kv[1][1] / cfg.angle_tolerance_rad),
        )
        lead(problem.hands, self.configuration.data, problem.world.ids.hand_sites, goals, cfg)
        binding = active_limits(problem, self.configuration, qp, cfg.ik_dt, cfg.damping)
        stall = self.configuration.q.copy()
        raise PlanningError(name, side, pos, ang, iterations, binding=binding, stall=stall)
