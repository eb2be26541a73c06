"""Whole-body motion planning with mink: hands to targets, feet fixed, CoM over the feet.

:class:`Planner` plans one motion (:meth:`Planner.move`) by differential inverse kinematics on
the *estimate* world's model and re-times it (:mod:`executive.planning.timing`); the returned
qpos index that model. Its IK problem is :class:`~executive.planning.problem.PlanningProblem`,
its step loop :class:`~executive.planning.ik_loop.IKLoop`, a hand's route
:mod:`executive.planning.route`. Types, errors and the configuration live in
:mod:`executive.planning.types` and are re-exported here.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import mink
import numpy as np
from numpy.typing import NDArray

from executive.planning.ik_loop import IKLoop
from executive.planning.limits import JointBounds, TiltLimit
from executive.planning.problem import PELVIS_QP_MARGIN, PlanningProblem
from executive.planning.route import hand_routes
from executive.planning.timing import Frames, TimedJoints, Trajectory, build_trajectory
from executive.planning.types import (
    HandTarget,
    PlannerConfig,
    PlanningError,
    PlanningInputError,
    PlanStats,
    hand_top_down_quat,
)
from executive.world.model import World

__all__ = [
    "HandTarget",
    "PlanStats",
    "Planner",
    "PlannerConfig",
    "PlanningError",
    "PlanningInputError",
    "Trajectory",
    "hand_top_down_quat",
]

FloatArray = NDArray[np.float64]


class Planner:
    """Whole-body differential-IK planner on a world's model (build once, call :meth:`move` often).

    :meth:`Planner.move` drives one or both hands to target poses from a start
    configuration by differential inverse kinematics (mink's tasks and limits; the QP
    of ``mink.solve_ik``, assembled on the unfrozen dofs and solved with DAQP by
    :class:`~executive.planning.limits.JointBounds`), then re-times the geometric path (see
    :mod:`executive.planning.timing`). Everything runs on the *estimate* world's
    model; the returned qpos index that model. The QP's tasks, equality constraints and
    limits are those of :class:`~executive.planning.problem.PlanningProblem` (``problem``),
    built once here; :class:`~executive.planning.ik_loop.IKLoop` steps them.

    A carried object is treated as part of its hand: its free-joint dofs are
    frozen in the QP, its collision Jacobian is taken on the palm, and after every
    IK step and at every knot its pose is set from the hand pose and the relative
    pose it had at the start.

    Three additions to plain differential IK keep it reliable:

    * via points (:mod:`executive.planning.route`): a hand whose straight way is
      blocked by an obstacle passes over it (IK alone stops dead in front of it);
    * relaxation: when the hands stall short of the tolerance because the soft
      posture task holds them back, its cost is scaled down (hard limits stay);
    * feet projection: after each step the feet's second-order drift is removed
      by a minimum-norm correction with the feet rows as equality constraints.

    Args:
        world: the (estimate) world to plan on.
        config: the planner's tuning (defaults when None).

    Raises:
        PlanningInputError: when the world's robot does not suit the planner (see
            :class:`~executive.planning.problem.PlanningProblem`).
    """

    def __init__(self, world: World, config: PlannerConfig | None = None) -> None:
        self.world = world
        self.config = config or PlannerConfig()
        self.model = world.model
        self.configuration = mink.Configuration(self.model)
        self.last_stats: PlanStats | None = None
        self.problem = PlanningProblem(world, self.config)
        self._ik = IKLoop(self.problem, self.configuration)

    # --- the problem's tasks and limits -----------------------------------------------------

    @property
    def velocity_limits(self) -> dict[str, float]:
        """Each timed joint's velocity limit (rad/s, scaled), by joint name."""
        return self.problem.velocity_limits

    @property
    def posture(self) -> mink.PostureTask:
        """The posture task."""
        return self.problem.posture

    @property
    def feet(self) -> list[mink.FrameTask]:
        """The feet's frame tasks (the QP's equality constraints)."""
        return self.problem.feet

    @property
    def hands(self) -> dict[str, mink.FrameTask]:
        """Each hand's frame task, by side."""
        return self.problem.hands

    @property
    def com(self) -> mink.ComTask:
        """The CoM task."""
        return self.problem.com

    @property
    def freeze(self) -> mink.DofFreezingTask:
        """The frozen dofs (fingers, objects) as mink's task (the QP leaves them out)."""
        return self.problem.freeze

    @property
    def joints(self) -> JointBounds:
        """The joint range and velocity limits as bounds of the QP, which it solves."""
        return self.problem.joints

    @property
    def tilt(self) -> TiltLimit:
        """The torso's tilt limit."""
        return self.problem.tilt

    def collision_pairs(
        self, carried: tuple[str, str] | None = None, allow_contact: Sequence[str] = ()
    ) -> list[tuple[int, int]]:
        """Geom pairs the planner keeps apart for a move (after ``allow_contact`` is removed).

        Args:
            carried: (hand side, object name) of a carried object.
            allow_contact: names of geoms the robot may touch.

        Returns:
            The geom pairs (built once per request, then kept).
        """
        return self.problem.collisions.pairs(carried, allow_contact)

    def required_clearance(self, pairs: Sequence[tuple[int, int]]) -> FloatArray:
        """Clearance (m) each pair must keep: an obstacle's own ``clearance`` against that
        obstacle, ``table_distance`` against the table, else ``min_distance``.

        Args:
            pairs: geom pairs.

        Returns:
            The clearance of each pair (m).
        """
        return self.problem.collisions.required_clearance(pairs)

    # --- planning ---------------------------------------------------------------------------

    def move(
        self,
        q_start: FloatArray,
        targets: Sequence[HandTarget],
        *,
        name: str,
        carried: tuple[str, str] | None = None,
        allow_contact: Sequence[str] = (),
        rest: bool = False,
        straight: bool = False,
    ) -> Trajectory:
        """Plan the whole body from ``q_start`` until every target hand is at its target.

        The posture task pulls the arms towards the home keyframe; the legs and waist hold
        their start angles (the body moves only as far as the hands need, so a short hand
        move is a short whole-body move), unless ``rest``: a return to the rest pose, where
        the legs and waist are pulled towards the keyframe too. A hand heads for its target
        over via points that lift it over what lies in its way
        (:func:`executive.planning.route.hand_routes`), unless ``straight``: a contact motion
        (a push's leg) keeps to the straight line, the collision limit alone keeping it clear.

        The pelvis stays inside the robot's safe posture (``profile.safe_posture``): a target
        the hands reach only with the pelvis lower than that is refused with the depth it
        would need (the move is planned again without the pelvis limit to measure it).

        Raises PlanningError when a hand is still outside tolerance after the
        iteration budget (or when progress stalls), naming the side and the
        remaining position and angle errors, or the safe posture's limit that holds it back.
        """
        try:
            return self._move(
                q_start, targets, name, carried, allow_contact, rest, posture=True, straight=straight
            )
        except PlanningError as exc:
            if self._ik.lowest > self.problem.pelvis_floor + 2.0 * PELVIS_QP_MARGIN:
                raise  # the pelvis limit did not hold the hands back
            self._posture_failure(exc, q_start, targets, name, carried, allow_contact, rest, straight)
            raise

    def _posture_failure(
        self,
        exc: PlanningError,
        q_start: FloatArray,
        targets: Sequence[HandTarget],
        name: str,
        carried: tuple[str, str] | None,
        allow_contact: Sequence[str],
        rest: bool,
        straight: bool,
    ) -> None:
        """Plan a failed move again without the pelvis limit; raise the posture's named reason
        when that reaches the targets with the pelvis below the safe posture (else return)."""
        try:
            free = self._move(
                q_start, targets, name, carried, allow_contact, rest, posture=False, straight=straight
            )
        except PlanningError:
            return
        problem = self.problem
        needed = problem.standing_height - float(np.min(free.qpos[:, problem.base_z_adr]))
        if needed <= problem.posture_limits.max_pelvis_drop:
            return
        held = (
            f"the {exc.side} hand stops {exc.position_error * 1000:.0f} mm short"
            if exc.side is not None
            else str(exc)
        )
        raise PlanningError(
            name,
            exc.side,
            exc.position_error,
            exc.angle_error,
            exc.iterations,
            f"motion '{name}': reaching the target needs the pelvis lower than the safe posture "
            f"allows: planned without that limit it takes {problem.posture_limits.describe_drop(needed)} "
            f"(robot '{self.world.profile.name}', safe_posture.max_pelvis_drop); with the pelvis "
            f"held there, {held}",
            binding=exc.binding,
            stall=exc.stall,
        ) from exc

    def _move(
        self,
        q_start: FloatArray,
        targets: Sequence[HandTarget],
        name: str,
        carried: tuple[str, str] | None,
        allow_contact: Sequence[str],
        rest: bool,
        *,
        posture: bool,
        straight: bool = False,
    ) -> Trajectory:
        """:meth:`move`, with the safe posture's pelvis limit in the QP if ``posture``."""
        started = time.perf_counter()
        cfg, model, ids, problem = self.config, self.model, self.world.ids, self.problem
        self._check_request(q_start, targets, carried)
        conf = self.configuration
        conf.update(np.array(q_start, dtype=float))
        allowed = problem.collisions.allowed_geoms(allow_contact)
        goals = hand_routes(
            model, conf.data, ids, targets, carried, allowed, cfg.via_clearance, straight=straight
        )
        qp = problem.move_qp(conf, goals, carried, allow_contact, rest, posture)
        clearance0 = qp.collisions.distances(conf.data)
        # What a step may not cut below: the required clearance (or the start distance, when a
        # pair starts closer), less a slack well inside the knots' check (clearance_tolerance).
        floor = np.minimum(clearance0, qp.required) - cfg.step_slack
        path, iterations, ik_time = self._ik.path(name, goals, qp, floor)
        trajectory = build_trajectory(
            model,
            cfg,
            np.array(path),
            name,
            TimedJoints(problem.timed_dofs, problem.timed_limits),
            Frames(dict(ids.hand_sites), ids.base_body, problem.quat_adr),
            carried,
            qp.relative,
            qp.polygon,
            qp.collisions,
            np.minimum(clearance0, qp.required),
        )
        if posture:
            self._check_posture(trajectory)
        self.last_stats = PlanStats(
            name, iterations, ik_time, time.perf_counter() - started, len(trajectory.times)
        )
        return trajectory

    def _check_posture(self, trajectory: Trajectory) -> None:
        """Every knot's pelvis within the safe posture (the QP's limit is first order), or no
        lower than where the move started when it started below it."""
        problem = self.problem
        heights = trajectory.qpos[:, problem.base_z_adr]
        k = int(np.argmin(heights))
        if heights[k] >= min(problem.pelvis_floor, float(heights[0])):
            return
        reason = problem.posture_limits.describe_drop(problem.standing_height - float(heights[k]))
        raise PlanningError(
            trajectory.name,
            None,
            0.0,
            0.0,
            0,
            f"motion '{trajectory.name}': at t = {trajectory.times[k]:.2f} s the timed path takes {reason}",
        )

    def _check_request(
        self, q_start: FloatArray, targets: Sequence[HandTarget], carried: tuple[str, str] | None
    ) -> None:
        """Raise PlanningInputError when the request does not fit the world: the start's shape,
        a hand that is not the robot's or named twice, or a carried object not in the world."""
        q = np.asarray(q_start)
        if q.shape != (self.model.nq,):
            raise PlanningInputError(
                f"q_start has shape {q.shape}; the world's model needs ({self.model.nq},)"
            )
        sides = [t.side for t in targets]
        sides_ok = self.problem.sides
        valid = ", ".join(sides_ok)
        for side in sides:
            if side not in sides_ok:
                raise PlanningInputError(f"no hand '{side}'; hands are: {valid}")
        if len(set(sides)) != len(sides) or not sides:
            raise PlanningInputError(f"give one target per moving hand, at least one; got sides {sides}")
        if carried is not None:
            side, obj = carried
            if side not in sides_ok:
                raise PlanningInputError(f"carried by hand '{side}'; hands are: {valid}")
            if obj not in self.world.ids.object_bodies:
                objs = ", ".join(sorted(self.world.ids.object_bodies))
                raise PlanningInputError(f"carried object '{obj}' is not in the world; objects are: {objs}")
