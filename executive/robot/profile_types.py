"""What the executive needs to know about a robot, beyond its MJCF.

A profile is a small YAML file (see ``executive/robots/profiles/*.yaml``)
loaded into these frozen dataclasses. Names refer to elements of the MJCF
model; the world builder checks every one exists when it builds the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from executive.robot.posture import SafePosture

__all__ = ["ArmProfile", "FootProfile", "GripperProfile", "HandFrame", "RobotProfile"]


@dataclass(frozen=True)
class HandFrame:
    """The grasp frame of a hand: an existing site, or a body plus an offset.

    Convention: +z points from the palm towards the fingertips (the approach
    direction); +y is the direction the jaws/fingers close along.
    When ``site`` is None the world builder adds a site named
    ``executive_<side>_hand`` on ``body`` at ``offset`` with ``quat``.

    ``closing_yaw_deg``: for a hand whose two closing directions are not alike (a
    thumb on one side, fingers on the other), the preferred yaw of +y about the
    vertical, relative to the robot's forward direction, when the hand grasps from
    above: of the two ways to close across an object, the one nearer this is taken.
    None: the jaws are symmetric, and the way nearer the home pose's is taken.
    """

    site: str | None = None
    body: str | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # w x y z, in the body frame
    closing_yaw_deg: float | None = None


@dataclass(frozen=True)
class GripperProfile:
    """Actuators that open and close one hand, with their open and closed targets."""

    actuators: tuple[str, ...]
    open: tuple[float, ...]
    closed: tuple[float, ...]


@dataclass(frozen=True)
class ArmProfile:
    joints: tuple[str, ...]  # shoulder to wrist, in kinematic order
    hand: HandFrame
    gripper: GripperProfile
    hand_body: str  # the root body of the hand (its subtree is "the hand")
    forearm_body: str | None = None  # for per-body-part collision severity


@dataclass(frozen=True)
class FootProfile:
    """A foot: the body whose geoms touch the ground (its sole)."""

    body: str
    geoms: tuple[str, ...] = ()  # empty: every collision geom of ``body``


@dataclass(frozen=True)
class RobotProfile:
    name: str
    base_body: str  # the floating base (pelvis)
    torso_body: str  # for trunk tilt
    head_body: str | None
    keyframe: str  # the standing home pose
    arms: dict[str, ArmProfile]  # keys "left" and "right"
    feet: dict[str, FootProfile]  # keys "left" and "right"
    waist_joints: tuple[str, ...]
    leg_joints: dict[str, tuple[str, ...]]  # keys "left" and "right"
    mjcf: Path | None = None  # the model this profile ships with (bundled robots)
    source: Path | None = None  # the profile file
    # Joint angles (rad) that replace the keyframe's in the home pose, e.g. arms held a little
    # further out so that open hands keep clear of the body.
    home_joints: dict[str, float] = field(default_factory=dict)
    # After placing across the body, go back along the carry lane to the hand's own side before
    # turning home (the G1: its straight way home from across the body ends in another arm
    # configuration with the waist bent). Off by default: on the bundled humanoid that extra
    # reach unloads a foot (the live guard measures the CoM 73 mm outside the foot contacts).
    return_along_lane: bool = False
    # The safe posture (pelvis drop, trunk tilt) the planner keeps to and the fall detector and
    # fall model measure against (executive.robot.posture).
    safe_posture: SafePosture = field(default_factory=SafePosture)
    # Alternatives this robot cannot do, by name, with the reason (e.g. {left_to_right: "..."}):
    # they are reported infeasible with that reason.
    unsupported_alternatives: dict[str, str] = field(default_factory=dict)

    @property
    def sides(self) -> tuple[str, ...]:
        return tuple(sorted(self.arms))
