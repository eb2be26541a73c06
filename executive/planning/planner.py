"""Whole-body motion planning with mink: hands to targets, feet fixed, CoM over the feet.

:class:`Planner` plans one motion (:meth:`Planner.move`) by differential inverse kinematics on
the *estimate* world's model and re-times it (:mod:`executive.planning.timing`); the returned
qpos index that model. Types, errors and the configuration live in
:mod:`executive.planning.types` and are re-exported here.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import NamedTuple

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.limits import (
    GeomPairCollisionLimit,
    JointBounds,
    PelvisHeightLimit,
    SupportPolygon,
    SupportPolygonLimit,
    TiltLimit,
    geom_pairs,
)
from executive.planning.route import footprint, via_points, world_box
from executive.planning.timing import Frames, TimedJoints, Trajectory, build_trajectory
from executive.planning.types import (
    HandTarget,
    PlannerConfig,
    PlanningError,
    PlanningInputError,
    PlanStats,
    Relative,
    attach_object,
    body_pose,
    hand_top_down_quat,
    se3,
    site_pose,
    site_quat,
)
from executive.robot.posture import standing_pelvis_height
from executive.world.model import World, is_descendant

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

#: m the pelvis limit of the IK's QP keeps above the safe posture's floor.
_PELVIS_QP_MARGIN = 0.005


class _MoveQP(NamedTuple):
    """One move's IK problem: its tasks, limits and equality constraints (the feet), the collision
    limit with its pairs' required clearance (m), a carried object's pose relative to its hand,
    the support polygon, and the posture cost before relaxation with the idle arms' dofs (which
    relaxation leaves alone)."""

    tasks: list[mink.Task]
    limits: list[mink.Limit]
    constraints: list[mink.Task]
    collisions: GeomPairCollisionLimit
    required: FloatArray
    relative: Relative | None
    polygon: SupportPolygon
    posture_cost: FloatArray
    idle_dofs: NDArray[np.bool_]


class Planner:
    """Whole-body differential-IK planner on a world's model (build once, call :meth:`move` often).

    :meth:`Planner.move` drives one or both hands to target poses from a start
    configuration by differential inverse kinematics (mink's tasks and limits; the QP
    of ``mink.solve_ik``, assembled on the unfrozen dofs and solved with DAQP by
    :class:`~executive.planning.limits.JointBounds`), then re-times the geometric path (see
    :mod:`executive.planning.timing`). Everything runs on the *estimate* world's
    model; the returned qpos index that model.

    The QP of every IK step (mink's formulation, ``min ||J dq + e||_W^2`` subject to
    ``G dq <= h``, ``A dq = b``):

    * tasks: a ``FrameTask`` per named hand site; a ``ComTask`` pulling
      the CoM xy towards the middle of the support polygon (modest cost: the robot
      may lean); a ``PostureTask`` towards the keyframe, legs stiffest, then waist,
      arms softest, except that an idle arm is held at its start joint angles
      (it moves with the torso, so it cannot wander into it);
    * equality constraints: both feet bodies held at their start pose
      (``FrameTask`` rows as constraints); finger and object dofs frozen (left out
      of the QP, which is the same as mink's ``DofFreezingTask``);
    * limits: ``ConfigurationLimit``, ``VelocityLimit`` (the joints' velocity limits;
      both as bounds on single dofs, see :class:`~executive.planning.limits.JointBounds`),
      the CoM inside the feet's support polygon shrunk by a margin
      (:class:`~executive.planning.limits.SupportPolygonLimit`), the robot's safe posture
      (:mod:`executive.robot.posture`: the torso's tilt, :class:`~executive.planning.limits.TiltLimit`,
      and the pelvis no lower than its limit below standing,
      :class:`~executive.planning.limits.PelvisHeightLimit`), and collision
      avoidance (:class:`~executive.planning.limits.GeomPairCollisionLimit`) between
      each arm (and a carried object) and the table, obstacles and other objects,
      between the arms, and between the arms and the rest of the body.

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
    """

    def __init__(self, world: World, config: PlannerConfig | None = None) -> None:
        self.world = world
        self.config = config or PlannerConfig()
        model = self.model = world.model
        ids = world.ids
        self.sides: tuple[str, ...] = tuple(sorted(ids.hand_sites))
        self.configuration = mink.Configuration(model)
        self._path_lowest = math.inf  # the lowest pelvis height of the last IK path (m)
        self.last_stats: PlanStats | None = None
        self.quat_adr = tuple(
            int(model.jnt_qposadr[j]) + 3
            for j in range(model.njnt)
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
        )
        legs, waist, arms, others = self._joint_groups()
        velocity = self._velocities(legs, waist, arms)
        self._posture_task(legs, waist, arms)
        frozen = self._frozen_dofs(others)
        self._frame_tasks(frozen)
        # The joint range and velocity limits as bounds of the step's QP on the unfrozen dofs.
        self.joints = JointBounds(model, velocity, frozen)
        self._safe_posture_limits()
        self.foot_geoms = [g for s in sorted(ids.foot_geoms) for g in ids.foot_geoms[s]]
        self._pairs: dict[tuple[tuple[str, str] | None, tuple[str, ...]], list[tuple[int, int]]] = {}
        # The collision limit of each (carried, allow_contact), with its pairs' required clearance:
        # both depend on the model and the configuration only, so they are built once.
        self._limits: dict[
            tuple[tuple[str, str] | None, tuple[str, ...]], tuple[GeomPairCollisionLimit, FloatArray]
        ] = {}
        self._collision_groups()

    # --- setup helpers ----------------------------------------------------------------------

    def _joint_name(self, joint: int) -> str:
        return str(mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint))

    def _joint_groups(self) -> tuple[set[str], set[str], set[str], list[int]]:
        """The robot's joint names by group (legs, waist, arms; hinge/slide only, the floating
        base is free) and the ids of its other joints (fingers etc.)."""
        model, world, ids, name = self.model, self.world, self.world.ids, self._joint_name
        legs = {name(model.joint(n).id) for side in world.profile.leg_joints.values() for n in side}
        waist = {name(model.joint(n).id) for n in world.profile.waist_joints}
        arms = {name(j) for side in self.sides for j in ids.arm_joints[side]}
        robot_joints = [
            j
            for j in range(model.njnt)
            if model.jnt_bodyid[j] in ids.robot_bodies and model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE
        ]
        others = [j for j in robot_joints if name(j) not in legs | waist | arms]  # fingers etc.
        return legs, waist, arms, others

    def _velocities(self, legs: set[str], waist: set[str], arms: set[str]) -> dict[str, float]:
        """Each group's joint velocity limit (rad/s, as configured); sets the timed dofs and
        their scaled limits. Returns the unscaled limits by joint name."""
        cfg, model = self.config, self.model
        velocity = {n: cfg.leg_velocity for n in legs} | {n: cfg.waist_velocity for n in waist}
        velocity |= {n: cfg.arm_velocity for n in arms}
        self.timed_dofs = np.array([int(model.jnt_dofadr[model.joint(n).id]) for n in velocity], dtype=int)
        self.timed_limits = np.array([velocity[n] * cfg.velocity_scale for n in velocity])
        self.velocity_limits = {n: v * cfg.velocity_scale for n, v in velocity.items()}
        return velocity

    def _posture_task(self, legs: set[str], waist: set[str], arms: set[str]) -> None:
        """The posture task (legs stiffest, then waist, arms softest) and the qpos/dof addresses
        it holds: the legs and waist, and each arm."""
        cfg, model, ids = self.config, self.model, self.world.ids
        posture_cost = np.zeros(model.nv)
        for names, cost in (
            (legs, cfg.posture_leg_cost),
            (waist, cfg.posture_waist_cost),
            (arms, cfg.posture_arm_cost),
        ):
            for n in names:
                posture_cost[model.jnt_dofadr[model.joint(n).id]] = cost
        self.posture_cost = posture_cost
        self.posture = mink.PostureTask(model, cost=posture_cost, gain=cfg.posture_gain)
        self.body_qadr = np.array(
            [int(model.jnt_qposadr[model.joint(n).id]) for n in legs | waist], dtype=int
        )
        self.arm_dofs = {
            s: np.array([int(model.jnt_dofadr[j]) for j in ids.arm_joints[s]], dtype=int) for s in self.sides
        }
        self.arm_qadr = {
            s: np.array([int(model.jnt_qposadr[j]) for j in ids.arm_joints[s]], dtype=int) for s in self.sides
        }

    def _frozen_dofs(self, others: list[int]) -> list[int]:
        """Dofs left out of the QP: the robot's other joints' (fingers) and the objects' free joints."""
        model = self.model
        frozen = [int(model.jnt_dofadr[j]) for j in others]
        for qadr in self.world.ids.object_qpos.values():
            joint = int(np.flatnonzero(model.jnt_qposadr == qadr)[0])
            frozen.extend(range(int(model.jnt_dofadr[joint]), int(model.jnt_dofadr[joint]) + 6))
        return frozen

    def _frame_tasks(self, frozen: list[int]) -> None:
        """The dof-freezing task, the feet and hand frame tasks and the CoM task."""
        cfg, model, world, ids = self.config, self.model, self.world, self.world.ids
        self.freeze = mink.DofFreezingTask(model, dof_indices=frozen)
        self.feet = [
            mink.FrameTask(world.profile.feet[s].body, "body", position_cost=1.0, orientation_cost=1.0)
            for s in sorted(world.profile.feet)
        ]
        self.hands = {
            s: mink.FrameTask(
                int(ids.hand_sites[s]),
                "site",
                position_cost=cfg.hand_position_cost,
                orientation_cost=cfg.hand_orientation_cost,
            )
            for s in self.sides
        }
        self.com = mink.ComTask(cost=[cfg.com_cost, cfg.com_cost, 0.0])
        # mink's ComTask regulates body 1's subtree: it must be the robot's base.
        if ids.base_body != 1:
            raise PlanningInputError(f"the robot's base must be body 1 of the model, not {ids.base_body}")

    def _safe_posture_limits(self) -> None:
        """The safe posture (executive.robot.posture): the torso's tilt, and the pelvis no lower than
        its limit below standing (a little higher in the QP, as for the balance, so that the
        second-order drift of a step and the knots between steps stay inside it)."""
        cfg, model, ids = self.config, self.model, self.world.ids
        self.posture_limits = self.world.profile.safe_posture
        tilt = min(cfg.max_torso_tilt_deg, self.posture_limits.max_trunk_tilt_deg)
        self.tilt = TiltLimit(model, ids.torso_body, float(np.radians(tilt)))
        self.standing_height = standing_pelvis_height(model, ids.keyframe, ids.base_body)
        self.pelvis_floor = self.standing_height - self.posture_limits.max_pelvis_drop
        self.pelvis = PelvisHeightLimit(model, ids.base_body, self.pelvis_floor + _PELVIS_QP_MARGIN)
        self.base_z_adr = int(model.jnt_qposadr[model.body_jntadr[ids.base_body]]) + 2

    def _collision_groups(self) -> None:
        """Geom groups: each arm's subtree, the rest of the body, and the environment."""
        model, ids = self.model, self.world.ids
        self.arm_geoms: dict[str, list[int]] = {}
        for side in self.sides:
            root = int(model.jnt_bodyid[ids.arm_joints[side][0]])
            subtree = {b for b in ids.robot_bodies if is_descendant(model, b, root)}
            self.arm_geoms[side] = [g for g in ids.robot_geoms if int(model.geom_bodyid[g]) in subtree]
        in_arms = {g for gs in self.arm_geoms.values() for g in gs}
        self.body_geoms = [g for g in ids.robot_geoms if g not in in_arms]
        self.static_env = [g for g in ids.table_geoms] + list(ids.obstacle_geoms.values())
        self.geom_names = {
            str(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)): g
            for g in range(model.ngeom)
            if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
        }

    def collision_pairs(
        self, carried: tuple[str, str] | None = None, allow_contact: Sequence[str] = ()
    ) -> list[tuple[int, int]]:
        """Geom pairs the planner keeps apart for a move (after ``allow_contact`` is removed).

        Built once per (carried, allow_contact) and kept: the groups depend on the model only.
        """
        key = (carried, tuple(allow_contact))
        cached = self._pairs.get(key)
        if cached is None:
            cached = self._pairs[key] = self._collision_pairs(carried, allow_contact)
        return list(cached)

    def _collision_pairs(
        self, carried: tuple[str, str] | None, allow_contact: Sequence[str]
    ) -> list[tuple[int, int]]:
        ids = self.world.ids
        allowed = {self._geom(n) for n in allow_contact}
        carried_geom = ids.object_geoms[carried[1]] if carried else None
        objects = [g for g in ids.object_geoms.values() if g != carried_geom]
        env = self.static_env + objects
        groups: list[tuple[Sequence[int], Sequence[int]]] = []
        for side in self.sides:
            groups += [(self.arm_geoms[side], env), (self.arm_geoms[side], self.body_geoms)]
        for i, a in enumerate(self.sides):
            for b in self.sides[i + 1 :]:
                groups.append((self.arm_geoms[a], self.arm_geoms[b]))
        if carried is not None and carried_geom is not None:
            others = [g for s in self.sides if s != carried[0] for g in self.arm_geoms[s]]
            groups.append(([carried_geom], env + self.body_geoms + others))
        return [p for p in geom_pairs(self.model, groups) if not allowed & set(p)]

    def required_clearance(self, pairs: Sequence[tuple[int, int]]) -> FloatArray:
        """Clearance (m) each pair must keep: an obstacle's own ``clearance`` against that
        obstacle, ``table_distance`` against the table, else ``min_distance``."""
        table = set(self.world.ids.table_geoms)
        geoms = self.world.ids.obstacle_geoms
        own = {
            geoms[b.name]: b.clearance
            for b in self.world.scenario.scene.obstacles
            if b.clearance is not None and geoms.get(b.name, -1) >= 0
        }
        cfg = self.config

        def required(a: int, b: int) -> float:
            for g in (a, b):
                if g in own:
                    return float(own[g])
            return cfg.table_distance if table & {a, b} else cfg.min_distance

        return np.array([required(a, b) for a, b in pairs], dtype=float)

    def _geom(self, name: str) -> int:
        if name not in self.geom_names:
            valid = ", ".join(sorted(self.geom_names))
            raise PlanningInputError(f"allow_contact names no geom '{name}'; geoms are: {valid}")
        return self.geom_names[name]

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
    ) -> Trajectory:
        """Plan the whole body from ``q_start`` until every target hand is at its target.

        The posture task pulls the arms towards the home keyframe; the legs and waist hold
        their start angles (the body moves only as far as the hands need, so a short hand
        move is a short whole-body move), unless ``rest``: a return to the rest pose, where
        the legs and waist are pulled towards the keyframe too.

        The pelvis stays inside the robot's safe posture (``profile.safe_posture``): a target
        the hands reach only with the pelvis lower than that is refused with the depth it
        would need (the move is planned again without the pelvis limit to measure it).

        Raises PlanningError when a hand is still outside tolerance after the
        iteration budget (or when progress stalls), naming the side and the
        remaining position and angle errors, or the safe posture's limit that holds it back.
        """
        try:
            return self._move(q_start, targets, name, carried, allow_contact, rest, posture=True)
        except PlanningError as exc:
            if self._path_lowest > self.pelvis_floor + 2.0 * _PELVIS_QP_MARGIN:
                raise  # the pelvis limit did not hold the hands back
            self._posture_failure(exc, q_start, targets, name, carried, allow_contact, rest)
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
    ) -> None:
        """Plan a failed move again without the pelvis limit; raise the posture's named reason
        when that reaches the targets with the pelvis below the safe posture (else return)."""
        try:
            free = self._move(q_start, targets, name, carried, allow_contact, rest, posture=False)
        except PlanningError:
            return
        needed = self.standing_height - float(np.min(free.qpos[:, self.base_z_adr]))
        if needed <= self.posture_limits.max_pelvis_drop:
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
            f"allows: planned without that limit it takes {self.posture_limits.describe_drop(needed)} "
            f"(robot '{self.world.profile.name}', safe_posture.max_pelvis_drop); with the pelvis "
            f"held there, {held}",
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
    ) -> Trajectory:
        """:meth:`move`, with the safe posture's pelvis limit in the QP if ``posture``."""
        started = time.perf_counter()
        self._path_lowest = math.inf
        cfg, model, ids = self.config, self.model, self.world.ids
        self._check_request(q_start, targets, carried)
        conf = self.configuration
        conf.update(np.array(q_start, dtype=float))
        goals = self._routes(targets, carried, allow_contact)
        qp = self._move_qp(goals, carried, allow_contact, rest, posture)
        clearance0 = qp.collisions.distances(conf.data)
        # What a step may not cut below: the required clearance (or the start distance, when a
        # pair starts closer), less a slack well inside the knots' check (clearance_tolerance).
        floor = np.minimum(clearance0, qp.required) - cfg.step_slack
        path, iterations, ik_time = self._ik_path(name, goals, qp, floor)
        trajectory = build_trajectory(
            model,
            cfg,
            np.array(path),
            name,
            TimedJoints(self.timed_dofs, self.timed_limits),
            Frames(dict(ids.hand_sites), ids.base_body, self.quat_adr),
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

    def _move_qp(
        self,
        goals: dict[str, list[mink.SE3]],
        carried: tuple[str, str] | None,
        allow_contact: Sequence[str],
        rest: bool,
        posture: bool,
    ) -> _MoveQP:
        """Set a move's tasks at the current configuration and gather its QP (see the class doc)."""
        conf, model = self.configuration, self.model
        tasks, posture_cost, idle_dofs = self._set_tasks(goals, rest)
        for foot in self.feet:
            foot.set_target_from_configuration(conf)
        polygon = SupportPolygon.from_feet(model, conf.data, self.foot_geoms)
        self.com.set_target(np.array([*polygon.centre, 0.0]))
        attach, relative = self._attachment(carried)
        collisions, required = self._collision_limit(carried, allow_contact, attach)
        # Keep a small extra margin in the QP so that interpolated knots stay inside the checked one.
        margin = self.config.support_margin + 0.002
        balance = SupportPolygonLimit(model, self.world.ids.base_body, polygon, margin)
        limits: list[mink.Limit] = [self.tilt, balance, collisions]
        if posture:
            limits.insert(1, self.pelvis)
        constraints: list[mink.Task] = list(self.feet)
        return _MoveQP(
            tasks, limits, constraints, collisions, required, relative, polygon, posture_cost, idle_dofs
        )

    def _set_tasks(
        self, goals: dict[str, list[mink.SE3]], rest: bool
    ) -> tuple[list[mink.Task], FloatArray, NDArray[np.bool_]]:
        """Point each moving hand's task at its first goal and the posture task at the keyframe,
        an idle arm held at its start joint angles (so it moves with the torso and cannot wander
        into it). Returns the tasks, the posture cost and the idle arms' dofs."""
        cfg, conf = self.config, self.configuration
        posture_target = self.world.home_qpos()
        if cfg.hold_body and not rest:
            posture_target[self.body_qadr] = conf.q[self.body_qadr]
        posture_cost = self.posture_cost.copy()
        idle_dofs = np.zeros(self.model.nv, dtype=bool)
        tasks: list[mink.Task] = [self.com, self.posture]
        for side in self.sides:
            if side in goals:
                self.hands[side].set_target(goals[side][0])
                tasks.append(self.hands[side])
            else:
                posture_target[self.arm_qadr[side]] = conf.q[self.arm_qadr[side]]
                posture_cost[self.arm_dofs[side]] = cfg.idle_arm_cost
                idle_dofs[self.arm_dofs[side]] = True
        self.posture.set_target(posture_target)
        self.posture.set_cost(posture_cost)
        return tasks, posture_cost, idle_dofs

    def _attachment(self, carried: tuple[str, str] | None) -> tuple[dict[int, int], Relative | None]:
        """A carried object's geom -> its hand's body, and its pose relative to the hand site now."""
        attach: dict[int, int] = {}
        if carried is None:
            return attach, None
        model, ids, data = self.model, self.world.ids, self.configuration.data
        side, obj = carried
        hand_body = int(model.site_bodyid[ids.hand_sites[side]])
        attach[ids.object_geoms[obj]] = hand_body
        relative = (
            ids.hand_sites[side],
            ids.object_bodies[obj],
            ids.object_qpos[obj],
            site_pose(data, ids.hand_sites[side]).inverse() @ body_pose(data, ids.object_bodies[obj]),
        )
        return attach, relative

    def _collision_limit(
        self, carried: tuple[str, str] | None, allow_contact: Sequence[str], attach: dict[int, int]
    ) -> tuple[GeomPairCollisionLimit, FloatArray]:
        """The collision limit of (carried, allow_contact) and its pairs' required clearance (m),
        built on first use and kept (both depend on the model and the request only)."""
        key = (carried, tuple(allow_contact))
        if key not in self._limits:
            cfg = self.config
            pairs = self.collision_pairs(carried, allow_contact)
            required = self.required_clearance(pairs)
            self._limits[key] = (
                GeomPairCollisionLimit(
                    self.model,
                    pairs,
                    # As for the balance: a little extra in the QP keeps the interpolated knots clear.
                    required + cfg.clearance_tolerance,
                    _detection_distance(cfg, required),
                    cfg.collision_gain,
                    attach,
                    cfg.collision_recovery,
                ),
                required,
            )
        return self._limits[key]

    def _ik_path(
        self, name: str, goals: dict[str, list[mink.SE3]], qp: _MoveQP, floor: FloatArray
    ) -> tuple[list[FloatArray], int, float]:
        """IK steps from the current configuration until every hand is at the last of its goals.

        Returns the path (qpos per step, the start first), the iterations and the time spent in
        the QP (s). Raises PlanningError (:meth:`_fail`) on the iteration budget or a stall,
        and when the QP has no solution.
        """
        cfg, conf = self.config, self.configuration
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
                self._fail(name, errors, iterations)
            if relax > cfg.relax_floor and self._stalled(history, cfg.relax_iterations):
                # Short of the floor a short stall relaxes; at the floor only a long stall fails.
                relax *= cfg.relax_factor
                self.posture.set_cost(np.where(qp.idle_dofs, qp.posture_cost, qp.posture_cost * relax))
                history = history[-1:]
            elif self._stalled(history, cfg.stall_iterations):
                self._fail(name, errors, iterations)
            self._lead(active)
            tick = time.perf_counter()
            try:
                velocity = self._solve(tasks, limits, constraints, collisions)
            except mink.NoSolutionFound as exc:
                raise self._no_solution(name, errors, iterations, exc) from exc
            ik_time += time.perf_counter() - tick
            self._step(velocity, qp.relative, collisions, floor)
            iterations += 1
            path.append(conf.q)
            self._path_lowest = min(self._path_lowest, float(conf.q[self.base_z_adr]))
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
                self.hands[side].set_target(active[side])
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

    def _check_posture(self, trajectory: Trajectory) -> None:
        """Every knot's pelvis within the safe posture (the QP's limit is first order), or no
        lower than where the move started when it started below it."""
        heights = trajectory.qpos[:, self.base_z_adr]
        k = int(np.argmin(heights))
        if heights[k] >= min(self.pelvis_floor, float(heights[0])):
            return
        reason = self.posture_limits.describe_drop(self.standing_height - float(heights[k]))
        raise PlanningError(
            trajectory.name,
            None,
            0.0,
            0.0,
            0,
            f"motion '{trajectory.name}': at t = {trajectory.times[k]:.2f} s the timed path takes {reason}",
        )

    def _routes(
        self, targets: Sequence[HandTarget], carried: tuple[str, str] | None, allow_contact: Sequence[str]
    ) -> dict[str, list[mink.SE3]]:
        """Per moving hand: via points over obstacles in the way (planning_route), then the target."""
        model, ids, data = self.model, self.world.ids, self.configuration.data
        allowed = {self._geom(n) for n in allow_contact}
        carried_geom = ids.object_geoms[carried[1]] if carried else None
        blockers = [
            g
            for g in [*ids.obstacle_geoms.values(), *ids.object_geoms.values()]
            if g not in allowed and g != carried_geom
        ]
        boxes = [world_box(model, data, g) for g in blockers]
        routes: dict[str, list[mink.SE3]] = {}
        for t in targets:
            site = ids.hand_sites[t.side]
            moving = [g for g in ids.robot_geoms if int(model.geom_bodyid[g]) in ids.hand_bodies[t.side]]
            if carried is not None and carried[0] == t.side and carried_geom is not None:
                moving.append(carried_geom)
            extent = footprint(model, data, site, moving)
            start = data.site_xpos[site].copy()
            vias = via_points(
                start, np.asarray(t.position, dtype=float), extent, boxes, self.config.via_clearance
            )
            routes[t.side] = [se3(v, t.quat) for v in vias] + [se3(t.position, t.quat)]
        return routes

    def _lead(self, goals: dict[str, mink.SE3]) -> None:
        """Point each hand task at most ``lead_distance`` / ``lead_angle_rad`` ahead of the hand.

        The hand then follows the straight line (and the shortest rotation) to its goal,
        while the balance and posture tasks keep up, instead of lunging at a far goal
        with whatever joints are cheapest and curving back later.
        """
        cfg, data = self.config, self.configuration.data
        for side, goal in goals.items():
            site = self.world.ids.hand_sites[side]
            position, quat = data.site_xpos[site], site_quat(data, site)
            delta = goal.wxyz_xyz[4:] - position
            turn = _rotation_log(quat, goal.wxyz_xyz[:4])  # hand to goal, in the hand frame
            dist, ang = float(np.linalg.norm(delta)), float(np.linalg.norm(turn))
            alpha = min(1.0, cfg.lead_distance / max(dist, 1e-12), cfg.lead_angle_rad / max(ang, 1e-12))
            if alpha >= 1.0:
                self.hands[side].set_target(goal)
                continue
            # mink.SO3.exp and the product, with the same MuJoCo routines mink uses.
            axis = alpha * turn
            theta = mujoco.mju_normalize3(axis)
            step, rotation = np.empty(4), np.empty(4)
            mujoco.mju_axisAngle2Quat(step, axis, theta)
            mujoco.mju_mulQuat(rotation, quat, step)
            self.hands[side].set_target(mink.SE3(np.concatenate([rotation, position + alpha * delta])))

    def _solve(
        self,
        tasks: list[mink.Task],
        limits: list[mink.Limit],
        constraints: list[mink.Task],
        collisions: GeomPairCollisionLimit,
    ) -> FloatArray:
        """One IK step's QP. Should pushing pairs back out to their clearance (the collision
        rows' recovery) leave no solution, solve again with the rows only holding them."""
        cfg = self.config
        try:
            return self.joints.solve(self.configuration, tasks, cfg.ik_dt, cfg.damping, limits, constraints)
        except mink.NoSolutionFound:
            if collisions.recovery == 0.0:
                raise
        collisions.recovery = 0.0
        try:
            return self.joints.solve(self.configuration, tasks, cfg.ik_dt, cfg.damping, limits, constraints)
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
        conf, cfg = self.configuration, self.config
        for _ in range(3):
            drift = max(float(np.linalg.norm(f.compute_error(conf))) for f in self.feet)
            if drift < cfg.feet_tolerance:
                return
            velocity = self.joints.project(conf, self.feet, cfg.ik_dt)
            conf.integrate_inplace(velocity, cfg.ik_dt)
            conf.update()

    def _check_request(
        self, q_start: FloatArray, targets: Sequence[HandTarget], carried: tuple[str, str] | None
    ) -> None:
        q = np.asarray(q_start)
        if q.shape != (self.model.nq,):
            raise PlanningInputError(
                f"q_start has shape {q.shape}; the world's model needs ({self.model.nq},)"
            )
        sides = [t.side for t in targets]
        valid = ", ".join(self.sides)
        for side in sides:
            if side not in self.sides:
                raise PlanningInputError(f"no hand '{side}'; hands are: {valid}")
        if len(set(sides)) != len(sides) or not sides:
            raise PlanningInputError(f"give one target per moving hand, at least one; got sides {sides}")
        if carried is not None:
            side, obj = carried
            if side not in self.sides:
                raise PlanningInputError(f"carried by hand '{side}'; hands are: {valid}")
            if obj not in self.world.ids.object_bodies:
                objs = ", ".join(sorted(self.world.ids.object_bodies))
                raise PlanningInputError(f"carried object '{obj}' is not in the world; objects are: {objs}")

    def _errors(self, goals: dict[str, mink.SE3]) -> dict[str, tuple[float, float]]:
        """Per hand: distance (m) and rotation angle (rad) from its goal."""
        data = self.configuration.data
        out = {}
        for side, goal in goals.items():
            site = self.world.ids.hand_sites[side]
            pos = float(np.linalg.norm(data.site_xpos[site] - goal.wxyz_xyz[4:]))
            out[side] = (pos, _rotation_angle(goal.wxyz_xyz[:4], site_quat(data, site)))
        return out

    def _arrived(self, errors: dict[str, tuple[float, float]]) -> bool:
        cfg = self.config
        return all(p <= cfg.position_tolerance and a <= cfg.angle_tolerance_rad for p, a in errors.values())

    def _stalled(self, history: list[float], n: int) -> bool:
        return len(history) > n and history[-n - 1] - history[-1] < self.config.stall_improvement

    def _fail(self, name: str, errors: dict[str, tuple[float, float]], iterations: int) -> None:
        cfg = self.config
        side, (pos, ang) = max(
            errors.items(),
            key=lambda kv: max(kv[1][0] / cfg.position_tolerance, kv[1][1] / cfg.angle_tolerance_rad),
        )
        raise PlanningError(name, side, pos, ang, iterations)


# --- small helpers --------------------------------------------------------------------------


def _relative(a: FloatArray, b: FloatArray) -> FloatArray:
    """a^-1 b of two unit quaternions, sign-fixed to w >= 0 as mink's SO3.log does."""
    inverse, out = np.empty(4), np.empty(4)
    mujoco.mju_negQuat(inverse, a)
    mujoco.mju_mulQuat(out, inverse, b)
    return out * np.sign(out[0])


def _rotation_log(a: FloatArray, b: FloatArray) -> FloatArray:
    """``(SO3(a).inverse() @ SO3(b)).log()`` of mink: the rotation vector from a to b."""
    q = _relative(a, b)
    v = q[1:].copy()
    norm = mujoco.mju_normalize3(v)
    if norm < 1e-10:  # mink's epsilon for float64
        return np.zeros(3)
    return np.asarray(2.0 * math.atan2(norm, float(q[0])) * v, dtype=float)


def _rotation_angle(a: FloatArray, b: FloatArray) -> float:
    """The norm of :func:`_rotation_log`: the angle (rad) between the two orientations."""
    q = _relative(a, b)
    norm = math.sqrt(float(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))
    if norm < 1e-10:
        return 0.0
    return 2.0 * math.atan2(norm, float(q[0]))


def _detection_distance(cfg: PlannerConfig, required: FloatArray) -> float:
    """The collision limit's detection distance: the configured one, widened for an obstacle's
    own clearance above ``min_distance`` so that its pairs enter the QP as far beyond their
    clearance as the others do."""
    widest = float(np.max(required, initial=0.0))
    if widest <= cfg.min_distance:
        return cfg.detection_distance
    return max(cfg.detection_distance, widest + cfg.detection_distance - cfg.min_distance)
