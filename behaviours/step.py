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
``tracking`` (the robot did not follow its plan; it still stands). The step tells the detector
which feet stand in each phase (``set_phase(support=...)``); when one of them slips (the
detector's ``slip``) the step first holds on both feet as after a guard's trip
(:meth:`Step.hold_safely`), then fails with ``slip``, the slip and the hold in its message.

A :class:`behaviours.guard.RiskGuard` wraps a step as it wraps a hand motion (the step is a
:class:`behaviours.guard.GuardedMotion`): its look-ahead runs along the walk's planned knots, its
CoM limit is the sole's (:meth:`Step.com_limit`), a foot rolled onto an edge counts as the CoM
outside its support, and when it trips :meth:`Step.hold_safely` puts the robot on both feet: the
plain hold when the robot tips towards the swing foot (its two-foot feed-forward sets the foot
down where it is), else the step's own plan back to where the foot lifted or on to its foothold,
whichever is shorter on one foot (:mod:`executive.planning.stepping_hold`; docs/stepping.md,
"When a guard stops a step").
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
from executive.planning.stepping_hold import back_to_both_feet, on_to_both_feet, single_support_left
from executive.planning.timing import Trajectory, concatenate
from executive.schema.types import GuardConfig
from executive.world.heading import yaw_of

__all__ = ["HELD_VERDICTS", "HOLDS", "Step", "foot_force", "foothold", "sole_gap"]

Status = py_trees.common.Status

#: How a stopped step holds (:meth:`Step.hold_safely`): ``auto`` (the rule measured safest, below),
#: ``freeze`` (every joint where it is, as a hand motion), ``plan`` (along the plan to both feet).
HOLDS = ("auto", "freeze", "plan")
#: The detector's verdicts after which a step holds on both feet (:meth:`Step.hold_safely`) before
#: it fails: a foot that slipped leaves the robot standing, a fall does not.
HELD_VERDICTS = ("slip",)
#: ``auto`` drops the swing foot where it is when the capture point's error from the plan lies
#: within 60 degrees of the direction from the stance foot to the swing foot: the robot tips
#: towards it (docs/stepping.md, "When a guard stops a step").
_TOWARDS_SWING = math.cos(math.radians(60.0))


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
    Fails at once when a physics detector flags a failure (a fall); after the safe hold
    (:meth:`hold_safely`) when it flags one of :data:`HELD_VERDICTS` (a foot slip, ``slipped``
    holds it); with ``tracking`` when the
    swing foot still carries more than ``liftoff_force`` (N) after the lift, is more than
    ``touchdown_gap`` above the floor after the touchdown, first touches the floor more than
    ``landing_tolerance`` (m) or ``landing_yaw_tolerance`` (rad) from its planned foothold, or
    carries less than ``load_share`` of the robot's weight after the weight shift back. A phase
    that ends with its check not yet met holds its last target for up to ``settle_s`` first.

    Measured (read them after the step): ``landing`` (where the swing foot touched down),
    ``landing_error`` ((m, rad) from the planned foothold), ``liftoff_residual`` (N left on the
    swing foot after the lift), ``min_com_margin`` (m: the least distance of the truth CoM inside
    the stance sole during lift, swing and touchdown; negative outside).

    As a :class:`behaviours.guard.GuardedMotion`: :attr:`trajectory`, :meth:`planned_time`,
    :meth:`com_limit`, :attr:`support_required`, :meth:`hold_safely` and :attr:`holding`.

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
        walk: the planned trajectory the step is part of (a walk's footsteps end to end, as
            :attr:`executive.planning.plan.AlternativePlan.trajectories` has it), which a guard
            looks ahead along; None: the step's own phases, concatenated.
        starts_at: s into ``walk`` at which this step starts.
        hold: how a stopped step holds (:data:`HOLDS`; :meth:`hold_safely`).
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
        walk: Trajectory | None = None,
        starts_at: float = 0.0,
        hold: str = "auto",
    ) -> None:
        super().__init__(name)
        if hold not in HOLDS:
            raise ValueError(f"step '{name}': hold '{hold}' is not one of {', '.join(HOLDS)}")
        self.plan = plan
        self.landing_tolerance = landing_tolerance
        self.landing_yaw_tolerance = landing_yaw_tolerance
        self.liftoff_force = liftoff_force
        self.touchdown_gap = touchdown_gap
        self.load_share = load_share
        self.settle_s = settle_s
        self.trajectory = walk if walk is not None else concatenate([p.trajectory for p in plan.phases], name)
        self.starts_at = starts_at if walk is not None else 0.0
        self.hold = hold
        # where each phase starts on the step's own time line (s)
        self._phase_at = np.concatenate([[0.0], np.cumsum([p.trajectory.duration for p in plan.phases])])
        self.landing: Foothold | None = None
        self.landing_error = (math.inf, math.inf)
        self.liftoff_residual = math.inf
        self.min_com_margin = math.inf
        self.holding = False  # the safe hold is reached (hold_safely): both feet down, or held
        self._phases: tuple[StepPhase, ...] = plan.phases  # followed; hold_safely's set-down after
        self._setting_down = False
        self._robot: Any = None
        self._index = 0
        self._t0 = 0.0
        self._ahead_t = np.zeros(0)
        self._ahead_q = np.zeros((0, 0))
        self._ahead_load: np.ndarray | None = None
        self._ahead_com = np.zeros((0, 3))
        self._ahead_i = 0
        self._balance: Any = None
        self._carried: tuple[str, str] | None = None
        self._held = ""  # what hold_safely did, in words
        self._slipped_in = ""  # the phase a slip came in
        self.slipped: Any = None  # the detector's Failure the step held after (HELD_VERDICTS)

    @property
    def phase(self) -> StepPhase:
        """The phase being followed."""
        return self._phases[min(self._index, len(self._phases) - 1)]

    def initialise(self) -> None:
        self._robot = self.robot
        self._balance = getattr(self._robot, "set_balance", None)
        self._phases, self._setting_down, self.holding = self.plan.phases, False, False
        self._index, self._t0 = 0, self._robot.time
        self._ahead_t, self._ahead_i = np.zeros(0), 0
        self.landing, self.landing_error = None, (math.inf, math.inf)
        self.liftoff_residual, self.min_com_margin = math.inf, math.inf
        self._held, self.slipped = "", None
        holding: dict[str, str] = self.bb.holding
        self._carried = next(iter(holding.items()), None) if holding else None
        self._declare(self.phase)
        self.feedback_message = f"{self.name}: {self.plan.swing} foot to {self.plan.target.describe()}"

    def update(self) -> Status:
        robot = self._robot
        if robot.failure is not None:
            return self._on_detector(robot)
        phase = self.phase
        t = robot.time - self._t0
        self._track(phase, t, robot.control_dt)
        if self._setting_down:
            status = self._set_down(phase, t)
            return self._held_after_slip() if self.slipped is not None and self.holding else status
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
        self._declare(self.phase)
        return Status.RUNNING

    def _declare(self, phase: StepPhase) -> None:
        """Tell the detector the phase's support feet (and the object in hand)."""
        self._robot.detector.set_phase(carried=self._carried, support=phase.support)

    def _on_detector(self, robot: Any) -> Status:
        """A detector's failure: the safe hold first for :data:`HELD_VERDICTS`, else fail with it."""
        failure = robot.failure
        if failure.mode not in HELD_VERDICTS or self.slipped is not None:
            self.failed_by_detector(robot)
            if self.slipped is not None:  # a second failure on the way to the hold
                self.feedback_message += f" (holding after {self._slip_line()})"
            return Status.FAILURE
        self._slipped_in = self.phase.name
        self.slipped = robot.detector.acknowledge()  # watched afresh while the robot holds
        self.hold_safely(robot)
        if self.holding:
            return self._held_after_slip()
        self.feedback_message = f"{self._slip_line()} (holding)"
        return Status.RUNNING

    def _slip_line(self) -> str:
        """The slip's detail, the phase it came in and what the hold did."""
        return f"{self.slipped.detail} in the '{self._slipped_in}' phase; {self._held}"

    def _held_after_slip(self) -> Status:
        """Fail with the slip's verdict, its detail and what the hold did."""
        return self.fail(self.slipped.mode, self._slip_line())

    # --- the guard's interface (behaviours.guard.GuardedMotion) ---------------------------------

    @property
    def support_required(self) -> bool:
        """True while the plan has one foot on the floor: its sole must touch the floor over an
        area (a stance foot rolled onto an edge counts as the CoM outside its support)."""
        return len(self.phase.support) == 1

    def planned_time(self, robot: Any) -> float:
        """Where the step is along :attr:`trajectory` now (s): a phase's end while it settles."""
        phase = min(self._index, len(self.plan.phases) - 1)
        t = min(robot.time - self._t0, self.plan.phases[phase].trajectory.duration)
        return self.starts_at + float(self._phase_at[phase]) + t

    def com_limit(self, config: GuardConfig) -> float:
        """The least CoM margin (m) over the foot contacts: the guard's ``min_com_margin``, or the
        margin the plan keeps inside the stance sole if that is less (a narrow sole: the CoM over
        its middle is less than ``min_com_margin`` from its edge)."""
        return min(config.min_com_margin, self.plan.sole_margin)

    def hold_safely(self, robot: Any, clear_ahead: bool = True) -> str:
        """Put the robot on both feet, the way ``hold`` says; what it does, in words.

        ``auto``: when the robot tips towards the swing foot (its capture point's error from the
        plan points there) the plain hold, whose two-foot feed-forward sets a lifted foot down
        where it is; else the step's own plan to both feet
        (:mod:`executive.planning.stepping_hold`): back to where the foot lifted from or on to
        its foothold, whichever is shorter on one foot (back when the path ahead is what tripped,
        ``clear_ahead`` False); a weight shift undone, a weight shift back finished. ``freeze``:
        the plain hold. ``plan``: the plan, as ``auto`` does when the robot does not tip towards
        the swing foot. :attr:`holding` turns True once the robot holds. Once started, a second
        call returns what the first does.
        """
        if self._setting_down or self.holding:
            return self._held
        self._held = self._hold(robot, clear_ahead)
        return self._held

    def _hold(self, robot: Any, clear_ahead: bool) -> str:
        """Start :meth:`hold_safely`'s hold; what it does, in words."""
        index = min(self._index, len(self.plan.phases) - 1)
        t = robot.time - self._t0
        one_foot = len(self.plan.phases[index].support) == 1
        if self.hold == "freeze" or (self.hold == "auto" and self._tips_towards_swing(robot, index, t)):
            robot.hold()
            self.holding = True
            if not one_foot:
                return "held on both feet where it stands"
            if self.hold == "freeze":
                return "held where it is"
            return f"the {self.plan.swing} foot put down where it is (the robot tips towards it)"
        if one_foot:
            back_s, on_s = single_support_left(self.plan, index, t)
            back = back_s <= on_s or not clear_ahead
        else:  # both feet down: a weight shift undone, a weight shift back finished
            back = index == 0
        phases = back_to_both_feet(self.plan, index, t) if back else on_to_both_feet(self.plan, index, t)
        if not phases:
            robot.hold()
            self.holding = True
            return "held on both feet where it stands"
        self._phases, self._setting_down = phases, True
        self._index, self._t0, self._ahead_t, self._ahead_i = 0, robot.time, np.zeros(0), 0
        self._track(phases[0], 0.0, robot.control_dt)  # this period's target already
        self._declare(phases[0])
        where = "back down where it lifted from" if back else "down on its foothold"
        if phases[0].name != "set_down":
            return "the weight shifted back onto both feet" if back else "the weight shift back finished"
        return f"the {self.plan.swing} foot set {where}, the weight shifted onto both feet"

    def _tips_towards_swing(self, robot: Any, index: int, t: float) -> bool:
        """Whether the measured capture point's error from the plan's lies within 60 degrees of
        the direction from the stance foot to the swing foot (Pratt et al. 2006's capture point
        ``c + c_dot / omega``, ``omega = sqrt(g / h)``)."""
        world, data = robot.world, robot.data
        model, base = world.model, world.ids.base_body
        planned = _com_at(self.plan.phases[index], np.array([t]))[0]
        floor = world.ids.floor_geom
        height = planned[2] - (float(data.geom_xpos[floor][2]) if floor >= 0 else 0.0)
        omega = math.sqrt(float(np.linalg.norm(model.opt.gravity)) / max(height, 1e-3))
        mujoco.mj_subtreeVel(model, data)
        error = data.subtree_com[base][:2] + data.subtree_linvel[base][:2] / omega - planned[:2]
        feet = world.profile.feet
        swing = data.xpos[model.body(feet[self.plan.swing].body).id][:2]
        towards = swing - data.xpos[model.body(feet[self.plan.stance].body).id][:2]
        size = float(np.linalg.norm(error)) * float(np.linalg.norm(towards))
        return size > 0.0 and float(error @ towards) > _TOWARDS_SWING * size

    def _set_down(self, phase: StepPhase, t: float) -> Status:
        """Follow the set-down phases of :meth:`hold_safely`; :attr:`holding` once they have played."""
        if t < phase.trajectory.duration:
            self.feedback_message = f"{self.name} {phase.name}: {t:.2f}/{phase.trajectory.duration:.2f} s"
            return Status.RUNNING
        if self._index + 1 < len(self._phases):
            self._index += 1
            self._t0, self._ahead_t, self._ahead_i = self._robot.time, np.zeros(0), 0
            self._declare(self._phases[self._index])
        else:
            self.holding = True
        return Status.RUNNING

    # --- checks -------------------------------------------------------------------------------

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
        return f"the {swing} foot {what}" if last_chance else None

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
            f"the {swing} foot landed at {self.landing.describe()}, {distance * 1000:.0f} mm "
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
