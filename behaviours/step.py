"""Taking one planned quasi-static step: its phases streamed to the servos, liftoff and landing checked.

A step's plan (:class:`executive.planning.stepping.StepPlan`) is five phases, each a joint
trajectory with the feet on the floor during it (``support``). :class:`Step` follows them one
after the other, feeding the leg servos the static load of each target on the phase's support
feet (:meth:`executive.execution.simulated.JointTargetController.leg_loads` with ``stance``: the
stance leg carries the whole body while the other swings), with the robot's ankle balance
feedback on those feet while the step runs
(:meth:`executive.execution.simulated.SimulatedRobot.set_balance`: the measured capture point held
on the plan's, which robots with soft leg servos need to stand on one foot), and checks what the
feet really do:

* after ``lift``: the swing foot's measured contact force with the floor has left it (liftoff);
* after ``touchdown``: the swing foot touches the floor again, where the plan put it.

Verdicts (the failure-mode table, :mod:`executive.schema.failure_modes`): a fall is the physics
detector's (``fall``, from :meth:`RobotBehaviour.failed_by_detector`); a foot that does not lift,
does not come down, or lands farther from its planned foothold than the tolerances fails with
``tracking`` (the robot did not follow its plan; it still stands).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
import py_trees

from behaviours.robot_access import RobotBehaviour
from executive.planning.limits import SupportPolygon
from executive.planning.stepping import Foothold, StepPhase, StepPlan
from executive.planning.stepping_geometry import yaw_of

__all__ = ["Step", "foot_force", "foothold", "sole_gap"]

Status = py_trees.common.Status


def foot_force(robot: Any, side: str) -> tuple[float, bool]:
    """The total normal force (N) between the floor and the soles of the ``side`` foot in the
    robot's current state, and whether they touch at all (a contact with no force yet counts)."""
    world, data = robot.world, robot.data
    soles, floor = set(world.ids.foot_geoms[side]), world.ids.floor_geom
    total, touching = 0.0, False
    wrench = np.zeros(6)
    for i in range(data.ncon):
        contact = data.contact[i]
        pair = (int(contact.geom1), int(contact.geom2))
        if floor in pair and soles & set(pair):
            mujoco.mj_contactForce(world.model, data, i, wrench)
            total += float(wrench[0])
            touching = True
    return total, touching


def sole_gap(robot: Any, side: str) -> float:
    """How far (m) the soles of the ``side`` foot are above the floor (negative: pressed into it)."""
    world, data = robot.world, robot.data
    floor = world.ids.floor_geom
    return min(
        float(mujoco.mj_geomDistance(world.model, data, g, floor, 0.5, None))
        for g in world.ids.foot_geoms[side]
    )


def foothold(robot: Any, side: str) -> Foothold:
    """Where the ``side`` foot stands now (its body's x, y and yaw)."""
    world, data = robot.world, robot.data
    body = world.model.body(world.profile.feet[side].body).id
    return Foothold(side, float(data.xpos[body][0]), float(data.xpos[body][1]), yaw_of(data.xquat[body]))


def _com_at(phase: StepPhase, times: np.ndarray) -> np.ndarray:
    """The phase's planned CoM (world xyz) at each of ``times`` (clamped to the phase)."""
    trajectory = phase.trajectory
    t = np.clip(times, 0.0, trajectory.duration)
    return np.stack([np.interp(t, trajectory.times, trajectory.com_path[:, k]) for k in range(3)], axis=1)


class Step(RobotBehaviour):
    """Follow a step's phases in physics, one control period per tick (never blocks).

    Each tick sets the phase's target and, on a robot that has it (``set_balance``), the ankle
    balance feedback on the phase's support feet with the phase's planned CoM; the step's end
    switches the feedback off.

    Succeeds when the last phase has played and the swing foot carries its share of the body.
    Fails at once when a physics detector flags a failure (a fall); with ``tracking`` when the
    swing foot still carries more than ``liftoff_force`` (N) after the lift, is more than
    ``touchdown_gap`` above the floor after the touchdown, first touches the floor more than
    ``landing_tolerance`` (m) or ``landing_yaw_tolerance`` (rad) from its planned foothold, or
    carries less than ``load_share`` of the robot's weight after the weight shift back. A phase
    that ends with its check not yet met holds its last target for up to ``settle_s`` first.

    Measured (read them after the step): ``landing`` (where the swing foot touched down),
    ``landing_error`` ((m, rad) from the planned foothold), ``liftoff_residual`` (N left on the
    swing foot after the lift), ``min_com_margin`` (m: the least distance of the truth CoM inside
    the stance sole during lift, swing and touchdown; negative outside).

    Args:
        name: the behaviour's name.
        plan: the planned step.
        landing_tolerance: m the swing foot may land from its planned foothold.
        landing_yaw_tolerance: rad it may be turned from it.
        liftoff_force: N the swing foot may still carry after the lift.
        touchdown_gap: m the swing foot's soles may still be above the floor when the touchdown
            ends (the weight shift back sets them down).
        load_share: the share of the robot's weight the swing foot carries after the weight
            shift back (its touchdown confirmed by its load).
        settle_s: s a phase's end waits for its check.
    """

    chunk: int = 25  # control periods sampled ahead (0.5 s at 50 Hz), as MoveHand

    def __init__(
        self,
        name: str,
        plan: StepPlan,
        landing_tolerance: float = 0.03,
        landing_yaw_tolerance: float = math.radians(5.0),
        liftoff_force: float = 5.0,
        touchdown_gap: float = 0.005,
        load_share: float = 0.25,
        settle_s: float = 0.6,
    ) -> None:
        super().__init__(name)
        self.plan = plan
        self.landing_tolerance = landing_tolerance
        self.landing_yaw_tolerance = landing_yaw_tolerance
        self.liftoff_force = liftoff_force
        self.touchdown_gap = touchdown_gap
        self.load_share = load_share
        self.settle_s = settle_s
        self.landing: Foothold | None = None
        self.landing_error = (math.inf, math.inf)
        self.liftoff_residual = math.inf
        self.min_com_margin = math.inf
        self._robot: Any = None
        self._index = 0
        self._t0 = 0.0
        self._ahead_t = np.zeros(0)
        self._ahead_q = np.zeros((0, 0))
        self._ahead_load: np.ndarray | None = None
        self._ahead_com = np.zeros((0, 3))
        self._ahead_i = 0
        self._balance: Any = None

    @property
    def phase(self) -> StepPhase:
        """The phase being followed."""
        return self.plan.phases[min(self._index, len(self.plan.phases) - 1)]

    def initialise(self) -> None:
        self._robot = self.robot
        self._balance = getattr(self._robot, "set_balance", None)
        self._index, self._t0 = 0, self._robot.time
        self._ahead_t, self._ahead_i = np.zeros(0), 0
        self.landing, self.landing_error = None, (math.inf, math.inf)
        self.liftoff_residual, self.min_com_margin = math.inf, math.inf
        holding: dict[str, str] = self.bb.holding
        carried = next(iter(holding.items()), None) if holding else None
        self._robot.detector.set_phase(carried=carried)
        self.feedback_message = f"{self.name}: {self.plan.swing} foot to {self.plan.target.describe()}"

    def update(self) -> Status:
        robot = self._robot
        if self.failed_by_detector(robot):
            return Status.FAILURE
        phase = self.phase
        t = robot.time - self._t0
        self._track(phase, t, robot.control_dt)
        if len(phase.support) == 1:
            self._watch_com(phase.support[0])
        if phase.name in ("touchdown", "shift_back"):
            off = self._watch_landing()
            if off:
                return self.fail("tracking", off)
        if t < phase.trajectory.duration:
            self.feedback_message = f"{self.name} {phase.name}: {t:.2f}/{phase.trajectory.duration:.2f} s"
            return Status.RUNNING
        waited = t - phase.trajectory.duration
        verdict = self._phase_check(phase.name, waited >= self.settle_s)
        if verdict is None:  # not yet: hold the phase's end a little longer
            return Status.RUNNING
        if verdict:
            return self.fail("tracking", verdict)
        self._index += 1
        if self._index >= len(self.plan.phases):
            distance, turn = self.landing_error
            self.feedback_message = (
                f"{self.name}: stepped (landed {distance * 1000:.0f} mm, {math.degrees(turn):.1f} deg "
                "from the planned foothold)"
            )
            return Status.SUCCESS
        self._t0, self._ahead_t, self._ahead_i = robot.time, np.zeros(0), 0
        return Status.RUNNING

    def _phase_check(self, name: str, last_chance: bool) -> str | None:
        """At a phase's end: "" when its check passes, None to wait longer, else why it fails."""
        swing = self.plan.swing
        if name == "lift":
            self.liftoff_residual, _ = foot_force(self._robot, swing)
            if self.liftoff_residual <= self.liftoff_force:
                return ""
            what = (
                f"still carries {self.liftoff_residual:.0f} N after the lift "
                f"(liftoff at {self.liftoff_force:.0f} N)"
            )
        elif name == "touchdown":
            # The servos may leave the sole a hair above the floor: the weight shift back sets it down.
            if self.landing is not None or sole_gap(self._robot, swing) <= self.touchdown_gap:
                return ""
            gap = sole_gap(self._robot, swing)
            what = f"is still {gap * 1000:.0f} mm above the floor after the touchdown"
        elif name == "shift_back":
            force, _ = foot_force(self._robot, swing)
            weight = self._robot.world.robot_mass * float(np.linalg.norm(self._robot.model.opt.gravity))
            if self.landing is not None and force >= self.load_share * weight:
                return ""
            what = (
                f"carries {force:.0f} N after the weight shift back (needs {self.load_share * weight:.0f} N)"
            )
        else:
            return ""
        return f"{self.name}: the {swing} foot {what}" if last_chance else None

    def _watch_landing(self) -> str:
        """Record where the swing foot first touches down; why it fails when off its foothold."""
        swing, target = self.plan.swing, self.plan.target
        if self.landing is not None or not foot_force(self._robot, swing)[1]:
            return ""
        self.landing = foothold(self._robot, swing)
        distance, turn = self.landing_error = self.landing.distance(target)
        if distance <= self.landing_tolerance and turn <= self.landing_yaw_tolerance:
            return ""
        return (
            f"{self.name}: the {swing} foot landed at {self.landing.describe()}, {distance * 1000:.0f} mm "
            f"and {math.degrees(turn):.1f} deg from its planned foothold {target.describe()} (tolerance "
            f"{self.landing_tolerance * 1000:.0f} mm, {math.degrees(self.landing_yaw_tolerance):.0f} deg)"
        )

    def _track(self, phase: StepPhase, t: float, dt: float) -> None:
        """Set the target of trajectory time ``t`` and its rate, the legs' load on the support feet."""
        i = self._ahead_i
        if i >= len(self._ahead_t) or abs(self._ahead_t[i] - t) > 1e-9:
            times = t + dt * np.arange(self.chunk + 1, dtype=np.float64)
            self._ahead_t = times[:-1]
            self._ahead_q = phase.trajectory.sample_many(times)
            self._ahead_com = _com_at(phase, times)
            leg_loads = getattr(getattr(self._robot, "controller", None), "leg_loads", None)
            support = [phase.support] * self.chunk
            self._ahead_load = leg_loads(self._ahead_q[:-1], support) if leg_loads is not None else None
            i = 0
        self._ahead_i = i + 1
        q = self._ahead_q[i]
        qvel = (self._ahead_q[i + 1] - q) / dt
        if self._ahead_load is not None:
            self._robot.set_joint_targets(q, qvel, leg_load=self._ahead_load[i])
        else:
            self._robot.set_joint_targets(q, qvel)
        if self._balance is not None:
            com = self._ahead_com[i]
            self._balance(phase.support, com=com, com_velocity=(self._ahead_com[i + 1] - com)[:2] / dt)

    def _watch_com(self, stance: str) -> None:
        """Keep the least margin of the truth CoM inside the stance sole's footprint."""
        world, data = self._robot.world, self._robot.data
        sole = SupportPolygon.from_feet(world.model, data, world.ids.foot_geoms[stance])
        self.min_com_margin = min(self.min_com_margin, sole.margin(data.subtree_com[world.ids.base_body]))

    def terminate(self, new_status: Status) -> None:
        if new_status in (Status.FAILURE, Status.INVALID):
            self.robot.hold()  # safe hold where the robot is (the balance feedback off)
        elif self._balance is not None:
            self._balance(None)  # the step is over: the plain servos hold its last target
