"""The posture check: verdict ``fall`` when the robot leaves its safe posture.

The pelvis lower than the standing height minus ``pelvis_drop``, or the torso's z axis
tilted more than ``trunk_tilt_deg`` from vertical. Both limits default to the robot's safe
posture's (:mod:`executive.robot.posture`) plus its tolerance. A robot geom on the floor is
a fall too; the contact check sees it.
"""

from __future__ import annotations

import math

from executive.monitoring.detector_base import DetectorThresholds, Failure, Phase
from executive.robot.posture import standing_pelvis_height
from executive.world.model import World

__all__ = ["FallCheck"]


class FallCheck:
    """Verdict ``fall`` from the pelvis height and the trunk tilt (two floats when all is well).

    ``standing_height``: the standing keyframe's pelvis height (m) the drop is measured from;
    ``pelvis_drop`` (m) and ``trunk_tilt_deg``: the limits in force.
    """

    def __init__(self, world: World, thresholds: DetectorThresholds) -> None:
        m, d, ids = world.model, world.data, world.ids
        th = thresholds
        self._m = m
        self._xpos, self._xmat = d.xpos, d.xmat
        self._base, self._torso = ids.base_body, ids.torso_body
        posture = world.profile.safe_posture
        self.standing_height = standing_pelvis_height(m, ids.keyframe, ids.base_body)
        self.pelvis_drop = th.pelvis_drop if th.pelvis_drop is not None else posture.fall_pelvis_drop
        self.trunk_tilt_deg = th.trunk_tilt_deg if th.trunk_tilt_deg is not None else posture.fall_tilt_deg
        self._min_height = self.standing_height - self.pelvis_drop
        self._min_cos_tilt = math.cos(math.radians(self.trunk_tilt_deg))

    def set_phase(self, phase: Phase) -> None:
        """Nothing depends on the phase."""

    def check(self, t: float) -> Failure | None:
        """A ``fall`` failure naming the pelvis (too low) or the torso (tilted), or None."""
        z = float(self._xpos[self._base, 2])
        cos_tilt = float(self._xmat[self._torso, 8])
        if z >= self._min_height and cos_tilt >= self._min_cos_tilt:
            return None
        m = self._m
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, cos_tilt))))
        base, torso = str(m.body(self._base).name), str(m.body(self._torso).name)
        state = (
            f"{base} at {z:.3f} m ({self.standing_height - z:.3f} m below standing "
            f"{self.standing_height:.3f} m, limit {self.pelvis_drop:.3f} m), {torso} tilted {tilt:.1f} deg "
            f"from vertical (limit {self.trunk_tilt_deg:.1f} deg)"
        )
        if z < self._min_height:
            return Failure("fall", f"fall: {base} dropped: {state} at t={t:.3f} s", t, (base,))
        return Failure("fall", f"fall: {torso} tilted: {state} at t={t:.3f} s", t, (torso,))
