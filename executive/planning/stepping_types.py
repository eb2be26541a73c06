"""Types of the quasi-static step planner: footholds, its tuning, a step's phases and plan.

Re-exported by :mod:`executive.planning.stepping`; import them from there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from executive.planning.timing import Trajectory

__all__ = ["PHASES", "Foothold", "StepConfig", "StepPhase", "StepPlan", "StepReach"]

FloatArray = NDArray[np.float64]

#: The phases of one step, in order: weight shift, lift, swing, touchdown, weight shift back.
PHASES = ("shift", "lift", "swing", "touchdown", "shift_back")


@dataclass(frozen=True)
class Foothold:
    """Where a foot stands on the floor: its foot body's origin (x, y, m, world) and its yaw (rad).

    The height is not part of it: a foothold is on the floor, the foot flat, its body as high
    above the floor as at the robot's standing start.
    """

    side: str
    x: float
    y: float
    yaw: float

    def distance(self, other: Foothold) -> tuple[float, float]:
        """(xy distance (m), |yaw difference| (rad)) to ``other``."""
        turn = abs(math.remainder(self.yaw - other.yaw, 2.0 * math.pi))
        return math.hypot(self.x - other.x, self.y - other.y), turn

    def describe(self) -> str:
        """``(x, y) m, yaw deg``, for messages."""
        return f"({self.x:.3f}, {self.y:.3f}) m, yaw {math.degrees(self.yaw):.1f} deg"


@dataclass(frozen=True)
class StepConfig:
    """Tuning of the step planner; defaults suit the bundled humanoid and the Unitree G1.

    Geometry:
        clearance: m the swing foot rises above the floor before it swings.
        single_support_margin, single_support_fraction: the CoM keeps inside the stance sole
            during lift, swing and touchdown (the sole's footprint shrunk by it) the smaller of
            ``single_support_margin`` (m) and ``single_support_fraction`` of the sole's half
            width (the distance from its middle to its nearest edge): a narrow sole keeps room
            for the CoM to move (:meth:`~executive.planning.stepping_planner.StepPlanner.sole_margin`).
        double_support_margin: m the CoM keeps inside the two feet's polygon in the weight shifts.
        leg_clearance: m kept between the swing leg and the stance leg (and the legs and the
            scene's table, obstacles and objects).
        knee_bend: rad each knee keeps from straight
            (:class:`~executive.planning.stepping_knees.KneeBendLimit`; 0: no limit).
        balance_reserve: the ankle hinges of the feet on the floor keep room in their range for
            the balance feedback (:class:`~executive.planning.stepping_ankles.AnkleReserveLimit`):
            the servo angle that puts the CoP at the sole's edge, and their share of a pelvis
            shift of ``balance_reserve_sigmas`` standard deviations of the scenario's
            ``uncertainty.com`` (False: the joint ranges alone).
    IK:
        foot_position_tolerance (m), foot_angle_tolerance_rad: the swing foot has arrived.
        com_tolerance: m the CoM ends from its target in a weight shift.
        foot_lead, foot_lead_angle_rad, com_lead: how far ahead of the foot (m, rad) and of the
            CoM (m) their tasks' targets are per IK step (they follow straight lines).
        foot_position_cost, foot_orientation_cost, com_cost, pelvis_orientation_cost: task costs.
        posture_leg_cost, posture_waist_cost, posture_arm_cost: the posture task's costs on the
            legs (towards their start angles), the waist and the arms (held at their start).
        lean_cost: the posture cost of the waist's roll joint when a phase whose CoM the legs
            leave short, an ankle at its balance reserve, is planned again leaning the torso
            over the stance foot.
        max_iterations, stall_iterations, stall_improvement: a phase fails after
            ``max_iterations`` IK steps, or when its error improved less than
            ``stall_improvement`` (m + rad) over ``stall_iterations`` steps.
    Timing:
        speed_scale: fraction of the planner's timed joint speed limits a step uses.
        shift_duration, foot_duration: the shortest weight shift and foot phase (s).
    Reach (:func:`executive.planning.stepping_walk.measure_reach`):
        reach_probe: m (and rad, for the turn) the probe asks the swing foot to go in each
            direction; the IK stops where the leg's kinematics or a limit binds.
        reach_fraction: :func:`~executive.planning.stepping_walk.plan_steps` steps at most
            this fraction of the measured reach.
    """

    clearance: float = 0.05
    single_support_margin: float = 0.03
    single_support_fraction: float = 0.4
    double_support_margin: float = 0.02
    leg_clearance: float = 0.02
    knee_bend: float = 0.15
    balance_reserve: bool = True
    balance_reserve_sigmas: float = 2.0
    foot_position_tolerance: float = 0.002
    foot_angle_tolerance_rad: float = float(np.radians(1.0))
    com_tolerance: float = 0.004
    foot_lead: float = 0.01
    foot_lead_angle_rad: float = float(np.radians(3.0))
    com_lead: float = 0.006
    foot_position_cost: float = 50.0
    foot_orientation_cost: float = 20.0
    com_cost: float = 30.0
    pelvis_orientation_cost: float = 10.0
    posture_leg_cost: float = 0.5
    posture_waist_cost: float = 20.0
    posture_arm_cost: float = 10.0
    lean_cost: float = 0.5
    max_iterations: int = 800
    stall_iterations: int = 40
    stall_improvement: float = 1e-4
    speed_scale: float = 0.5
    shift_duration: float = 2.5
    foot_duration: float = 1.2
    reach_probe: float = 0.8
    reach_fraction: float = 0.5


@dataclass(frozen=True)
class StepPhase:
    """One phase of a step: its name (one of :data:`PHASES`), its timed joint trajectory, and the
    feet in contact with the floor during it (sides; both in the weight shifts, the stance foot
    alone in lift, swing and touchdown)."""

    name: str
    trajectory: Trajectory
    support: tuple[str, ...]


@dataclass(frozen=True)
class StepPlan:
    """One planned quasi-static step.

    Attributes:
        swing: the side of the foot that steps.
        stance: the side of the foot that stays.
        phases: the step's phases in order (:data:`PHASES`), each starting where the last ended.
        start: every foot's foothold before the step, by side.
        footholds: every foot's planned foothold after the step, by side (the swing foot's is
            the target).
        sole_margin: the least margin (m) the plan keeps the CoM inside the stance sole while the
            swing foot is off the floor
            (:meth:`~executive.planning.stepping_planner.StepPlanner.sole_margin`).
        planning_s: wall time the plan took (s).
    """

    swing: str
    stance: str
    phases: tuple[StepPhase, ...]
    start: dict[str, Foothold]
    footholds: dict[str, Foothold]
    sole_margin: float
    planning_s: float = 0.0

    @property
    def target(self) -> Foothold:
        """The swing foot's planned foothold."""
        return self.footholds[self.swing]

    @property
    def duration(self) -> float:
        """The phases' total duration (s)."""
        return float(sum(p.trajectory.duration for p in self.phases))

    @property
    def final_qpos(self) -> FloatArray:
        """The configuration the step ends in (the last phase's last knot)."""
        return np.array(self.phases[-1].trajectory.qpos[-1], dtype=float)

    def phase(self, name: str) -> StepPhase:
        """The phase called ``name`` (KeyError when the plan has none)."""
        for p in self.phases:
            if p.name == name:
                return p
        raise KeyError(name)


@dataclass(frozen=True)
class StepReach:
    """How far one foot can step from a stance, measured by IK
    (:func:`~executive.planning.stepping_walk.measure_reach`).

    Offsets are of the swing foot in the stance foot's frame, from where it stood: ``forward``
    and ``backward`` (m, along the stance foot's x), ``outward`` and ``inward`` (m, across it,
    away from and towards the stance foot), ``turn_out`` and ``turn_in`` (rad, the toes away
    from and towards the stance foot). ``binds`` names what stopped the probe in each
    direction.
    """

    side: str
    forward: float
    backward: float
    outward: float
    inward: float
    turn_out: float
    turn_in: float
    binds: dict[str, str] = field(default_factory=dict)
