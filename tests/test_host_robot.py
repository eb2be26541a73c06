"""A host's own robot behind the JointIO protocol (executive/execution/robot_interface.py).

The host's "hardware" here is a separate MuJoCo truth world the host steps itself
through its own servo loop; the executive only reads joint states and base pose
(and the object pose the host perceives) and sends joint targets and gripper
commands. Success is judged from the host's world.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np
import pytest

from behaviours.gripper import object_contacts
from executive.decision.physics_check import with_rollouts
from executive.execution.robot_interface import HostRobot, JointState
from executive.execution.simulated import SimulatedRobot
from executive.runtime.mission import Executive
from executive.scenario import load
from executive.world.model import build


class SimulatedHardware:
    """The host's robot: its own world and servo loop; JointIO on top."""

    def __init__(self, world, control_dt: float) -> None:  # type: ignore[no-untyped-def]
        self.world = world
        self.servo = SimulatedRobot(world, control_dt=control_dt)
        model = world.model
        self.joints = {
            model.joint(j).name: int(model.jnt_qposadr[j])
            for j in range(model.njnt)
            if model.joint(j).name
            and model.jnt_bodyid[j] in world.ids.robot_bodies
            and model.jnt_type[j] != 0
        }

    def read(self) -> JointState:
        d = self.world.data
        qpos = d.qpos
        base = self.world.model.jnt_qposadr[self.world.model.body_jntadr[self.world.ids.base_body]]
        objects = {name: self.world.object_pose(name) for name in self.world.ids.object_bodies}
        return JointState(
            float(d.time),
            {name: float(qpos[adr]) for name, adr in self.joints.items()},
            tuple(qpos[base : base + 3]),  # type: ignore[arg-type]
            tuple(qpos[base + 3 : base + 7]),  # type: ignore[arg-type]
            objects,
        )

    def send_joint_targets(self, targets: Mapping[str, float]) -> None:
        q = self.servo.q_target.copy()
        for name, value in targets.items():
            q[self.joints[name]] = value
        self.servo.set_joint_targets(q)

    def send_gripper(self, side: str, closed: bool) -> None:
        self.servo.set_gripper(side, closed)

    def hand_contacts(self, side: str, obj: str) -> tuple[int, float]:
        return object_contacts(self.servo, side, obj)  # the "hardware's" fingertip sensing


@pytest.mark.slow
def test_executive_drives_a_host_robot_through_joint_io() -> None:
    scenario = with_rollouts(load("book_transfer"), 0)  # the host's joint I/O is the subject, not the risk
    hardware = SimulatedHardware(build(scenario), control_dt=0.02)
    robot = HostRobot(build(scenario), hardware, control_dt=0.02)
    executive = Executive(scenario, approval="auto", robot=robot)
    assert not executive.owns_physics
    deadline = time.monotonic() + 400.0  # wall clock: planning runs in a thread, slower under load
    while not executive.done and time.monotonic() < deadline:
        robot.sync()  # the host: read the robot into the executive's mirror
        executive.tick()
        hardware.servo.advance()  # the host steps its own robot
    summary = executive.summary()
    pos, _ = hardware.world.object_pose("book")
    err = float(np.hypot(pos[0] - 0.52, pos[1] + 0.26))
    print(executive.log.of_kind("failure"), f"book {err * 1000:.1f} mm from the target")
    assert summary["outcome"] == "success"
    assert err < 0.02
