"""The differential-IK loop of one step phase: a foot and the CoM to their targets.

:class:`StepIK` steps mink's QP (assembled and solved by the planner's
:class:`~executive.planning.limits.JointBounds`) for one :class:`PhaseGoal`: the feet on the floor
held as equality constraints, the swing foot's ``FrameTask`` and the ``ComTask`` led along straight
lines to their goals, the pelvis kept level and headed, a posture task, and the limits of the
whole-body planner (the CoM inside the phase's support polygon, the torso's tilt, the pelvis
height, joint ranges and speeds) plus the legs kept apart from each other and from the scene.
When the phase stalls short of its goal, :meth:`StepIK.binding` names the limits at their bound.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.limits import GeomPairCollisionLimit, SupportPolygon, SupportPolygonLimit, geom_pairs
from executive.planning.loaded_com import LoadedCoM, LoadedComTask
from executive.planning.problem import PlanningProblem
from executive.planning.rotation import rotation_angle, rotation_log
from executive.planning.stepping_ankles import AnkleReserveLimit, reserve_limit, waist_roll
from executive.planning.stepping_knees import KneeBendLimit, find_knees
from executive.planning.stepping_types import StepConfig
from executive.planning.types import PlanningError, attach_object
from executive.world.heading import yaw_quat
from executive.world.model import is_descendant

__all__ = ["PhaseGoal", "StepIK", "StepPlanningError"]

FloatArray = NDArray[np.float64]

#: How close (rad, m) a joint, the pelvis or the CoM must be to its bound to count as binding.
_JOINT_SLACK = 0.01
_BOUND_SLACK = 0.004


class StepPlanningError(PlanningError):
    """A step could not be planned. ``binds`` names what held it back (joint ranges at their
    bound, the CoM at its polygon's edge, the pelvis at its lowest, the torso at its tilt limit,
    a pair of legs at their clearance), empty when nothing did (a stall)."""

    def __init__(self, name: str, reason: str, binds: Sequence[str] = (), iterations: int = 0) -> None:
        super().__init__(name, None, 0.0, 0.0, iterations, reason)
        self.binds = tuple(binds)


class PhaseGoal(NamedTuple):
    """What one phase's IK drives to.

    ``held``: the feet on the floor (held where they are); ``swing``/``foot_goal``: the moving
    foot and its goal pose (None: no foot moves); ``com_goal``: the CoM's xy target, which the
    phase must reach when ``com_required``; ``polygon``/``margin``: the support polygon the
    CoM stays inside, shrunk by ``margin`` (m); ``pelvis_yaw``: the pelvis's heading (rad);
    ``com_region``/``region_margin``: where a CoM that stalls short of its goal may end the
    phase (inside it by ``region_margin`` (m); None: it may not); ``waist``: the waist joints'
    angles the posture task holds (None: where the phase starts).
    """

    name: str
    held: tuple[str, ...]
    swing: str | None
    foot_goal: mink.SE3 | None
    com_goal: FloatArray
    com_required: bool
    polygon: SupportPolygon
    margin: float
    pelvis_yaw: float
    com_region: SupportPolygon | None = None
    region_margin: float = 0.0
    waist: FloatArray | None = None


class StepIK:
    """The IK of the step phases on ``problem``'s model, integrated on ``configuration``.

    Build once per step planner; :meth:`path` runs one phase from the configuration's current
    state (and leaves it at the phase's end).

    Args:
        problem: the world's whole-body IK problem (its joint groups, joint bounds, tilt and
            pelvis limits, collision pairs).
        configuration: the configuration the steps are integrated on.
        config: the step planner's tuning.
    """

    def __init__(
        self,
        problem: PlanningProblem,
        configuration: mink.Configuration,
        config: StepConfig,
        carried: tuple[str, str] | None = None,
    ) -> None:
        self.problem = problem
        self.carried = carried
        self.configuration = configuration
        self.config = config
        self.planner_config = problem.config
        world, model = problem.world, problem.model
        self.model = model
        self.feet = {side: int(model.body(f.body).id) for side, f in world.profile.feet.items()}
        self.sole_geoms = {side: list(world.ids.foot_geoms[side]) for side in self.feet}
        c = config
        self.foot_tasks = {
            side: mink.FrameTask(body, "body", c.foot_position_cost, c.foot_orientation_cost)
            for side, body in self.feet.items()
        }
        self.holds = {side: mink.FrameTask(body, "body", 1.0, 1.0) for side, body in self.feet.items()}
        self.loaded = LoadedCoM(world, carried)  # the CoM balanced: the robot's and a carried object's
        self.com = LoadedComTask(self.loaded, cost=[c.com_cost, c.com_cost, 0.0])
        base = world.ids.base_body
        self.pelvis = mink.FrameTask(base, "body", 0.0, c.pelvis_orientation_cost)
        self.home_pelvis_quat = np.array(world.home_qpos()[problem.quat_adr[0] : problem.quat_adr[0] + 4])
        self._posture(world.profile.leg_joints, world.profile.waist_joints)
        self._leg_ranges(world.profile.leg_joints, world.profile.waist_joints)
        self.knees = find_knees(model, world.home_qpos(), world.profile.leg_joints, self.feet)
        self.knee_limit = KneeBendLimit(model, self.knees, c.knee_bend) if c.knee_bend > 0 else None
        self.ankle_limit: AnkleReserveLimit | None = (
            reserve_limit(world, self.feet, self.sole_geoms, c.balance_reserve_sigmas)
            if c.balance_reserve
            else None
        )
        self._collision_limits: dict[str, tuple[GeomPairCollisionLimit, FloatArray]] = {}
        self._attach, _ = problem.attachment(configuration.data, carried)
        self._active = self.collisions(next(iter(self.feet)))[0]  # the limit of the phase running

    def _posture(self, legs: dict[str, tuple[str, ...]], waist: Sequence[str]) -> None:
        """The posture task: the legs gently towards the keyframe, waist and arms held."""
        model, c = self.model, self.config
        cost = np.zeros(model.nv)
        self.leg_qadr: dict[str, NDArray[np.int_]] = {}
        for side, names in legs.items():
            joints = [model.joint(n).id for n in names]
            cost[[model.jnt_dofadr[j] for j in joints]] = c.posture_leg_cost
            self.leg_qadr[side] = np.array([model.jnt_qposadr[j] for j in joints], dtype=int)
        cost[[model.jnt_dofadr[model.joint(n).id] for n in waist]] = c.posture_waist_cost
        self.waist_qadr = np.array([model.jnt_qposadr[model.joint(n).id] for n in waist], dtype=int)
        for dofs in self.problem.arm_dofs.values():
            cost[dofs] = c.posture_arm_cost
        self.posture = mink.PostureTask(model, cost=cost, gain=self.planner_config.posture_gain)
        self._posture_cost = cost
        roll = waist_roll(model, self.problem.world.home_qpos(), self.problem.world.ids.base_body, waist)
        self.waist_roll_dof = None if roll is None else int(model.jnt_dofadr[model.joint(roll).id])

    def _leg_ranges(self, legs: dict[str, tuple[str, ...]], waist: Sequence[str]) -> None:
        """The leg and waist joints with a range: (name, qpos address, lower, upper)."""
        model = self.model
        names = [n for side in legs.values() for n in side] + list(waist)
        self.ranged = [
            (n, int(model.jnt_qposadr[j]), float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1]))
            for n in names
            if model.jnt_limited[j := model.joint(n).id]
        ]

    def collisions(self, swing: str) -> tuple[GeomPairCollisionLimit, FloatArray]:
        """The collision limit of a step of ``swing`` and its pairs' required clearance (m): the
        whole-body planner's pairs (the arms, and a carried object, against the scene and the body)
        and the swing leg against the other leg, and both legs against the table, obstacles and
        the objects not carried."""
        if swing in self._collision_limits:
            return self._collision_limits[swing]
        problem, model, ids = self.problem, self.model, self.problem.world.ids
        pairs = problem.collisions.pairs(self.carried)
        required = list(problem.collisions.required_clearance(pairs))
        legs = {side: self._leg_geoms(side) for side in self.feet}
        objects = [g for g in ids.object_geoms.values() if g not in self._attach]
        env = list(ids.table_geoms) + list(ids.obstacle_geoms.values()) + objects
        groups: list[tuple[Sequence[int], Sequence[int]]] = [
            (legs[swing], legs[s]) for s in legs if s != swing
        ]
        groups += [(geoms, env) for geoms in legs.values()]
        extra = [p for p in geom_pairs(model, groups) if p not in set(pairs)]
        pairs += extra
        required += [self.config.leg_clearance] * len(extra)
        need = np.array(required, dtype=float)
        cfg = self.planner_config
        limit = GeomPairCollisionLimit(
            model,
            pairs,
            need + cfg.clearance_tolerance,
            max(cfg.detection_distance, float(np.max(need, initial=0.0)) + 0.05),
            cfg.collision_gain,
            self._attach or None,
            cfg.collision_recovery,
        )
        self._collision_limits[swing] = (limit, need)
        return limit, need

    def _leg_geoms(self, side: str) -> list[int]:
        """The collision geoms of a leg: the subtree of its first joint's body."""
        model, ids = self.model, self.problem.world.ids
        first = model.joint(self.problem.world.profile.leg_joints[side][0]).id
        root = int(model.jnt_bodyid[first])
        return [g for g in ids.robot_geoms if is_descendant(model, int(model.geom_bodyid[g]), root)]

    # --- one phase ----------------------------------------------------------------------------

    def path(
        self, goal: PhaseGoal, collisions: GeomPairCollisionLimit, probe: bool = False, lean: bool = False
    ) -> tuple[list[FloatArray], int]:
        """IK steps from the configuration's current state until the phase's goal is reached.

        Args:
            goal: the phase's goal.
            collisions: the collision limit of the step (:meth:`collisions`).
            probe: stop quietly at a stall instead of raising (a reach probe).
            lean: the waist's roll held at ``lean_cost`` instead of the waist's posture cost (the
                torso leans over the stance foot where the legs leave the CoM short).

        Returns:
            The path (qpos per step, the start first) and the iterations.

        Raises:
            StepPlanningError: on a stall or the iteration budget (naming what binds), or when
                the QP has no solution.
        """
        conf, c, cfg = self.configuration, self.config, self.planner_config
        cost = self._posture_cost.copy()
        if lean and self.waist_roll_dof is not None:
            cost[self.waist_roll_dof] = c.lean_cost
        self.posture.set_cost(cost)
        tasks, limits, constraints = self._set_tasks(goal, collisions)
        self._active = collisions
        _, relative = self.problem.attachment(conf.data, self.carried)  # moves with its hand
        path = [conf.q]
        history = [self._error(goal)]
        iterations = 0
        while not self._arrived(goal):
            if iterations >= c.max_iterations or self._stalled(history):
                if probe or self._settled(goal):
                    break
                raise self._failure(goal, iterations, "stops")
            self._lead(goal)
            try:
                velocity = self.problem.joints.solve(conf, tasks, cfg.ik_dt, cfg.damping, limits, constraints)
            except mink.NoSolutionFound as exc:
                if probe:
                    break
                raise self._failure(goal, iterations, f"has no IK solution ({exc}) and stops") from exc
            conf.integrate_inplace(velocity, cfg.ik_dt)
            conf.update()
            self._project(constraints)
            if relative is not None:
                attach_object(conf.data, relative)
                conf.update()
            iterations += 1
            path.append(conf.q)
            history.append(self._error(goal))
        return path, iterations

    def _set_tasks(
        self, goal: PhaseGoal, collisions: GeomPairCollisionLimit
    ) -> tuple[list[mink.Task], list[mink.Limit], list[mink.Task]]:
        """Point the phase's tasks at the current configuration and gather its QP."""
        conf, problem = self.configuration, self.problem
        constraints: list[mink.Task] = []
        for side in goal.held:
            self.holds[side].set_target_from_configuration(conf)
            constraints.append(self.holds[side])
        # The legs towards the keyframe; the waist and the arms held where they are.
        target = conf.q.copy()
        legs = np.concatenate(list(self.leg_qadr.values()))
        target[legs] = problem.world.home_qpos()[legs]
        if goal.waist is not None:
            target[self.waist_qadr] = goal.waist
        self.posture.set_target(target)
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, yaw_quat(goal.pelvis_yaw), self.home_pelvis_quat)
        self.pelvis.set_target(mink.SE3(np.concatenate([quat, conf.data.xpos[problem.world.ids.base_body]])))
        tasks: list[mink.Task] = [self.com, self.posture, self.pelvis]
        if goal.swing is not None and goal.foot_goal is not None:
            tasks.append(self.foot_tasks[goal.swing])
        margin = goal.margin + 0.002  # as the planner's: interpolated knots stay inside the checked one
        balance = SupportPolygonLimit(
            self.model, problem.world.ids.base_body, goal.polygon, margin, com=self.loaded
        )
        limits: list[mink.Limit] = [problem.tilt, problem.pelvis, balance, collisions]
        if self.knee_limit is not None:
            limits.append(self.knee_limit)
        if self.ankle_limit is not None:
            self.ankle_limit.support = goal.held
            limits.append(self.ankle_limit)
        return tasks, limits, constraints

    def _lead(self, goal: PhaseGoal) -> None:
        """Point the CoM and the swing foot's tasks a bounded way ahead along their straight lines."""
        data, c = self.configuration.data, self.config
        com = self.loaded.position(data)[:2]
        delta = goal.com_goal - com
        alpha = min(1.0, c.com_lead / max(float(np.linalg.norm(delta)), 1e-12))
        self.com.set_target(np.array([*(com + alpha * delta), 0.0]))
        if goal.swing is None or goal.foot_goal is None:
            return
        body = self.feet[goal.swing]
        position, quat = data.xpos[body], data.xquat[body]
        move = goal.foot_goal.wxyz_xyz[4:] - position
        turn = rotation_log(quat, goal.foot_goal.wxyz_xyz[:4])
        dist, ang = float(np.linalg.norm(move)), float(np.linalg.norm(turn))
        alpha = min(1.0, c.foot_lead / max(dist, 1e-12), c.foot_lead_angle_rad / max(ang, 1e-12))
        if alpha >= 1.0:
            self.foot_tasks[goal.swing].set_target(goal.foot_goal)
            return
        axis = alpha * turn
        theta = mujoco.mju_normalize3(axis)
        step, rotation = np.empty(4), np.empty(4)
        mujoco.mju_axisAngle2Quat(step, axis, theta)
        mujoco.mju_mulQuat(rotation, quat, step)
        self.foot_tasks[goal.swing].set_target(mink.SE3(np.concatenate([rotation, position + alpha * move])))

    def _project(self, constraints: list[mink.Task]) -> None:
        """Remove the held feet's second-order drift (as the whole-body planner's feet projection)."""
        cfg = self.planner_config
        self.problem.project_drift(self.configuration, constraints, cfg.feet_tolerance, cfg.ik_dt)

    # --- progress -----------------------------------------------------------------------------

    def foot_error(self, goal: PhaseGoal) -> tuple[float, float]:
        """The swing foot's distance (m) and angle (rad) from its goal (zeros: no foot moves)."""
        if goal.swing is None or goal.foot_goal is None:
            return 0.0, 0.0
        data, body = self.configuration.data, self.feet[goal.swing]
        pos = float(np.linalg.norm(data.xpos[body] - goal.foot_goal.wxyz_xyz[4:]))
        return pos, rotation_angle(goal.foot_goal.wxyz_xyz[:4], data.xquat[body])

    def com_error(self, goal: PhaseGoal) -> float:
        """The CoM's xy distance (m) from its goal."""
        com = self.loaded.position(self.configuration.data)[:2]
        return float(np.linalg.norm(com - goal.com_goal))

    def _error(self, goal: PhaseGoal) -> float:
        pos, ang = self.foot_error(goal)
        return pos + ang + (self.com_error(goal) if goal.com_required else 0.0)

    def _arrived(self, goal: PhaseGoal) -> bool:
        com = not goal.com_required or self.com_error(goal) <= self.config.com_tolerance
        return self._foot_arrived(goal) and com

    def _settled(self, goal: PhaseGoal) -> bool:
        """Whether a stalled phase may end where it is: its foot arrived and its CoM inside its
        ``com_region`` shrunk by ``region_margin``."""
        if goal.com_region is None or not self._foot_arrived(goal):
            return False
        com = self.loaded.position(self.configuration.data)[:2]
        return goal.com_region.margin(com) >= goal.region_margin

    def _foot_arrived(self, goal: PhaseGoal) -> bool:
        c = self.config
        pos, ang = self.foot_error(goal)
        return pos <= c.foot_position_tolerance and ang <= c.foot_angle_tolerance_rad

    def short_at_reserve(self, goal: PhaseGoal) -> bool:
        """Whether the phase ended with its CoM farther than ``com_tolerance`` from its goal and
        a held foot's ankle at its balance reserve, with a waist roll that could lean the torso."""
        if self.ankle_limit is None or self.waist_roll_dof is None:
            return False
        at_reserve = self.ankle_limit.binding(self.configuration.q, goal.held)
        return bool(at_reserve) and self.com_error(goal) > self.config.com_tolerance

    def _stalled(self, history: list[float]) -> bool:
        n = self.config.stall_iterations
        return len(history) > n and history[-n - 1] - history[-1] < self.config.stall_improvement

    # --- what binds ---------------------------------------------------------------------------

    def binding(self, goal: PhaseGoal, collisions: GeomPairCollisionLimit) -> list[str]:
        """The limits at their bound in the current configuration, named for a message."""
        conf, problem = self.configuration, self.problem
        q, data = conf.q, conf.data
        out = []
        for name, qadr, lower, upper in self.ranged:
            if q[qadr] <= lower + _JOINT_SLACK:
                out.append(f"joint '{name}' at its lower limit {lower:.2f} rad")
            elif q[qadr] >= upper - _JOINT_SLACK:
                out.append(f"joint '{name}' at its upper limit {upper:.2f} rad")
        for knee in self.knees.values() if self.knee_limit is not None else ():
            if knee.bends * (q[knee.qadr] - knee.straight) <= self.config.knee_bend + _JOINT_SLACK:
                out.append(
                    f"joint '{knee.joint}' at its bend limit ({self.config.knee_bend:.2f} rad from straight)"
                )
        if self.ankle_limit is not None:
            out += self.ankle_limit.binding(q, goal.held)
        base = problem.world.ids.base_body
        com_margin = goal.polygon.margin(self.loaded.position(data)[:2])
        if com_margin <= goal.margin + 0.002 + _BOUND_SLACK:
            which = "stance sole" if len(goal.held) == 1 else "feet's support polygon"
            out.append(f"the CoM at the {which}'s edge ({com_margin * 1000:.0f} mm inside)")
        drop = problem.standing_height - float(data.xpos[base][2])
        if float(data.xpos[base][2]) <= problem.pelvis.min_height + _BOUND_SLACK:
            out.append(f"the pelvis at its lowest ({problem.posture_limits.describe_drop(drop)})")
        tilt = float(np.degrees(np.arccos(np.clip(data.xmat[problem.world.ids.torso_body][8], -1.0, 1.0))))
        limit = float(np.degrees(np.arccos(problem.tilt.min_cos)))
        if tilt >= limit - 0.5:
            out.append(f"the torso's tilt at its limit ({tilt:.1f} of {limit:.0f} deg)")
        out += self._close_pairs(collisions)
        return out

    def _close_pairs(self, collisions: GeomPairCollisionLimit) -> list[str]:
        """Collision pairs at their clearance, named."""
        distances = collisions.distances(self.configuration.data)
        close = np.flatnonzero(distances <= collisions.min_distance + _BOUND_SLACK)
        names = []
        for i in close.tolist():
            a, b = (self._geom_label(int(g)) for g in collisions.pairs[i])
            names.append(f"{a} and {b} at their clearance ({distances[i] * 1000:.0f} mm)")
        return names

    def _geom_label(self, geom: int) -> str:
        """``geom 'name'``, or ``a geom of body 'name'`` for an unnamed geom."""
        name = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, geom)
        if name:
            return f"geom '{name}'"
        body = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_BODY, int(self.model.geom_bodyid[geom]))
        return f"a geom of body '{body}'"

    def _failure(self, goal: PhaseGoal, iterations: int, what: str) -> StepPlanningError:
        """The error of a phase that stops short, naming what binds."""
        binds = self.binding(goal, self._active)
        pos, ang = self.foot_error(goal)
        short = (
            f"the {goal.swing} foot {what} {pos * 1000:.0f} mm and {np.degrees(ang):.1f} deg short of "
            "its goal"
            if goal.swing
            else f"the CoM {what} {self.com_error(goal) * 1000:.0f} mm short of its goal"
        )
        held = "; ".join(binds) if binds else "no limit at its bound (the IK stalls)"
        return StepPlanningError(
            goal.name,
            f"step phase '{goal.name}': {short} after {iterations} IK steps; binding: {held}",
            binds,
            iterations,
        )
