"""Executing joint targets in the truth world: position servos, gravity feed-forward, detectors.

The behaviours never step physics. Each tick they set targets on a
:class:`SimulatedRobot`; the host then calls :meth:`SimulatedRobot.advance`,
which steps MuJoCo for one control period at the model's timestep and runs the
failure detectors after every physics step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.detectors import Failure, FailureDetector
from executive.world import World

__all__ = ["JointTargetController", "SimulatedRobot"]

FloatArray = NDArray[np.float64]


class JointTargetController:
    """Maps a full-model qpos target to the robot's position-servo ctrl.

    MuJoCo's position actuator applies ``kp (ctrl - q) - kv qdot``; to hold a
    joint at ``q*`` against a bias torque ``tau`` the servo needs
    ``ctrl = q* + tau / kp`` (gravity feed-forward). It is applied to the arm
    and waist joints only: for a floating-base robot ``qfrc_bias`` of a leg
    joint is the torque of the subtree *below* it (the foot), not of the body
    the stance leg carries, so the legs rely on their stiff gains alone.
    Gripper actuators are left to :meth:`SimulatedRobot.set_gripper`.
    """

    def __init__(self, world: World) -> None:
        model = world.model
        grippers = {a for ids in world.ids.gripper_actuators.values() for a in ids}
        arm_and_waist = {j for ids in world.ids.arm_joints.values() for j in ids}
        for name in world.profile.waist_joints:
            arm_and_waist.add(int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)))
        acts, qadr, dadr, kp, ff = [], [], [], [], []
        for a in range(model.nu):
            if a in grippers or model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
                continue
            joint = int(model.actuator_trnid[a, 0])
            acts.append(a)
            qadr.append(int(model.jnt_qposadr[joint]))
            dadr.append(int(model.jnt_dofadr[joint]))
            kp.append(float(model.actuator_gainprm[a, 0]))
            ff.append(joint in arm_and_waist)
        self.actuators = np.array(acts, dtype=int)
        self.qpos_adr = np.array(qadr, dtype=int)
        self.dof_adr = np.array(dadr, dtype=int)
        self.kp = np.array(kp)
        self.feed_forward = np.array(ff, dtype=bool)
        self.ctrl_low = model.actuator_ctrlrange[self.actuators, 0]
        self.ctrl_high = model.actuator_ctrlrange[self.actuators, 1]

    def joint_ctrl(self, q_target: FloatArray, data: mujoco.MjData) -> FloatArray:
        """Servo targets for the non-gripper actuators, in the order of ``self.actuators``."""
        ctrl = q_target[self.qpos_adr].copy()
        bias = data.qfrc_bias[self.dof_adr]
        ctrl[self.feed_forward] += bias[self.feed_forward] / self.kp[self.feed_forward]
        return np.clip(ctrl, self.ctrl_low, self.ctrl_high)


@dataclass
class StepStats:
    physics_steps: int = 0
    physics_wall_s: float = 0.0


class SimulatedRobot:
    """The truth world driven through its actuators, watched by a :class:`FailureDetector`."""

    def __init__(
        self,
        world: World,
        control_dt: float = 0.02,
        detector: FailureDetector | None = None,
    ) -> None:
        self.world = world
        self.model = world.model
        self.data = world.data
        self.control_dt = control_dt
        self.substeps = max(1, round(control_dt / self.model.opt.timestep))
        self.detector = detector if detector is not None else FailureDetector(world)
        self.controller = JointTargetController(world)
        self.q_target: FloatArray = self.data.qpos.copy()
        self.gripper_ctrl: dict[str, FloatArray] = {}
        for side, arm in world.profile.arms.items():
            ids = world.ids.gripper_actuators[side]
            self.gripper_ctrl[side] = self.data.ctrl[list(ids)].copy()
            del arm
        self.stats = StepStats()

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def failure(self) -> Failure | None:
        return self.detector.failure

    def set_joint_targets(self, q_target: FloatArray) -> None:
        """Targets for every robot joint, given as a full-model qpos (object entries ignored)."""
        self.q_target = np.asarray(q_target, dtype=float)

    def set_gripper(self, side: str, closed: bool) -> None:
        grip = self.world.profile.arms[side].gripper
        self.gripper_ctrl[side] = np.array(grip.closed if closed else grip.open, dtype=float)

    def gripper_opening(self, side: str) -> float:
        """Mean absolute position of the gripper's actuated joints (0 = closed for the humanoid)."""
        joints = self.model.actuator_trnid[list(self.world.ids.gripper_actuators[side]), 0]
        return float(np.mean(np.abs(self.data.qpos[self.model.jnt_qposadr[joints]])))

    def hold(self) -> None:
        """Safe hold: servo every joint to where it is now."""
        self.q_target = self.data.qpos.copy()

    def advance(self) -> Failure | None:
        """Step physics for one control period; stop early at the first detected failure."""
        ctrl = self.data.ctrl
        start = time.perf_counter()
        for _ in range(self.substeps):
            ctrl[self.controller.actuators] = self.controller.joint_ctrl(self.q_target, self.data)
            for side, values in self.gripper_ctrl.items():
                ctrl[list(self.world.ids.gripper_actuators[side])] = values
            mujoco.mj_step(self.model, self.data)
            self.stats.physics_steps += 1
            failure = self.detector.check()
            if failure is not None:
                self.hold()
                break
        self.stats.physics_wall_s += time.perf_counter() - start
        return self.detector.failure
