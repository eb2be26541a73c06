"""What the robot observes of the objects, and how the estimate world is updated from it.

An :class:`Observation` is one look at the scene through the robot: the pose of every object
it sees, which hand holds which object, where the look came from (``source``) and when.
:func:`update_estimate` brings the estimate world (:class:`executive.world.model.World`) to it:

* an object no hand holds is put where it was seen (an object not seen stays where the
  estimate had it);
* an object a hand holds moves with that hand: it is put at the hand site's pose (at the
  robot's measured joints) times its *grip*, its pose in the site's frame
  (:class:`executive.world.model.Grip`). Each look at a held object measures the grip once
  more; the grip is the mean of those measurements since the grasp (a rigid grasp: the same
  offset seen with independent noise, so its error shrinks as one over the square root of
  the looks). A held object never seen is assumed at the site, in the orientation the
  estimate had it. ``World.held`` (object -> side) says which hand holds what; an object
  released (or lost) leaves it.

Which hand holds what is the robot's own record (the blackboard's ``holding``, written by
the grasp and release behaviours, :mod:`behaviours.gripper`) confirmed by touch: the hand
still holds the object by the grasp behaviour's own test (:data:`GRASP_CONTACTS` hand geoms
on it, :data:`GRASP_FORCE` in total; the robot's ``hand_contacts`` if it senses touch itself,
else the contacts of its MuJoCo state, :func:`executive.world.touch.hand_contacts`).

Sources: the bundled physics observes through a :class:`SimulatedSensor` (the truth world's
poses with Gaussian noise of the scenario's ``uncertainty``); a host's robot supplies its own
poses (:class:`executive.execution.robot_interface.HostRobot`, ``JointState.objects``). A robot with no
``observe_objects()`` sees nothing: only the held objects move (with the hands).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.world.heading import yaw_of, yaw_quat
from executive.world.model import Grip, World
from executive.world.touch import hand_contacts

__all__ = [
    "GRASP_CONTACTS",
    "GRASP_FORCE",
    "OBSERVATION_STREAM",
    "REASONS",
    "Observation",
    "SimulatedSensor",
    "confirmed_holding",
    "follow_base_of",
    "holders",
    "look",
    "measure_base",
    "measured_qpos",
    "refresh",
    "update_estimate",
]

FloatArray = NDArray[np.float64]
Pose = tuple[FloatArray, FloatArray]  # position (m), quaternion (w x y z)

#: A hand holds an object with at least this many of its geoms on it, pressing this hard in
#: total (N): the grasp behaviour's test (:class:`behaviours.gripper.Grasp` defaults).
GRASP_CONTACTS, GRASP_FORCE = 2, 10.0
#: The simulated sensor's generator is ``default_rng([seed, OBSERVATION_STREAM])``: the run's
#: truth seed, but a stream independent of the truth's own draw (``default_rng(seed)``).
OBSERVATION_STREAM = 1
#: ... and its odometry's (the base after a walk) ``default_rng([seed, ODOMETRY_STREAM])``.
ODOMETRY_STREAM = 2
#: Why the estimate is updated: after a task ended, after a failure, before a re-plan, and (a
#: host's robot) at start-up.
REASONS = ("after_task", "after_failure", "before_replan", "at_start")


@dataclass(frozen=True)
class Observation:
    """One look at the scene.

    objects: name -> (position, quaternion w x y z) of each object seen.
    holding: side -> object each hand holds (the robot's record, confirmed by touch).
    source: where the poses came from, for the log (``{"source": "simulated", ...}`` or
        ``{"source": "host"}``; ``{"source": "none"}`` for a robot that sees nothing).
    time: the robot's time (s).
    """

    objects: dict[str, Pose]
    holding: dict[str, str]
    source: dict[str, Any]
    time: float


class SimulatedSensor:
    """Object poses of the truth world as a noisy sensor gives them.

    Each look draws, per object (in the scenario's order), x and y offsets from
    N(0, ``uncertainty.object_position``) (the scenario's 1-sigma error per horizontal axis) and
    a yaw about the vertical from N(0, ``uncertainty.object_yaw_rad``); height, roll and pitch
    are exact. A sigma of 0 draws nothing on that axis. The same seed gives the same looks.

    Args:
        truth: the world physics runs (the sensor reads its current data).
        seed: the run's truth seed (the generator is ``default_rng([seed, OBSERVATION_STREAM])``).
    """

    def __init__(self, truth: World, seed: int) -> None:
        self.truth = truth
        self.seed = int(seed)
        self.sigma_position = float(truth.scenario.uncertainty.object_position)
        self.sigma_yaw = float(truth.scenario.uncertainty.object_yaw_rad)
        self.rng = np.random.default_rng([self.seed, OBSERVATION_STREAM])
        self.sigma_base = float(truth.scenario.uncertainty.base_position)
        self.sigma_base_yaw = float(truth.scenario.uncertainty.base_yaw_rad)
        self.odometry = np.random.default_rng([self.seed, ODOMETRY_STREAM])

    @property
    def source(self) -> dict[str, Any]:
        """The log's description of this sensor."""
        return {
            "source": "simulated",
            "sigma_position_m": self.sigma_position,
            "sigma_yaw_rad": self.sigma_yaw,
            "seed": self.seed,
        }

    def observe_base(self) -> Pose:
        """Where the robot measures its base after a walk: the truth with the odometry's noise."""
        pos = np.array(self.truth.data.qpos[self.truth.base_qpos][:3], dtype=float)
        quat = np.array(self.truth.data.qpos[self.truth.base_qpos][3:], dtype=float)
        if self.sigma_base:
            pos[:2] += self.odometry.normal(0.0, self.sigma_base, 2)
        if self.sigma_base_yaw:
            quat = _turn(quat, float(self.odometry.normal(0.0, self.sigma_base_yaw)))
        return pos, quat

    def observe(self) -> dict[str, Pose]:
        """One noisy look at every object of the truth world: name -> (position, quaternion)."""
        seen: dict[str, Pose] = {}
        for name in self.truth.ids.object_bodies:
            pos, quat = self.truth.object_pose(name)
            if self.sigma_position:
                pos[:2] += self.rng.normal(0.0, self.sigma_position, 2)
            if self.sigma_yaw:
                quat = _turn(quat, float(self.rng.normal(0.0, self.sigma_yaw)))
            seen[name] = (pos, quat)
        return seen


def _turn(quat: FloatArray, yaw: float) -> FloatArray:
    """``quat`` turned by ``yaw`` (rad) about the world's vertical."""
    out = np.empty(4)
    mujoco.mju_mulQuat(out, yaw_quat(yaw), np.asarray(quat, float))
    return out


def _holds(robot: Any, side: str, obj: str) -> bool:
    """The grasp behaviour's test: does ``side``'s hand hold ``obj`` now (touch)?"""
    sense = getattr(robot, "hand_contacts", None)
    n, force = sense(side, obj) if callable(sense) else hand_contacts(robot.world, side, obj)
    return n >= GRASP_CONTACTS and force >= GRASP_FORCE


def confirmed_holding(robot: Any, holding: Mapping[str, str]) -> dict[str, str]:
    """The entries of the robot's grasp record its touch confirms: side -> object.

    Args:
        robot: the robot (``hand_contacts(side, obj)`` if it senses touch, else its ``world``'s
            MuJoCo contacts are counted).
        holding: the robot's grasp record, side -> object (the blackboard's ``holding``).
    """
    return {side: obj for side, obj in holding.items() if _holds(robot, side, obj)}


def holders(holding: Mapping[str, str]) -> dict[str, str]:
    """Object -> the side that holds it, from a confirmed record (side -> object).

    An object in two hands (a handover midway) is given to the hand that grasped it first (the
    first in the record): the giver, which holds it until it lets go.
    """
    held: dict[str, str] = {}
    for side, obj in holding.items():
        held.setdefault(obj, side)
    return held


def look(robot: Any, holding: Mapping[str, str]) -> Observation:
    """One :class:`Observation` through ``robot``.

    Args:
        robot: the robot; its ``observe_objects()`` (name -> (position, quaternion)) gives the
            poses and its ``observation_source`` (a dict) says whence; a robot without them
            sees nothing.
        holding: the robot's grasp record, side -> object.
    """
    observe = getattr(robot, "observe_objects", None)
    seen = observe() if callable(observe) else {}
    source = dict(getattr(robot, "observation_source", None) or {"source": "none"})
    objects = {
        name: (np.asarray(p, float).copy(), np.asarray(q, float).copy()) for name, (p, q) in seen.items()
    }
    return Observation(objects, confirmed_holding(robot, holding), source, float(robot.time))


def update_estimate(world: World, q: FloatArray, seen: Observation) -> list[dict[str, Any]]:
    """Bring the estimate ``world`` to the observation ``seen`` (see the module docstring).

    Writes the objects' free joints of ``world.data`` (the robot's joints there are left as
    they are), ``world.held`` and ``world.grips``, then the kinematics.

    Args:
        world: the estimate world.
        q: the robot's measured configuration (full qpos of ``world``'s model; the hand sites
            are computed at it).
        seen: the observation.

    Returns:
        One record per object of the scene, for the log: name, position, yaw (rad), quat,
        held_by (side or None), seen (bool), and for a held object its grip's ``looks``.
    """
    sites = mujoco.MjData(world.model)
    sites.qpos[:] = q
    mujoco.mj_kinematics(world.model, sites)
    records = []
    held = holders(seen.holding)
    for name, adr in world.ids.object_qpos.items():
        side = held.get(name)
        pose = seen.objects.get(name)
        if side is None:
            world.held.pop(name, None)
            world.grips.pop(name, None)
        else:
            pose = _at_hand(world, sites, name, side, pose)
        if pose is not None:
            world.data.qpos[adr : adr + 3] = pose[0]
            world.data.qpos[adr + 3 : adr + 7] = pose[1] / np.linalg.norm(pose[1])
        records.append(_record(world, name, name in seen.objects))
    mujoco.mj_kinematics(world.model, world.data)
    for record in records:
        record["position"], quat = world.object_pose(record["name"])
        record["quat"], record["yaw"] = quat, yaw_of(quat)
    return records


def _record(world: World, name: str, was_seen: bool) -> dict[str, Any]:
    record: dict[str, Any] = {"name": name, "held_by": world.held_by(name), "seen": was_seen}
    grip = world.grips.get(name)
    if grip is not None:
        record["grip_looks"] = grip.looks
    return record


def _site_pose(data: mujoco.MjData, site: int) -> Pose:
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, data.site_xmat[site])
    return data.site_xpos[site].copy(), quat


def _at_hand(world: World, sites: mujoco.MjData, name: str, side: str, pose: Pose | None) -> Pose:
    """The pose of ``name`` held by ``side``: the hand site's pose times the (updated) grip."""
    site_pos, site_quat = _site_pose(sites, world.ids.hand_sites[side])
    grip = world.grips.get(name)
    if grip is not None and grip.side != side:  # a new grasp: the grip is measured afresh
        grip = None
    if pose is not None:
        grip = _measured(grip, side, site_pos, site_quat, pose)
    elif grip is None:  # held, never seen: at the site, oriented as the estimate has it
        _, quat = world.object_pose(name)
        grip = Grip(side, np.zeros(3), _relative_quat(site_quat, quat), 0)
    world.grips[name] = grip
    world.held[name] = side
    return _compose(site_pos, site_quat, grip.position, grip.quat)


def _measured(grip: Grip | None, side: str, site_pos: FloatArray, site_quat: FloatArray, pose: Pose) -> Grip:
    """The grip with one more measurement (the seen pose in the site's frame) averaged in.

    Orientations are averaged as the normalised sum of sign-aligned quaternions, which is the
    mean rotation to second order for a small spread (Markley et al. 2007, "Averaging quaternions").
    """
    rel_pos = np.empty(3)
    inverse = np.empty(4)
    mujoco.mju_negQuat(inverse, site_quat)
    mujoco.mju_rotVecQuat(rel_pos, np.asarray(pose[0], float) - site_pos, inverse)
    rel_quat = _relative_quat(site_quat, pose[1])
    if grip is None or grip.looks == 0:
        return Grip(side, rel_pos, rel_quat, 1)
    n = grip.looks
    if float(np.dot(rel_quat, grip.quat)) < 0.0:
        rel_quat = -rel_quat
    quat = grip.quat * n + rel_quat
    return Grip(side, (grip.position * n + rel_pos) / (n + 1), quat / np.linalg.norm(quat), n + 1)


def _relative_quat(frame_quat: FloatArray, quat: FloatArray) -> FloatArray:
    """``quat`` expressed in the frame of orientation ``frame_quat``: frame^-1 * quat."""
    inverse, out = np.empty(4), np.empty(4)
    mujoco.mju_negQuat(inverse, np.asarray(frame_quat, float))
    mujoco.mju_mulQuat(out, inverse, np.asarray(quat, float) / np.linalg.norm(quat))
    return out


def _compose(pos: FloatArray, quat: FloatArray, rel_pos: FloatArray, rel_quat: FloatArray) -> Pose:
    """The pose (pos, quat) * (rel_pos, rel_quat)."""
    out_pos, out_quat = np.empty(3), np.empty(4)
    mujoco.mju_rotVecQuat(out_pos, rel_pos, quat)
    mujoco.mju_mulQuat(out_quat, quat, rel_quat)
    return pos + out_pos, out_quat / np.linalg.norm(out_quat)


def refresh(
    world: World, robot: Any, holding: Mapping[str, str], reason: str, *, follow_base: bool = False
) -> dict[str, Any]:
    """Look through ``robot`` and update the estimate ``world``: the fields of the log's line.

    Args:
        world: the estimate world.
        robot: the robot (its measured ``data.qpos`` is in ``world``'s layout).
        holding: the robot's grasp record, side -> object.
        reason: one of :data:`REASONS`.
        follow_base: the robot walked: the estimate's base goes where the robot measures it
            (:func:`follow_base`), and the line says where (``base``).

    Returns:
        ``reason``, ``source``, ``time``, ``objects`` (the records of :func:`update_estimate`)
        and ``holding`` (the grasp record as touch confirms it, side -> object), for
        ``AuditLog.record("observation", ...)``; with ``follow_base``, ``base`` too.
    """
    if reason not in REASONS:
        raise ValueError(f"observation reason {reason!r} is not one of {REASONS}")
    base = follow_base_of(world, robot) if follow_base else None
    seen = look(robot, holding)
    records = update_estimate(world, measured_qpos(world, robot), seen)
    fields: dict[str, Any] = {
        "reason": reason,
        "source": seen.source,
        "time": seen.time,
        "objects": records,
        "holding": dict(seen.holding),
    }
    if base is not None:
        fields["base"] = base
    return fields


def measure_base(world: World, robot: Any) -> Pose:
    """Where ``robot`` measures its base: its ``observe_base()`` (the simulated robot's odometry,
    with the scenario's ``uncertainty.base_position``/``base_yaw``), else its ``data.qpos``.

    Args:
        world: a world of the robot's model (its base's place in ``qpos``).
        robot: the robot.

    Returns:
        The base's position (m) and orientation (w x y z).
    """
    measure = getattr(robot, "observe_base", None)
    if callable(measure):
        pos, quat = measure()
        return np.asarray(pos, dtype=float), np.asarray(quat, dtype=float)
    q = np.array(robot.data.qpos, dtype=float)[world.base_qpos]
    return q[:3], q[3:]


def follow_base_of(world: World, robot: Any) -> dict[str, Any]:
    """Put the estimate's robot base where ``robot`` measures it (:func:`measure_base`): the log's
    record of it (position, yaw)."""
    pos, quat = measure_base(world, robot)
    world.data.qpos[world.base_qpos] = np.concatenate([pos, np.asarray(quat) / np.linalg.norm(quat)])
    world.follows_base = True
    mujoco.mj_kinematics(world.model, world.data)
    return {"position": [float(v) for v in pos], "yaw": yaw_of(np.asarray(quat, dtype=float))}


def measured_qpos(world: World, robot: Any) -> FloatArray:
    """The robot's measured joints, its base where the estimate has it once it follows the base."""
    q = np.array(robot.data.qpos, dtype=float)
    if world.follows_base:
        q[world.base_qpos] = world.data.qpos[world.base_qpos]
    return q
