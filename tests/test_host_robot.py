"""A host's own robot behind the JointIO protocol (executive/execution/robot_interface.py).

The host's "hardware" here is a separate MuJoCo truth world the host steps itself
through its own servo loop; the executive only reads joint states and base pose
(and the object pose the host perceives) and sends joint targets and gripper
commands. Success is judged from the host's world.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from executive.decision.physics_check import with_rollouts
from executive.execution.robot_interface import HostRobot, SimulatedJointIO
from executive.runtime.mission import Executive
from executive.scenario import load
from executive.world.model import build


@pytest.mark.slow
def test_executive_drives_a_host_robot_through_joint_io() -> None:
    scenario = with_rollouts(load("book_transfer"), 0)  # the host's joint I/O is the subject, not the risk
    hardware = SimulatedJointIO(build(scenario), control_dt=0.02)
    robot = HostRobot(build(scenario), hardware, control_dt=0.02)
    executive = Executive(scenario, approval="auto", robot=robot)
    assert not executive.owns_physics
    deadline = time.monotonic() + 400.0  # a hang guard only: planning runs in the worker process
    while not executive.done and time.monotonic() < deadline:
        robot.sync()  # the host: read the robot into the executive's mirror
        executive.tick()
        hardware.servo.advance()  # the host steps its own robot
        task = executive.current_task
        if task is not None and task.phase in ("planning", "awaiting_approval"):
            # While it only holds, the host's loop keeps the wall clock's pace, as a real robot's
            # does: a loop racing ahead would take the planner's core for a robot that stands.
            time.sleep(0.02)
    summary = executive.summary()
    pos, _ = hardware.world.object_pose("book")
    err = float(np.hypot(pos[0] - 0.52, pos[1] + 0.26))
    print(executive.log.of_kind("failure"), f"book {err * 1000:.1f} mm from the target")
    assert summary["outcome"] == "success"
    assert err < 0.02
