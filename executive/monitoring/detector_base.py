"""What the failure detector's checks share: thresholds, the failure they report, the phase, the interface.

A check (:class:`Check`) watches one family of verdicts of the failure-mode table
(:mod:`executive.schema.failure_modes`); :class:`~executive.monitoring.detectors.FailureDetector`
runs its checks in a fixed order after each physics step and latches the first :class:`Failure`.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Protocol

from executive.errors import ExecutiveError

__all__ = [
    "Check",
    "ClosestCall",
    "DetectorError",
    "DetectorThresholds",
    "Failure",
    "Phase",
    "require_object",
    "require_side",
]


class DetectorError(ExecutiveError, ValueError):
    """A detector was asked about a side or an object the world does not have."""


@dataclass(frozen=True)
class Failure:
    """What went wrong, when, and (for contacts) between which bodies and how hard."""

    mode: str  # a verdict of the failure-mode table (executive.schema.failure_modes)
    detail: str  # human-readable: names bodies/geoms, force in N, heights/angles, times
    time: float  # simulation time (s)
    bodies: tuple[str, ...] = ()  # body names involved (collision)
    force: float = 0.0  # contact normal force magnitude in N (collision)


@dataclass(frozen=True)
class DetectorThresholds:
    """When an observation counts as a failure; every default with its reason."""

    # m below the standing height => fall. None: the robot's safe posture's limit plus its
    # tolerance (SafePosture.fall_pelvis_drop): the planner plans no deeper than the limit.
    pelvis_drop: float | None = None
    # deg of the torso's z axis from vertical => fall. None: the safe posture's
    # (SafePosture.fall_tilt_deg).
    trunk_tilt_deg: float | None = None
    # N; contacts below this are grazes, ignored (kept as the closest call). 1 N is about
    # the weight of 0.1 kg: any deliberate push exceeds it, solver noise of a touch does not.
    collision_force: float = 1.0
    # m from the holding hand's site to the carried object's surface => drop. The site is
    # between the pads, inside a held object; 5 cm out means it left the jaws.
    hold_distance: float = 0.05
    # m in the table plane between the placed object's centre and its target: the
    # placement accuracy a later grasp of the object tolerates.
    place_position_tol: float = 0.02
    # deg of yaw error of a placed object (checked only when the task gives a yaw).
    place_yaw_tol_deg: float = 10.0
    # rad/s or m/s; beyond => unstable. Servoed joints move at a few rad/s, a falling
    # body at a few m/s; 100 is only reached by a diverging simulation.
    max_qvel: float = 100.0
    # m/s below which a placed object counts as resting (and 10x this in rad/s): 2 cm/s
    # is slower than any deliberate motion, faster than solver creep of a resting box.
    rest_speed: float = 0.02
    # deg of a placed object's z axis from vertical beyond which it has tipped over.
    place_tilt_deg: float = 10.0
    # m; clearances larger than this are not computed (broad phase of the closest call).
    clearance_horizon: float = 0.20
    # m the part of a standing foot's sole on the floor may slide along it => slip. None: 0.4
    # of the sole's half width (its middle's distance to its nearest edge; humanoid 30 mm, G1
    # 14 mm): the room the step planner keeps the CoM inside the stance sole (SLIDE_FRACTION).
    foot_slip: float | None = None
    # deg a standing foot may turn about the vertical => slip. None: the turn that moves the
    # sole's toe by foot_slip (humanoid 13.2 deg, G1 8.9 deg).
    foot_slip_yaw_deg: float | None = None
    # share of the robot's weight a foot must carry for its slide to count: a foot that only
    # skims the floor (a swing foot set down, a weight shifted off it) takes no support away.
    foot_slip_load: float = 0.1


@dataclass(frozen=True)
class ClosestCall:
    """The nearest thing to a failure seen so far, for the report.

    ``distance``: the smallest clearance (m) between a forbidden pair, ``inf`` when no
    pair came within ``clearance_horizon``; negative when it penetrated (then the
    contact force tells whether it was a graze). ``ignored_force``: the largest normal
    force (N) of a forbidden contact below ``collision_force``. ``self_contacts``: how
    many robot self-contacts (summed over steps) were seen; ``self_force``: the largest.
    """

    distance: float = math.inf
    distance_bodies: tuple[str, ...] = ()
    distance_time: float = 0.0
    ignored_force: float = 0.0
    ignored_bodies: tuple[str, ...] = ()
    ignored_time: float = 0.0
    self_contacts: int = 0
    self_force: float = 0.0
    self_bodies: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line for the report."""
        parts = []
        if math.isfinite(self.distance):
            a, b = self.distance_bodies
            parts.append(f"closest {a}-{b} {self.distance * 1000:.1f} mm at t={self.distance_time:.2f} s")
        else:
            parts.append("nothing came within the clearance horizon")
        if self.ignored_bodies:
            a, b = self.ignored_bodies
            parts.append(f"largest graze {a}-{b} {self.ignored_force:.2f} N at t={self.ignored_time:.2f} s")
        if self.self_contacts:
            largest = f"{'-'.join(self.self_bodies)} " if self.self_bodies else ""
            parts.append(f"{self.self_contacts} self-contacts (largest {largest}{self.self_force:.1f} N)")
        return "; ".join(parts)


@dataclass(frozen=True)
class Phase:
    """What the executing behaviour does now (``FailureDetector.set_phase``'s arguments).

    carried: (side, object) the hand holds; grasping: (side, object) the hand closes on, or
    (side, obstacle) it presses; placing: the object allowed to touch the table; approaching:
    (side, object) the open hand moves onto to grasp; pushing: (side, object) the hand slides;
    support: the feet meant to stand still where they touch the floor (a step's stance foot;
    None: every foot).
    """

    carried: tuple[str, str] | None = None
    grasping: tuple[str, str] | None = None
    placing: str | None = None
    approaching: tuple[str, str] | None = None
    pushing: tuple[str, str] | None = None
    support: tuple[str, ...] | None = None


class Check(Protocol):
    """One family of verdicts, looked at after a physics step.

    ``set_phase`` is told each new phase (after the detector validated it); ``check(t)``
    looks at the current state at simulation time ``t`` and returns a :class:`Failure`
    whose ``mode`` is a verdict of the failure-mode table, or None.
    """

    def set_phase(self, phase: Phase) -> None:
        """Take the behaviour's new phase into account."""

    def check(self, t: float) -> Failure | None:
        """The failure the current state shows, or None."""


def require_side(side: str, sides: Collection[str]) -> None:
    """Raise :class:`DetectorError` unless ``side`` is one of the robot's hand ``sides``."""
    if side not in sides:
        raise DetectorError(f"no hand side '{side}'; the robot has: {', '.join(sorted(sides))}")


def require_object(name: str, objects: Collection[str]) -> None:
    """Raise :class:`DetectorError` unless ``name`` is one of the scene's ``objects``."""
    if name not in objects:
        names = ", ".join(sorted(objects)) or "(none)"
        raise DetectorError(f"no object '{name}' in the scene; objects: {names}")
