"""The whole-body planner's IK problem on one world: its tasks, limits and collision pairs.

:class:`PlanningProblem` is built once per world (by :class:`~executive.planning.planner.Planner`):
it sorts the robot's joints into groups, builds mink's tasks and the planner's limits on them,
and holds the geom pairs the collision limit keeps apart
(:class:`~executive.planning.collision_pairs.CollisionPairs`). :meth:`PlanningProblem.move_qp` sets the
tasks for one move and gathers that move's QP (:class:`MoveQP`), which
:class:`~executive.planning.ik_loop.IKLoop` steps through.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.collision_pairs import CollisionPairs
from executive.planning.limits import (
    GeomPairCollisionLimit,
    JointBounds,
    PelvisHeightLimit,
    SupportPolygon,
    SupportPolygonLimit,
    TiltLimit,
)
from executive.planning.types import PlannerConfig, PlanningInputError, Relative, body_pose, site_pose
from executive.robot.posture import standing_pelvis_height
from executive.world.model import World

__all__ = ["PELVIS_QP_MARGIN", "MoveQP", "PlanningProblem"]

FloatArray = NDArray[np.float64]

#: m the pelvis limit of the IK's QP keeps above the safe posture's floor.
PELVIS_QP_MARGIN = 0.005


class MoveQP(NamedTuple):
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


class PlanningProblem:
    """The IK problem of one world (build once, then :meth:`move_qp` per move).

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
    frozen in the QP and its collision Jacobian is taken on the palm.

    Args:
        world: the (estimate) world whose model the problem is built on.
        config: the planner's tuning.

    Raises:
        PlanningInputError: when the robot's base is not body 1 of the model (mink's CoM task).
    """

    def __init__(self, world: World, config: PlannerConfig) -> None:
        self.world = world
        self.config = config
        model = self.model = world.model
        ids = world.ids
        self.sides: tuple[str, ...] = tuple(sorted(ids.hand_sites))
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
        self.collisions = CollisionPairs(world, config)

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
        self.pelvis = PelvisHeightLimit(model, ids.base_body, self.pelvis_floor + PELVIS_QP_MARGIN)
        self.base_z_adr = int(model.jnt_qposadr[model.body_jntadr[ids.base_body]]) + 2

    # --- one move's QP ----------------------------------------------------------------------

    def move_qp(
        self,
        conf: mink.Configuration,
        goals: dict[str, list[mink.SE3]],
        carried: tuple[str, str] | None,
        allow_contact: Sequence[str],
        rest: bool,
        posture: bool,
    ) -> MoveQP:
        """Set a move's tasks at the configuration ``conf`` and gather its QP (see the class doc).

        Args:
            conf: the planner's configuration, at the move's start.
            goals: each moving hand's goals (its route), by side.
            carried: (hand side, object name) of a carried object.
            allow_contact: names of geoms the robot may touch in this move.
            rest: whether the move returns to the rest pose (the legs and waist pulled home too).
            posture: whether the safe posture's pelvis limit is in the QP.

        Returns:
            The move's QP.
        """
        model = self.model
        tasks, posture_cost, idle_dofs = self._set_tasks(conf, goals, rest)
        for foot in self.feet:
            foot.set_target_from_configuration(conf)
        polygon = SupportPolygon.from_feet(model, conf.data, self.foot_geoms)
        self.com.set_target(np.array([*polygon.centre, 0.0]))
        attach, relative = self.attachment(conf.data, carried)
        collisions, required = self.collisions.limit(carried, allow_contact, attach)
        # Keep a small extra margin in the QP so that interpolated knots stay inside the checked one.
        margin = self.config.support_margin + 0.002
        balance = SupportPolygonLimit(model, self.world.ids.base_body, polygon, margin)
        limits: list[mink.Limit] = [self.tilt, balance, collisions]
        if posture:
            limits.insert(1, self.pelvis)
        constraints: list[mink.Task] = list(self.feet)
        return MoveQP(
            tasks, limits, constraints, collisions, required, relative, polygon, posture_cost, idle_dofs
        )

    def _set_tasks(
        self, conf: mink.Configuration, goals: dict[str, list[mink.SE3]], rest: bool
    ) -> tuple[list[mink.Task], FloatArray, NDArray[np.bool_]]:
        """Point each moving hand's task at its first goal and the posture task at the keyframe,
        an idle arm held at its start joint angles (so it moves with the torso and cannot wander
        into it). Returns the tasks, the posture cost and the idle arms' dofs."""
        cfg = self.config
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

    def attachment(
        self, data: mujoco.MjData, carried: tuple[str, str] | None
    ) -> tuple[dict[int, int], Relative | None]:
        """A carried object's geom -> its hand's body, and its pose relative to the hand site now."""
        attach: dict[int, int] = {}
        if carried is None:
            return attach, None
        model, ids = self.model, self.world.ids
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

    def project_drift(
        self, conf: mink.Configuration, held: Sequence[mink.Task], tolerance: float, dt: float
    ) -> None:
        """Remove the ``held`` tasks' second-order drift from ``conf``: the least-norm dq with their rows
        exact (the QP of a step with no task but the damping), up to three passes, each squaring the
        error, until it is below ``tolerance``."""
        if not held:
            return
        for _ in range(3):
            drift = max(float(np.linalg.norm(t.compute_error(conf))) for t in held)
            if drift < tolerance:
                return
            conf.integrate_inplace(self.joints.project(conf, held, dt), dt)
            conf.update()
