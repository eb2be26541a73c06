"""Who holds the object when along a planned alternative: carry spans, handovers, poses.

:func:`hold_problem` walks a plan's steps and collects, per hand, the knots at which it holds
the object (:class:`CarrySpan`: the object's path, from which the grip's load follows) and, per
handover, the geometry of the receiver closing on the object the giver holds
(:class:`ReceiverMiss`). :mod:`executive.risk.hold` turns them into a probability.

Usage::

    problem = hold_problem(world, plan)
    for span, g in problem.spans: ...
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.timing import Trajectory
from executive.risk.hold_grip import Grip, grip
from executive.risk.hold_patch import patch
from executive.risk.model_geometry import body_half_extent, site_pose_at
from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = [
    "GRAVITY",
    "CarrySpan",
    "HoldProblem",
    "ReceiverMiss",
    "hold_problem",
    "object_pose_at",
    "servo_sag",
]

FloatArray = NDArray[np.float64]
GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass
class CarrySpan:
    """The knots at which one hand holds the object: times (s), object rotations and COM path.

    grasp_rotation / grasp_centre: the object's centre (COM) and rotation in the hand site
    frame at the grasp (fixed while held); object_half: its half extents along site x and z.
    alone: per knot, True when no other hand holds it.
    """

    side: str
    grasp_rotation: FloatArray  # (3, 3) object frame -> site frame
    grasp_centre: FloatArray  # (3,) object COM in the site frame
    object_half: FloatArray  # (2,) the object's half extents along site x and z
    times: list[float] = field(default_factory=list)
    rotations: list[FloatArray] = field(default_factory=list)  # object rotation per knot
    positions: list[FloatArray] = field(default_factory=list)  # object COM per knot
    alone: list[bool] = field(default_factory=list)
    _forces: tuple[FloatArray, FloatArray] | None = field(default=None, repr=False)

    def add(self, t: float, rotation: FloatArray, position: FloatArray, alone: bool) -> None:
        if self.times and t <= self.times[-1] + 1e-9:
            return
        self.times.append(t)
        self.rotations.append(rotation)
        self.positions.append(position)
        self.alone.append(alone)

    def grip_forces(self) -> tuple[FloatArray, FloatArray]:
        """Per knot, the grip force per unit mass a - g in the site frame (K, 3), and dt weights."""
        if self._forces is None or len(self._forces[0]) != len(self.times):
            self._forces = self._compute_forces()
        return self._forces

    def _compute_forces(self) -> tuple[FloatArray, FloatArray]:
        t = np.asarray(self.times)
        pos = np.asarray(self.positions).reshape(-1, 3)
        if len(t) >= 3:
            acc = np.gradient(np.gradient(pos, t, axis=0), t, axis=0)  # finite differences
        else:
            acc = np.zeros_like(pos)
        site_rot = np.asarray(self.rotations) @ self.grasp_rotation.T  # world <- site
        force = np.einsum("kji,kj->ki", site_rot, acc - GRAVITY)
        dt = np.gradient(t) if len(t) >= 2 else np.zeros_like(t)
        return force, dt


@dataclass
class ReceiverMiss:
    """A handover's receiver closing its jaws on the object the giver holds.

    giver: the giver's span up to the receiver's grasp (plus the jaws' closing time);
    depth: m the receiver's pads reach past the object's face along its approach axis (plan);
    lever_cross / lever_cross2: y x r and y x (y x r) (world) for r from the giver's patch centre
    to the receiver's site, y the giver's closing axis (Rodrigues: the point moves by
    sin(t) y x r + (1 - cos t) y x (y x r) when the object turns t about y);
    approach: the receiver's approach axis (world); sag: how far the object's point under the
    receiver moves per kg held, by the giving arm's servo compliance (world, m/kg); receiver:
    the receiver's grip; receiver_centre: the object's centre in the receiver's site frame
    (plan); lateral_shift: how much of the object's lateral error along the giver's x shows
    along the receiver's x; closing_s: the receiver's closing time; squaring: the giver's turn
    about its closing axis per radian of yaw squared out of its jaws at most, w / (2 h_z), and
    patch_half_height its h_z (see :func:`executive.risk.hold.squaring_turn`); receiver_span:
    the receiver's own hold (set once the walk reaches it).
    """

    giver: CarrySpan
    depth: float
    lever_cross: FloatArray
    lever_cross2: FloatArray
    approach: FloatArray
    sag: FloatArray
    receiver: Grip
    receiver_centre: FloatArray
    receiver_half: FloatArray
    lateral_shift: float
    closing_s: float
    squaring: float
    patch_half_height: float
    receiver_span: CarrySpan | None = None


def servo_sag(
    world: World, qpos: FloatArray, side: str, load_point: FloatArray, probe_point: FloatArray
) -> FloatArray:
    """Displacement (world, m per kg) of a point held by the ``side`` hand under a held weight.

    The servos do not feed the held object's weight forward, so the weight m g at
    ``load_point`` (the object's COM) bends each servoed joint by tau / kp (a stiffness model
    of position servos): dq = Kp^-1 J_load^T m g, and a point rigidly held by the hand moves
    by J_probe dq, which includes the hand's turn under the weight's moment. Dofs without a
    servo and the gripper's own (force-saturated) slides are taken as rigid.

    Args:
        world: the world (its model); qpos: the configuration.
        side: the holding hand.
        load_point: world point where the weight acts; probe_point: world point to follow.

    Returns:
        (3,) the probe point's displacement per kg of held mass.
    """
    model = world.model
    body = int(model.site_bodyid[world.ids.hand_sites[side]])
    jac_load, jac_probe = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    with scratch_data(model) as data:
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_jac(model, data, jac_load, None, np.asarray(load_point, dtype=float), body)
        mujoco.mj_jac(model, data, jac_probe, None, np.asarray(probe_point, dtype=float), body)
    grippers = {a for acts in world.ids.gripper_actuators.values() for a in acts}
    compliance = np.zeros(model.nv)
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or a in grippers:
            continue
        joint = int(model.actuator_trnid[a, 0])
        kp = float(model.actuator_gainprm[a, 0])
        kind = int(model.jnt_type[joint])
        if kind in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)) and kp > 0:
            compliance[model.jnt_dofadr[joint]] = 1.0 / kp
    return np.asarray(jac_probe @ (compliance * (jac_load.T @ GRAVITY)), dtype=float)


@dataclass
class HoldProblem:
    """Everything the hold probability needs from one planned alternative."""

    obj: str
    mass: float
    spans: list[tuple[CarrySpan, Grip]] = field(default_factory=list)
    misses: list[ReceiverMiss] = field(default_factory=list)


def _object_poses(world: World, qpos: FloatArray, obj: str) -> tuple[FloatArray, FloatArray]:
    """The object's rotations (K, 3, 3) and COMs (K, 3) in configurations ``qpos`` (K, nq)."""
    adr = world.ids.object_qpos[obj]
    rows = np.atleast_2d(np.asarray(qpos, dtype=float))
    q = rows[:, adr + 3 : adr + 7]
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rot = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )  # unit quaternion (w, x, y, z) to rotation matrix
    com = rows[:, adr : adr + 3] + rot @ world.model.body_ipos[world.ids.object_bodies[obj]]
    return rot, com


def object_pose_at(world: World, qpos: FloatArray, obj: str) -> tuple[FloatArray, FloatArray]:
    """The object's rotation and COM (world) in one configuration ``qpos``."""
    rot, com = _object_poses(world, qpos, obj)
    return rot[0], com[0]


def _object_half(world: World, obj: str, obj_rot: FloatArray, site_rot: FloatArray) -> FloatArray:
    """The object's half extents along the site's x and z axes (object body frame conversion)."""
    geom = world.ids.object_geoms[obj]
    axes = obj_rot.T @ site_rot
    return np.array([body_half_extent(world.model, geom, axes[:, i]) for i in (0, 2)])


def _receiver_miss(
    world: World, qpos: FloatArray, obj: str, giver: tuple[CarrySpan, Grip], side: str, closing_s: float
) -> ReceiverMiss:
    """The geometry of the receiver ``side`` closing on the object ``giver`` holds at ``qpos``."""
    span, g = giver
    obj_rot, com = object_pose_at(world, qpos, obj)
    giver_rot = obj_rot @ span.grasp_rotation.T
    giver_pos = com - giver_rot @ span.grasp_centre
    half_g = _object_half(world, obj, obj_rot, giver_rot)
    pg = patch(g, span.grasp_centre[[0, 2]][None, :], half_g)
    centre_world = giver_pos + giver_rot @ np.array([pg.centre[0, 0], 0.0, pg.centre[0, 1]])
    rec_pos, rec_rot = site_pose_at(world, qpos, side)
    axis = giver_rot[:, 1]
    lever = rec_pos - centre_world
    rec_half = _object_half(world, obj, obj_rot, rec_rot)
    rec_centre = rec_rot.T @ (com - rec_pos)
    receiver = grip(world, side, obj, obj_rot.T @ rec_rot[:, 1])
    depth = receiver.pad_centre[1] + receiver.pad_half[1] - (rec_centre[2] - rec_half[1])
    return ReceiverMiss(
        giver=span,
        depth=float(depth),
        lever_cross=np.cross(axis, lever),
        lever_cross2=np.cross(axis, np.cross(axis, lever)),
        approach=rec_rot[:, 2].copy(),
        sag=servo_sag(world, qpos, g.side, com, rec_pos),
        receiver=receiver,
        receiver_centre=rec_centre[[0, 2]],
        receiver_half=rec_half,
        lateral_shift=float(giver_rot[:, 0] @ rec_rot[:, 0]),
        closing_s=closing_s,
        squaring=g.half_width / float(pg.half[0, 1]) if pg.half[0, 1] > 0.0 else 0.0,
        patch_half_height=float(pg.half[0, 1]),
    )


def hold_problem(world: World, plan: object, closing_s: float = 0.5) -> HoldProblem:
    """Walk a planned alternative's steps: who holds the object when, and each handover.

    Args:
        world: the estimate world the plan was made on.
        plan: an :class:`executive.planning.plan.AlternativePlan` (steps with kind, name, side;
            trajectories by step name; task.object).
        closing_s: time a grasp's jaws take to close and settle (the Grasp behaviour's settle
            time), spent with the object at rest in the hands that already hold it.

    Returns:
        The :class:`HoldProblem`.

    Raises:
        HoldModelUnavailable: a grasping hand is not a parallel jaw (see :func:`grip`).
    """
    from executive.planning.plan import held_at_start

    obj: str = plan.task.object  # type: ignore[attr-defined]
    body = world.ids.object_bodies[obj]
    problem = HoldProblem(obj=obj, mass=float(world.model.body_mass[body]))
    holding: dict[str, tuple[CarrySpan, Grip]] = {}
    qpos, t_now = world.data.qpos.copy(), 0.0
    trajectories: dict[str, Trajectory] = plan.trajectories  # type: ignore[attr-defined]
    held = held_at_start(plan.steps)  # type: ignore[attr-defined]
    for step in plan.steps:  # type: ignore[attr-defined]
        traj = trajectories.get(step.name)
        if traj is not None and held.get(step.side) == obj and not problem.spans:
            # Held from the start (a place after a pick): the grip is as the plan starts.
            holding[step.side] = _start_span(world, traj.qpos[0], obj, step.side, t_now)
            problem.spans.append(holding[step.side])
        if traj is not None:
            if holding:
                rots, coms = _object_poses(world, traj.qpos, obj)
                for k, t in enumerate(traj.times):
                    for span, _ in holding.values():
                        span.add(t_now + float(t), rots[k], coms[k], len(holding) == 1)
            t_now, qpos = t_now + traj.duration, traj.qpos[-1]
        elif step.kind == "grasp" and step.side not in holding:
            rot, com = object_pose_at(world, qpos, obj)
            t_now += closing_s
            for span, _ in holding.values():
                span.add(t_now, rot, com, len(holding) == 1)
            if holding:
                giver = next(iter(holding.values()))
                problem.misses.append(_receiver_miss(world, qpos, obj, giver, step.side, closing_s))
            site_pos, site_rot = site_pose_at(world, qpos, step.side)
            g = grip(world, step.side, obj, rot.T @ site_rot[:, 1])
            half = _object_half(world, obj, rot, site_rot)
            span = CarrySpan(step.side, site_rot.T @ rot, site_rot.T @ (com - site_pos), half)
            span.add(t_now, rot, com, not holding)
            holding[step.side] = (span, g)
            if problem.misses and problem.misses[-1].receiver_span is None and len(holding) > 1:
                problem.misses[-1].receiver_span = span
            problem.spans.append((span, g))
        elif step.kind == "release" and step.side in holding:
            del holding[step.side]
    return problem


def _start_span(world: World, qpos: FloatArray, obj: str, side: str, t: float) -> tuple[CarrySpan, Grip]:
    """The span of ``side`` holding ``obj`` in configuration ``qpos`` (its grip as it is there)."""
    rot, com = object_pose_at(world, qpos, obj)
    site_pos, site_rot = site_pose_at(world, qpos, side)
    g = grip(world, side, obj, rot.T @ site_rot[:, 1])
    half = _object_half(world, obj, rot, site_rot)
    span = CarrySpan(side, site_rot.T @ rot, site_rot.T @ (com - site_pos), half)
    span.add(t, rot, com, True)
    return span, g
