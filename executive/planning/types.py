"""Types of the whole-body planner: targets, configuration, errors, statistics, pose helpers.

Re-exported by :mod:`executive.planning.planner`; import them from there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError

__all__ = [
    "Binding",
    "BindingKind",
    "HandTarget",
    "PlanStats",
    "PlannerConfig",
    "PlanningError",
    "PlanningInputError",
    "Relative",
    "attach_object",
    "body_pose",
    "hand_top_down_quat",
    "se3",
    "site_pose",
    "site_quat",
]

FloatArray = NDArray[np.float64]
#: A carried object's attachment: (hand site, object body, object qpos address, pose in the site frame).
Relative = tuple[int, int, int, mink.SE3]


#: What a :class:`Binding` can be: the kinds of limit of the IK step's QP.
BindingKind = Literal["collision", "joint_range", "joint_velocity", "pelvis", "tilt", "balance", "ball_joint"]


@dataclass(frozen=True)
class Binding:
    """One limit of the IK step's QP that holds a stalled move back (an active constraint).

    Found by :func:`executive.planning.active_set.active_limits`; a :class:`PlanningError`
    names them (``binding``), and ``as_dict`` is their form in ``executive plan --json`` and
    the audit log.

    Attributes:
        kind: which limit (:data:`BindingKind`).
        name: what it holds: the geom pair ``"a vs b"``, the joint's name, ``pelvis``,
            ``torso`` or ``CoM``.
        value: where that is now: the pair's distance (m), the joint's angle (rad, or its
            step's rate in rad/s for a velocity limit), the pelvis's drop below standing (m),
            the torso's tilt (deg), the CoM's distance inside the support polygon's edge (m).
        bound: the limit's value, in the same unit: the pair's required clearance, the
            joint's range bound or velocity limit, the safe posture's largest drop, the
            largest tilt, the support margin.
        side: ``upper`` or ``lower`` for a joint's bound, else empty.
        multiplier: the constraint's Lagrange multiplier in the step's QP (absolute): how
            hard it holds the step back (comparable between rows of one kind).
    """

    kind: BindingKind
    name: str
    value: float
    bound: float
    side: str = ""
    multiplier: float = 0.0

    def describe(self) -> str:
        """The binding in words, for a message."""
        if self.kind == "collision":
            return f"{self.name} at {self.value:.3f} m (clearance {self.bound:.3f} m)"
        if self.kind == "joint_range":
            return f"{self.name} at its {self.side} limit ({self.bound:.2f} rad)"
        if self.kind == "joint_velocity":
            return f"{self.name} at its velocity limit ({self.bound:.2f} rad/s)"
        if self.kind == "pelvis":
            return f"the pelvis {self.value:.3f} m below standing, at the {self.bound:.2f} m posture limit"
        if self.kind == "tilt":
            return f"the torso's tilt at its limit ({self.value:.1f} of {self.bound:.0f} deg)"
        if self.kind == "balance":
            return f"the CoM {self.value:.3f} m inside the support polygon's edge (margin {self.bound:.3f} m)"
        return f"{self.name} at its range"

    def as_dict(self) -> dict[str, str | float]:
        """The binding as plain data (JSON, the audit log): the attributes by name."""
        out: dict[str, str | float] = {"kind": self.kind, "name": self.name, "value": self.value}
        out |= {"bound": self.bound, "multiplier": self.multiplier}
        if self.side:
            out["side"] = self.side
        return out


class PlanningError(ExecutiveError):
    """A motion could not be planned: a hand target out of reach, or a balance or QP failure.

    Attributes:
        name: the trajectory (segment) name.
        side: the hand that fell short (None when no hand is to blame).
        position_error: remaining distance of that hand to its target (m).
        angle_error: remaining rotation of that hand to its target (rad).
        binding: the limits that held the move back where it stalled (the active set of the
            IK step's QP, :class:`Binding`); empty when not known (not an IK stall).
        stall: the configuration (qpos) the move stalled at; None when not an IK stall.
    """

    def __init__(
        self,
        name: str,
        side: str | None,
        position_error: float,
        angle_error: float,
        iterations: int,
        reason: str | None = None,
        binding: Sequence[Binding] | None = None,
        stall: FloatArray | None = None,
    ) -> None:
        self.name = name
        self.side = side
        self.position_error = position_error
        self.angle_error = angle_error
        self.iterations = iterations
        self.binding: tuple[Binding, ...] = tuple(binding or ())
        self.stall = stall
        if reason is None:
            reason = (
                f"{side} hand cannot reach target '{name}': {position_error:.3f} m and "
                f"{np.degrees(angle_error):.1f} deg short after {iterations} iterations"
            )
            if binding is not None:
                reason += "; binding: " + (
                    ", ".join(b.describe() for b in binding)
                    if binding
                    else "no limit active (the IK's tasks balance short of the target)"
                )
        super().__init__(reason)


class PlanningInputError(ExecutiveError):
    """A request names a side, object or geom the world does not have."""


@dataclass(frozen=True)
class HandTarget:
    """Where a hand site should go: world position and orientation (w x y z).

    ``frame``: what the target is fixed to. ``world`` (an object's pick or place, a lane over the
    table) stays where it is when the robot's base turns out elsewhere than planned; ``base`` (a
    home pose) moves with the base (:mod:`executive.planning.restance`).
    """

    side: str
    position: FloatArray
    quat: FloatArray
    frame: Literal["world", "base"] = "world"


@dataclass(frozen=True)
class PlannerConfig:
    """Tuning of the planner; defaults suit the embedded humanoid.

    Tolerances and budget:
        position_tolerance (m), angle_tolerance_rad: a hand has arrived within both.
        max_iterations: IK steps per move before a PlanningError.
        relax_iterations, relax_factor, relax_floor: when the hands' error improved less
            than ``stall_improvement`` over ``relax_iterations`` steps short of the
            tolerance (the soft posture task holds them back), scale the posture task's
            costs by ``relax_factor``, until they are below ``relax_floor`` of their
            defaults. The hard limits (CoM in the support polygon, clearance) are not
            relaxed. A short window relaxes early (a hand creeping towards its goal against
            the posture task costs IK steps and path length); once relaxed to the floor,
            only ``stall_iterations`` decide that the hands cannot get closer.
        stall_iterations, stall_improvement: stop early (and raise) when the worst
            hand's error (m + rad) improved less than ``stall_improvement`` over the
            last ``stall_iterations`` steps.
    IK:
        ik_dt: the IK step's pseudo time (s); the velocity limit bounds a step to v * ik_dt.
        damping: mink's Levenberg-Marquardt damping on all dofs.
        feet_tolerance: after each step the feet's pose error (m + rad, mink FrameTask
            error) is projected out until below this.
        hand_position_cost, hand_orientation_cost: FrameTask costs of a moving hand.
        lead_distance (m), lead_angle_rad: a hand task's target is at most this far ahead
            of the hand on the straight way to its goal (so the hand moves along a line).
        idle_arm_cost: PostureTask cost holding an idle arm's joints at their start angles.
        com_cost: ComTask cost on x and y (none on z).
        posture_leg_cost, posture_waist_cost, posture_arm_cost: PostureTask per joint group.
        posture_gain: the PostureTask's gain (mink): the fraction of the posture error it asks
            to remove per step, so the body drifts back gently instead of lunging (a lunge of the
            legs or waist swings the CoM, and the timing then slows the whole move down).
    Balance and clearance:
        support_margin: the CoM xy stays this far inside the feet's support polygon (m).
        max_torso_tilt_deg: the torso's z axis stays within this angle of the vertical
            (a lean, not a bow: the CoM stays over the feet by the waist and arm choices).
        min_distance: clearance kept between avoided geom pairs (m): the robot and a carried
            object against obstacles, other objects and the robot itself. It must exceed the
            servos' tracking error at the hands.
        table_distance: the smaller clearance kept between the robot and the table (m): a
            top-down grasp of a flat object brings the fingertips close to the table top.
        detection_distance: pairs closer than this enter the QP (m).
        collision_gain: mink's velocity-damper gain of the collision rows.
        collision_recovery: a pair that has drifted inside its clearance is pushed back out
            by up to this much per IK step (m) (see GeomPairCollisionLimit).
        backtrack_steps: an IK step that leaves a pair closer than ``min_distance`` (the
            rows are first order) less ``step_slack`` is halved up to this many times.
        step_slack: how far (m) an IK step may leave a pair below its clearance (or below
            its start distance, when it starts closer); smaller than ``clearance_tolerance``,
            so the knots between the steps still pass their check.
        clearance_tolerance: the timed trajectory is checked at every knot; a pair closer
            than min_distance minus this (m) is a PlanningError.
        via_clearance: a hand whose straight way is blocked by an obstacle or object
            passes over it with this clearance (m) (see executive.planning.route).
        via_tolerance: a via point counts as passed within this distance (m).
    Timing:
        leg_velocity, waist_velocity, arm_velocity: joint velocity limits (rad/s).
        velocity_scale: fraction of those limits the timed trajectory uses.
        hand_speed: bound on each hand site's speed along the timed path (m/s).
        acceleration_limit: bound on the tangential joint acceleration (rad/s^2).
        knot_spacing (s), max_knots, min_duration (s): the knot grid.
        zmp_margin (m): the zero-moment point of the timed CoM path (linear inverted
            pendulum, CoM acceleration over 0.1 s) stays this far inside the support
            polygon; a motion too brisk for that is slowed down by ``zmp_stretch`` per
            round, at most ``zmp_retime_rounds`` rounds (then a PlanningError).
    """

    position_tolerance: float = 0.002
    angle_tolerance_rad: float = float(np.radians(1.0))
    max_iterations: int = 600
    relax_iterations: int = 3
    relax_factor: float = 0.05
    relax_floor: float = 1e-3
    stall_iterations: int = 60
    stall_improvement: float = 1e-4
    ik_dt: float = 0.025
    feet_tolerance: float = 1e-5
    damping: float = 1e-3
    hand_position_cost: float = 50.0
    hand_orientation_cost: float = 20.0
    lead_distance: float = 0.02
    lead_angle_rad: float = float(np.radians(5.0))
    idle_arm_cost: float = 10.0
    com_cost: float = 30.0
    posture_leg_cost: float = 100.0
    posture_waist_cost: float = 20.0
    posture_arm_cost: float = 0.1
    posture_gain: float = 0.2
    hold_body: bool = False
    support_margin: float = 0.02
    max_torso_tilt_deg: float = 20.0
    min_distance: float = 0.02
    table_distance: float = 0.01
    detection_distance: float = 0.10
    clearance_tolerance: float = 0.002
    collision_gain: float = 0.5
    collision_recovery: float = 0.0005
    backtrack_steps: int = 4
    step_slack: float = 0.001
    via_clearance: float = 0.04
    via_tolerance: float = 0.03
    leg_velocity: float = 2.0
    waist_velocity: float = 1.5
    arm_velocity: float = 2.0
    velocity_scale: float = 0.5
    hand_speed: float = 0.25
    acceleration_limit: float = 2.0
    knot_spacing: float = 0.02
    max_knots: int = 300
    min_duration: float = 0.2
    zmp_margin: float = 0.02
    zmp_stretch: float = 1.25
    zmp_retime_rounds: int = 12


@dataclass(frozen=True)
class PlanStats:
    """What the last :meth:`Planner.move` cost."""

    name: str
    iterations: int
    ik_time_s: float  # time spent in mink.solve_ik (all steps)
    total_time_s: float
    knots: int


def hand_top_down_quat(closing_axis_world: Sequence[float] = (0.0, 1.0, 0.0)) -> FloatArray:
    """Hand site quaternion (w x y z) with site z = world -z and site y along the closing axis.

    The closing axis is projected onto the horizontal plane; site x = y x z.
    """
    y = np.array(closing_axis_world, dtype=float)
    y[2] = 0.0
    norm = float(np.linalg.norm(y))
    if norm < 1e-9:
        raise PlanningInputError(f"closing axis {tuple(closing_axis_world)} has no horizontal component")
    y /= norm
    z = np.array([0.0, 0.0, -1.0])
    rot = np.column_stack([np.cross(y, z), y, z])
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rot.reshape(-1))
    return quat


# --- pose helpers ----------------------------------------------------------------------------


def se3(position: FloatArray, quat: FloatArray) -> mink.SE3:
    """Pose from a position and a (normalised) w x y z quaternion."""
    q = np.asarray(quat, dtype=float)
    return mink.SE3.from_rotation_and_translation(
        mink.SO3(wxyz=q / np.linalg.norm(q)), np.asarray(position, dtype=float)
    )


def site_pose(data: mujoco.MjData, site: int) -> mink.SE3:
    """World pose of a site in the current kinematics."""
    return mink.SE3.from_rotation_and_translation(
        mink.SO3.from_matrix(data.site_xmat[site].reshape(3, 3)), data.site_xpos[site].copy()
    )


def site_quat(data: mujoco.MjData, site: int) -> FloatArray:
    """A site's world orientation (w x y z) in the current kinematics, as mink's
    SO3.from_matrix makes it (``mju_mat2Quat``)."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, data.site_xmat[site])
    return quat


def body_pose(data: mujoco.MjData, body: int) -> mink.SE3:
    """World pose of a body in the current kinematics."""
    return mink.SE3.from_rotation_and_translation(
        mink.SO3(wxyz=data.xquat[body].copy()), data.xpos[body].copy()
    )


def attach_object(data: mujoco.MjData, relative: Relative) -> None:
    """Put a carried object's free joint at hand pose x relative pose (needs current kinematics)."""
    site, _body, qadr, rel = relative
    rel_quat, rel_pos = rel.wxyz_xyz[:4], rel.wxyz_xyz[4:]
    data.qpos[qadr : qadr + 3] = data.site_xpos[site] + data.site_xmat[site].reshape(3, 3) @ rel_pos
    quat = np.empty(4)
    mujoco.mju_mulQuat(quat, site_quat(data, site), rel_quat)
    data.qpos[qadr + 3 : qadr + 7] = quat / np.linalg.norm(quat)
