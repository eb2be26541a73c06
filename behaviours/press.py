"""Pressing: push a hand into an obstacle with a commanded force for a while, measuring the contact force.

``Press(name, trajectory, side=, target=, standoff=, force=, hold_s=, tolerance=)`` plays the press
step's planned trajectory (from ``standoff`` off the surface to the servo depth of the force) no
faster than ``seek_speed`` along the push, up to where the plan touches the surface or the hand
does. From there it closes the loop on the contact force between the hand's geoms and the target's
(``mujoco.mj_contactForce``, normal components summed): the arm's servo targets move by
``J^T u / kp`` (:func:`executive.planning.press_geometry.servo_shift`) for a push ``u`` that creeps on
at ``seek_speed`` until the first touch and then integrates the force error, until the force has
stayed within half the tolerance for ``steady_s``; then it must stay within ``tolerance`` for
``hold_s``. At the end the target fades back to the plan's last knot (where the release starts).
It succeeds when every sample of the hold was within the tolerance and leaves its measurement on
the blackboard (``/executive/press_record``); it fails with ``press: ...`` naming what went wrong:
a force the arm's servos cannot give from the press pose (the joint and its torque limit), no
contact, the force too low (with the arm joint at its torque limit, if one is) or too high, or
leaving the tolerance during the hold.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import py_trees

from behaviours.robot_access import RobotBehaviour
from executive.planning.planner import Trajectory
from executive.planning.press_geometry import press_compliance, servo_shift

__all__ = ["Press", "SetGripper"]

Status = py_trees.common.Status
RECORD_KEY = "press_record"  # executive.tasks.press.PRESS_RECORD_KEY


class Press(RobotBehaviour):
    """Press obstacle ``target`` with ``side``'s hand: ``force`` N for ``hold_s`` s within ``tolerance`` N.

    Args:
        name: the behaviour's name (the step's).
        trajectory: the press step's plan, from the standoff to the servo depth of the force.
        side, target: the hand and the obstacle it presses.
        standoff: how far (m) the trajectory starts off the surface: it is played until the hand is
            planned to touch (the rest, the depth of the force, is the force loop's), or touches.
        force: the commanded force (N) along the trajectory's push.
        hold_s: how long the force must stay within ``tolerance``.
        tolerance: N either side of ``force``.
        settle_s: after the touch (or the planned one), how long the force may take to settle.
        gain_p, gain_i: the force loop's proportional gain and integral gain per control period
            (dimensionless: N of servo push per N of force error).
        seek_speed: m/s the target moves at most along the push on the way in, and on past the
            planned touch until the hand touches (the plan's depth can fall short by the planner's
            position tolerance). Slow: a stiff arm on a swaying body turns speed into impact force.
        steady_s: the force must stay within half the tolerance this long before the hold starts.
        ramp_s: at the end, how long the loop's correction takes to fade back to the planned target.
    """

    def __init__(
        self,
        name: str,
        trajectory: Trajectory,
        *,
        side: str,
        target: str,
        standoff: float,
        force: float,
        hold_s: float,
        tolerance: float,
        settle_s: float = 2.0,
        gain_p: float = 0.0,
        gain_i: float = 0.25,
        seek_speed: float = 0.005,
        steady_s: float = 0.3,
        ramp_s: float = 0.1,
    ) -> None:
        super().__init__(name)
        self.bb.register_key(RECORD_KEY, access=py_trees.common.Access.WRITE)
        self.trajectory = trajectory
        self.side, self.target, self.standoff = side, target, standoff
        self._touch_s = trajectory.duration
        self.force, self.hold_s, self.tolerance = force, hold_s, tolerance
        self.settle_s, self.ramp_s, self.steady_s = settle_s, ramp_s, steady_s
        self.gain_p, self.gain_i, self.seek_speed = gain_p, gain_i, seek_speed
        self._integral = 0.0  # the loop's integral state (N)
        self._touched = False
        self._compliance = 1.0  # m/N of the hand along the push, at the press pose
        self._steady = 0  # consecutive periods within the tolerance while settling
        self._robot: Any = None
        self._phase = "in"
        self._since = 0.0  # robot time the phase started
        self._u = 0.0  # N of push added to the planned target's by the force loop
        self._shift = np.zeros(0)  # servo target shift per newton (qpos layout)
        self._q_end = trajectory.qpos[-1]
        self._q_base = self._q_end  # the target the force loop shifts: where the hand first touched
        self.samples: list[tuple[float, float]] = []  # (time, force) of the hold
        self.trace: list[tuple[float, float, str]] = []  # (time, force, phase) of every tick
        self.last_force = 0.0

    def initialise(self) -> None:
        robot = self._robot = self.robot
        self._phase, self._since, self._u, self.samples, self.trace = "in", robot.time, 0.0, [], []
        self._q_base = self._q_end
        self._integral, self._touched = 0.0, False
        self.last_force = 0.0
        robot.detector.set_phase(grasping=(self.side, self.target))  # the planned contact
        model, ids = robot.world.model, robot.world.ids
        bodies = set(ids.hand_bodies[self.side])
        self._hand = np.array([g for g in ids.robot_geoms if int(model.geom_bodyid[g]) in bodies])
        self._panel = int(ids.obstacle_geoms[self.target])
        hand_path = self.trajectory.hand_paths[self.side]
        push = hand_path[-1] - hand_path[0]
        self._into = push / max(float(np.linalg.norm(push)), 1e-9)
        # The plan's time of touch: its hand path ``standoff`` along the push (np.interp: a monotone path).
        along = np.maximum.accumulate((hand_path - hand_path[0]) @ self._into)
        times = self.trajectory.times
        self._touch_s = float(np.interp(self.standoff, along, times))
        self._speed = np.diff(along) / np.maximum(np.diff(times), 1e-9)
        self._speed_t = times[:-1]
        self._tau = 0.0  # how far into the trajectory the target is
        self.feedback_message = f"{self.name}: in to the {self.target}"

    def contact_force(self) -> float:
        """Total normal force (N) of the contacts between the pressing hand and the target now."""
        robot = self._robot
        data = robot.data
        if not data.ncon:
            return 0.0
        pairs = data.contact.geom
        hits = (np.isin(pairs[:, 0], self._hand) & (pairs[:, 1] == self._panel)) | (
            np.isin(pairs[:, 1], self._hand) & (pairs[:, 0] == self._panel)
        )
        wrench = np.zeros(6)
        total = 0.0
        for i in np.flatnonzero(hits):
            mujoco.mj_contactForce(robot.world.model, data, int(i), wrench)
            total += abs(float(wrench[0]))
        return total

    def update(self) -> Status:
        robot = self._robot
        if self.failed_by_detector(robot):
            return Status.FAILURE
        f = self.last_force = self.contact_force()
        self.trace.append((robot.time, f, self._phase))
        t = robot.time - self._since
        if self._phase == "in":
            return self._move_in(t)
        if self._phase == "out":
            return self._fade_out(t)
        self._control(f)
        robot.set_joint_targets(self._q_base + self._u * self._shift)
        if self._phase == "settle":
            return self._settle(t, f)
        return self._hold(t, f)

    def _control(self, f: float) -> None:
        """The servo push ``_u`` (N): on at ``seek_speed`` until the first touch, then PI on the force
        (``gain_p`` 0 by default: the integral alone; a proportional share excites the body's sway)."""
        if not self._touched and f <= 0.0:
            self._integral += self.seek_speed * self._robot.control_dt / self._compliance
            self._u = self._integral
            return
        self._touched = True
        error = self.force - f
        limit = 5.0 * self.force
        self._integral = float(np.clip(self._integral + self.gain_i * error, -limit, limit))
        self._u = self._integral + self.gain_p * error

    def _move_in(self, t: float) -> Status:
        """Play the plan in, no faster than ``seek_speed`` along the push, to its planned touch; at the
        first touch (or there) the force loop takes over from where the target is."""
        robot, traj = self._robot, self.trajectory
        dt = robot.control_dt
        tau = self._tau
        q = traj.sample(tau)
        if tau < self._touch_s and self.last_force <= 0.0:
            speed = float(np.interp(tau, self._speed_t, self._speed))  # the plan's, along the push
            step = dt * min(1.0, self.seek_speed / speed) if speed > 0 else dt
            self._tau = min(tau + step, self._touch_s)
            robot.set_joint_targets(q, (traj.sample(self._tau) - q) / dt)
            return Status.RUNNING
        self._q_base = q
        robot.set_joint_targets(self._q_base)
        data, model = robot.data, robot.world.model
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        self._shift = servo_shift(robot.world, data, self.side, self._into)
        self._compliance = press_compliance(robot.world, self.side, data.qpos, self._into)
        problem = self._torque_limit(data)
        if problem:
            return self.fail("task", f"press: force {self.force:g} N {problem}")
        self._phase, self._since, self._steady = "settle", robot.time, 0
        return Status.RUNNING

    def _torque_limit(self, data: mujoco.MjData) -> str:
        """Why the arm cannot push ``force`` from here ("" if it can): the joint whose servo torque,
        gravity plus ``J^T F``, is beyond its actuator's force range."""
        model = self._robot.world.model
        jac = np.zeros((3, model.nv))
        mujoco.mj_jacSite(model, data, jac, None, self._robot.world.ids.hand_sites[self.side])
        need = data.qfrc_bias + jac.T @ (self.force * self._into)
        joints = set(self._robot.world.ids.arm_joints[self.side])
        for a in range(model.nu):
            joint = int(model.actuator_trnid[a, 0])
            if joint not in joints or not model.actuator_forcelimited[a]:
                continue
            tau = float(need[int(model.jnt_dofadr[joint])])
            low, high = model.actuator_forcerange[a]
            if not low <= tau <= high:
                name = model.joint(joint).name
                return f"needs {abs(tau):.1f} Nm at {name}, beyond its servo's {max(-low, high):.0f} Nm"
        return ""

    def _settle(self, t: float, f: float) -> Status:
        self._steady = self._steady + 1 if abs(f - self.force) <= 0.5 * self.tolerance else 0
        if self._steady * self._robot.control_dt >= self.steady_s:
            self._phase, self._since = "hold", self._robot.time
            self.samples = [(self._robot.time, f)]
            self.feedback_message = f"{self.name}: holding {f:.1f} N"
            return Status.RUNNING
        if t < self.settle_s:
            return Status.RUNNING
        return self.fail("task", self._not_reached(f))

    def _not_reached(self, f: float) -> str:
        band = f"{self.force:g} +- {self.tolerance:.2g} N"
        if f < 1e-6:
            return (
                f"press: no contact between the {self.side} hand and {self.target} "
                f"{self.settle_s:g} s after the push (force 0 N, commanded {band})"
            )
        if abs(f - self.force) <= self.tolerance:  # in the band now, but it kept swinging out
            return (
                f"press: the force on {self.target} did not settle: never {self.steady_s:g} s within "
                f"+- {0.5 * self.tolerance:.2g} N of {self.force:g} N in {self.settle_s:g} s (last {f:.1f} N)"
            )
        low = "low" if f < self.force else "high"
        saturated = self._saturated()
        why = f"; {saturated} at its torque limit" if saturated and low == "low" else ""
        return (
            f"press: force too {low}: {f:.1f} N on {self.target}, commanded {band}, "
            f"after {self.settle_s:g} s{why}"
        )

    def _saturated(self) -> str:
        """The first arm joint whose actuator is at its force limit ("" if none)."""
        robot = self._robot
        model, data = robot.world.model, robot.data
        joints = set(robot.world.ids.arm_joints[self.side])
        for a in range(model.nu):
            joint = int(model.actuator_trnid[a, 0])
            if joint in joints and model.actuator_forcelimited[a]:
                low, high = model.actuator_forcerange[a]
                if not low * 0.999 < data.actuator_force[a] < high * 0.999:
                    return str(model.joint(joint).name)
        return ""

    def _hold(self, t: float, f: float) -> Status:
        self.samples.append((self._robot.time, f))
        if abs(f - self.force) > self.tolerance:
            low = "dropped" if f < self.force else "rose"
            return self.fail(
                "task",
                f"press: force {low} to {f:.1f} N on {self.target} {t:.2f} s into the {self.hold_s:g} s hold "
                f"(commanded {self.force:g} +- {self.tolerance:.2g} N)",
            )
        if t < self.hold_s:
            self.feedback_message = f"{self.name}: {f:.1f} N, {t:.2f}/{self.hold_s:g} s"
            return Status.RUNNING
        self._write_record()
        self._phase, self._since = "out", self._robot.time
        return Status.RUNNING

    def _fade_out(self, t: float) -> Status:
        fade = max(0.0, 1.0 - t / self.ramp_s) if self.ramp_s > 0 else 0.0
        held = self._q_base + self._u * self._shift
        self._robot.set_joint_targets(self._q_end + fade * (held - self._q_end))  # to the release's start
        if fade > 0.0:
            return Status.RUNNING
        mean, held = self.record()["mean_n"], self.record()["held_s"]
        self.feedback_message = (
            f"{self.name}: held {mean:.2f} N (commanded {self.force:g} N) for {held:.2f} s"
        )
        return Status.SUCCESS

    def record(self) -> dict[str, Any]:
        """The hold's measurement: commanded and measured force (mean, min, max, std; N) and times (s)."""
        times = np.array([s[0] for s in self.samples])
        forces = np.array([s[1] for s in self.samples])
        return {
            "target": self.target,
            "side": self.side,
            "commanded_n": self.force,
            "tolerance_n": self.tolerance,
            "mean_n": float(forces.mean()),
            "min_n": float(forces.min()),
            "max_n": float(forces.max()),
            "std_n": float(forces.std()),
            "held_s": float(times[-1] - times[0]),
            "start_s": float(times[0]),
            "samples": len(forces),
        }

    def _write_record(self) -> None:
        self.bb.set(RECORD_KEY, self.record())

    def terminate(self, new_status: Status) -> None:
        if new_status in (Status.FAILURE, Status.INVALID) and self._robot is not None:
            self._robot.hold()  # safe hold where the robot is


class SetGripper(RobotBehaviour):
    """Close (a fist to press with) or open one hand's gripper and succeed at once.

    The fingers move while the next motion runs: a press closes the hand on its way to the
    point and opens it on its way home.
    """

    def __init__(self, name: str, side: str, *, closed: bool) -> None:
        super().__init__(name)
        self.side, self.closed = side, closed

    def update(self) -> Status:
        self.robot.set_gripper(self.side, closed=self.closed)
        self.feedback_message = f"{self.side} hand {'closed' if self.closed else 'opened'}"
        return Status.SUCCESS
