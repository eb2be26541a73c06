"""How the executive talks to a robot it does not simulate itself.

Behaviours use a robot through a small surface (:class:`RobotInterface`): the
time, a MuJoCo ``world``/``data`` holding the robot's *current* state (for hand
positions, contacts and the detectors), joint targets, the gripper, a safe hold.
:class:`executive.execution.simulated.SimulatedRobot` is that surface over the bundled
physics. For a host's own robot, :class:`HostRobot` builds it from an even
smaller protocol the host implements, :class:`JointIO`: read the joint state and
base pose (and, if the robot perceives them, object poses), send joint targets
and gripper commands, and report touch (hand links on an object, normal force)
so a grasp can be verified. ``HostRobot.sync()`` copies the measured state into a
MuJoCo mirror of the scenario (``mj_forward``: kinematics, contacts, forces) and
runs the failure detectors on it; the host calls it once per control period,
before :meth:`executive.runtime.mission.Executive.tick`.

The objects a host reports in ``JointState.objects`` are what the robot sees
(:class:`ObservingRobot`, ``HostRobot.observe_objects``): the executive updates its
estimate from them at start-up, after every task, after every failure and before every
re-plan (:mod:`executive.world.observation`), each time with an ``observation`` line in the
audit log. Report the objects the robot sees now, in the world frame; leave out one it does
not see (its estimate stays). An object in a hand (the grasp behaviour's record, confirmed
by ``hand_contacts``) moves with that hand in the estimate.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.monitoring.detectors import Failure, FailureDetector
from executive.world import touch
from executive.world.model import World

__all__ = [
    "HostRobot",
    "JointIO",
    "JointState",
    "ObservingRobot",
    "RobotInterface",
    "SimulatedJointIO",
    "base_address",
    "joint_addresses",
    "joint_state",
]

FloatArray = NDArray[np.float64]


class RobotInterface(Protocol):
    """What behaviours and the executive use of a robot (SimulatedRobot and HostRobot have it)."""

    world: World
    data: mujoco.MjData
    control_dt: float
    detector: FailureDetector

    @property
    def time(self) -> float: ...

    @property
    def failure(self) -> Failure | None: ...

    def set_joint_targets(self, q_target: FloatArray, qvel_target: FloatArray | None = None) -> None: ...

    def set_gripper(self, side: str, closed: bool) -> None: ...

    def hold(self) -> None: ...


class ObservingRobot(RobotInterface, Protocol):
    """A robot that sees the objects (SimulatedRobot and HostRobot have it).

    The executive updates its estimate (:mod:`executive.world.observation`) after every task,
    after every failure and before every re-plan: it calls ``observe_objects()`` once and logs
    ``observation_source`` with the result. A robot without these methods sees nothing: its
    estimate keeps the objects where they were, except those in a hand, which move with it.
    """

    def observe_objects(self) -> dict[str, tuple[FloatArray, FloatArray]]:
        """Object name -> (position (m), quaternion w x y z) in the world frame, as seen now."""
        ...

    @property
    def observation_source(self) -> dict[str, object]:
        """A JSON-able description of the poses' origin, e.g. ``{"source": "host"}``."""
        ...


@dataclass(frozen=True)
class JointState:
    """One reading of the robot: time (s), joint positions by joint name, base pose, objects seen."""

    time: float
    joints: Mapping[str, float]
    base_position: tuple[float, float, float]
    base_quat: tuple[float, float, float, float]  # w x y z
    objects: Mapping[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)  # name -> pos, quat


def joint_addresses(world: World) -> dict[str, int]:
    """The robot's named joints (its base's free joint left out): name -> their ``qpos`` address."""
    model = world.model
    return {
        model.joint(j).name: int(model.jnt_qposadr[j])
        for j in range(model.njnt)
        if model.joint(j).name
        and model.jnt_bodyid[j] in world.ids.robot_bodies
        and model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE
    }


def base_address(world: World) -> int:
    """The ``qpos`` address of the robot base's free joint (position, then w x y z quaternion).

    Raises:
        ExecutiveError: the robot's base body has no free joint (it cannot be mirrored).
    """
    model = world.model
    base_joint = next((j for j in range(model.njnt) if model.jnt_bodyid[j] == world.ids.base_body), None)
    if base_joint is None or model.jnt_type[base_joint] != mujoco.mjtJoint.mjJNT_FREE:
        raise ExecutiveError("HostRobot needs a robot whose base body has a free joint")
    return int(model.jnt_qposadr[base_joint])


def joint_state(
    world: World,
    time: float | None = None,
    objects: Mapping[str, tuple[FloatArray, FloatArray]] | None = None,
) -> JointState:
    """What a robot in ``world``'s state would report: its joints and base pose.

    Args:
        time: the reading's time (None: the world's simulated time).
        objects: the objects it sees (None: none).
    """
    qpos, base = world.data.qpos, base_address(world)
    return JointState(
        float(world.data.time) if time is None else time,
        {name: float(qpos[adr]) for name, adr in joint_addresses(world).items()},
        (float(qpos[base]), float(qpos[base + 1]), float(qpos[base + 2])),
        (float(qpos[base + 3]), float(qpos[base + 4]), float(qpos[base + 5]), float(qpos[base + 6])),
        dict(objects or {}),
    )


class SimulatedJointIO:
    """A :class:`JointIO` over a simulated robot the host steps itself (``servo.advance()`` once a
    control period): a stand-in for the host's hardware when testing or timing a host's loop.

    Args:
        world: the robot's world (a world of the scenario, its own instance).
        control_dt: the servo's control period (s).
    """

    def __init__(self, world: World, control_dt: float) -> None:
        from executive.execution.simulated import SimulatedRobot

        self.world = world
        self.servo = SimulatedRobot(world, control_dt=control_dt)
        self.joints = joint_addresses(world)

    def read(self) -> JointState:
        objects = {name: self.world.object_pose(name) for name in self.world.ids.object_bodies}
        return joint_state(self.world, objects=objects)

    def send_joint_targets(self, targets: Mapping[str, float]) -> None:
        q = self.servo.q_target.copy()
        for name, value in targets.items():
            q[self.joints[name]] = value
        self.servo.set_joint_targets(q)

    def send_gripper(self, side: str, closed: bool) -> None:
        self.servo.set_gripper(side, closed)

    def hand_contacts(self, side: str, obj: str) -> tuple[int, float]:
        return touch.hand_contacts(self.world, side, obj)  # the simulated fingertips' sensing


class JointIO(Protocol):
    """The host's side: read the robot, send it targets."""

    def read(self) -> JointState: ...

    def send_joint_targets(self, targets: Mapping[str, float]) -> None: ...

    def send_gripper(self, side: str, closed: bool) -> None: ...

    def hand_contacts(self, side: str, obj: str) -> tuple[int, float]:
        """Touch sensing: how many hand links touch ``obj`` and the total normal force (N)."""
        ...


class HostRobot:
    """A :class:`RobotInterface` over a host's :class:`JointIO`, mirrored into ``world``.

    ``world`` is a world of the same scenario (its own instance, not the estimate the
    planner uses); its data becomes the measured state on every :meth:`sync`.
    """

    def __init__(self, world: World, io: JointIO, control_dt: float = 0.01) -> None:
        self.world, self.io, self.control_dt = world, io, control_dt
        self.model, self.data = world.model, world.data
        self.detector = FailureDetector(world)
        self._joints = joint_addresses(world)
        self._base = base_address(world)
        self._time = 0.0
        self._seen: dict[str, tuple[FloatArray, FloatArray]] = {}
        self.q_target: FloatArray = self.data.qpos.copy()
        self.sync()
        self.q_target = self.data.qpos.copy()

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self._joints)

    @property
    def time(self) -> float:
        return self._time

    @property
    def failure(self) -> Failure | None:
        return self.detector.failure

    def sync(self) -> Failure | None:
        """Read the robot into the mirror, compute its kinematics and contacts, run the detectors."""
        state = self.io.read()
        qpos = self.data.qpos
        missing = [name for name in self._joints if name not in state.joints]
        if missing:
            raise ExecutiveError(f"the host's joint state lacks {len(missing)} joints, e.g. {missing[:3]}")
        for name, adr in self._joints.items():
            qpos[adr] = state.joints[name]
        qpos[self._base : self._base + 3] = state.base_position
        qpos[self._base + 3 : self._base + 7] = state.base_quat
        self._check_objects(state.objects)
        for name, (pos, quat) in state.objects.items():
            adr = self.world.ids.object_qpos[name]
            qpos[adr : adr + 3], qpos[adr + 3 : adr + 7] = pos, quat
        self._seen = {k: (np.asarray(p, float), np.asarray(q, float)) for k, (p, q) in state.objects.items()}
        self._time = float(state.time)
        self.data.time = self._time
        mujoco.mj_forward(self.model, self.data)
        return self.detector.check()

    def _check_objects(self, objects: Mapping[str, object]) -> None:
        """Every object the host reports must be one of the scenario's."""
        known = self.world.ids.object_qpos
        unknown = sorted(set(objects) - set(known))
        if unknown:
            raise ExecutiveError(
                f"the host's JointState.objects names {unknown}, which scenario "
                f"'{self.world.scenario.name}' does not have (its objects: {sorted(known)})"
            )

    def observe_objects(self) -> dict[str, tuple[FloatArray, FloatArray]]:
        """The object poses of the last :meth:`sync` (``JointState.objects``): name -> (position, quat).

        An object the host did not report is absent (the estimate keeps its own pose of it).
        """
        return dict(self._seen)

    @property
    def observation_source(self) -> dict[str, object]:
        """Where :meth:`observe_objects` comes from, for the log."""
        return {"source": "host"}

    def set_joint_targets(self, q_target: FloatArray, qvel_target: FloatArray | None = None) -> None:
        self.q_target = np.asarray(q_target, dtype=float)
        self.io.send_joint_targets({name: float(self.q_target[adr]) for name, adr in self._joints.items()})

    def set_gripper(self, side: str, closed: bool) -> None:
        self.io.send_gripper(side, closed)

    def hand_contacts(self, side: str, obj: str) -> tuple[int, float]:
        """The robot's own touch sensing (a kinematic mirror has no trustworthy contact forces)."""
        return self.io.hand_contacts(side, obj)

    def hold(self) -> None:
        self.set_joint_targets(self.data.qpos.copy())
