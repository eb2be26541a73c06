"""The safe posture of a robot: how far its pelvis may sink and its trunk lean.

One definition, read by three parts of the executive:

* the planner keeps every planned configuration inside it (the pelvis no more than
  ``max_pelvis_drop`` below its standing height, the torso's z axis within
  ``max_trunk_tilt_deg`` of the vertical); a target that needs more is refused with a
  named reason;
* the fall detector calls a fall only outside it by more than a tolerance
  (``pelvis_tolerance``, ``tilt_tolerance_deg``): the servos' tracking error of a posture at
  the edge of the safe set must not read as a fall;
* the fall model adds the probability that the pelvis, planned at its lowest height, ends
  below the detector's floor under the CoM uncertainty.

The numbers are the robot's (its profile's ``safe_posture``, see
:mod:`executive.robot.profile`); :class:`SafePosture`'s defaults are the bundled
humanoid's.

Usage::

    posture = world.profile.safe_posture
    standing = standing_pelvis_height(world.model, world.ids.keyframe, world.ids.base_body)
    floor = standing - posture.fall_pelvis_drop  # the fall detector's floor
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

__all__ = ["SafePosture", "standing_pelvis_height"]


@dataclass(frozen=True)
class SafePosture:
    """Limits of a safe whole-body posture, relative to standing.

    Attributes:
        max_pelvis_drop: m the planner may lower the pelvis below its standing height.
        max_trunk_tilt_deg: deg the planner may tilt the torso's z axis from the vertical.
        pelvis_tolerance: m beyond ``max_pelvis_drop`` the detector still accepts (tracking
            error of the servos under load); deeper is a fall.
        tilt_tolerance_deg: deg beyond ``max_trunk_tilt_deg`` the detector still accepts.
    """

    max_pelvis_drop: float = 0.10
    max_trunk_tilt_deg: float = 20.0
    pelvis_tolerance: float = 0.05
    tilt_tolerance_deg: float = 10.0

    def __post_init__(self) -> None:
        for name in ("max_pelvis_drop", "max_trunk_tilt_deg", "pelvis_tolerance", "tilt_tolerance_deg"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"SafePosture.{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 < self.max_trunk_tilt_deg + self.tilt_tolerance_deg < 180.0:
            raise ValueError(
                "SafePosture: max_trunk_tilt_deg + tilt_tolerance_deg must be in (0, 180), got "
                f"{self.max_trunk_tilt_deg} + {self.tilt_tolerance_deg}"
            )

    @property
    def fall_pelvis_drop(self) -> float:
        """m below standing at which the pelvis has fallen: the posture's limit plus its tolerance."""
        return self.max_pelvis_drop + self.pelvis_tolerance

    @property
    def fall_tilt_deg(self) -> float:
        """deg of torso tilt at which the robot has fallen: the posture's limit plus its tolerance."""
        return self.max_trunk_tilt_deg + self.tilt_tolerance_deg

    def describe_drop(self, depth: float) -> str:
        """The pelvis ``depth`` m below standing against this posture's limit, for a named reason.

        Args:
            depth: how far below standing (m) a motion puts the pelvis.

        Returns:
            e.g. "the pelvis 17 cm below standing; the safe posture allows 5 cm".
        """
        return (
            f"the pelvis {depth * 100:.0f} cm below standing; the safe posture allows "
            f"{self.max_pelvis_drop * 100:.0f} cm"
        )


def standing_pelvis_height(model: mujoco.MjModel, keyframe: int, base_body: int) -> float:
    """Height (m) of ``base_body`` at the standing keyframe ``keyframe`` of ``model``.

    Args:
        model: the world's model.
        keyframe: index of the standing keyframe (``world.ids.keyframe``).
        base_body: the floating base (``world.ids.base_body``).

    Returns:
        The base body's z in the world frame at that keyframe.
    """
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, keyframe)
    mujoco.mj_kinematics(model, data)
    return float(data.xpos[base_body][2])
