"""The legs' knees, found from the model, and the limit that keeps them bent while stepping.

A straight knee is a singular point of a leg: there the foot cannot move along the leg's length
to first order (a robot standing with straight legs, as the Unitree G1's keyframe does, cannot
lift a foot by IK steps from it: bending the knee first lengthens a hyperextended leg).
:func:`find_knees` finds each leg's knee as the joint of the leg that changes the distance
between the leg's first joint and the foot the most (forward kinematics over the joint's range,
the other joints at the keyframe) and its straight angle as the one where that distance is
longest. :class:`KneeBendLimit` keeps each knee ``bend`` (rad) away from straight, towards the
side its range extends (the bending side).
"""

from __future__ import annotations

from dataclasses import dataclass

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["Knee", "KneeBendLimit", "find_knees"]

FloatArray = NDArray[np.float64]

#: A joint that changes its leg's length by less than this (m) over its range is no knee.
_MIN_SPAN = 0.01
#: Samples of a joint's range when looking for its straight angle.
_SAMPLES = 401


@dataclass(frozen=True)
class Knee:
    """A leg's knee: its joint's name, dof and qpos address, its straight angle (rad) and the
    side it bends to (+1: towards its upper limit, -1: towards its lower limit)."""

    joint: str
    dof: int
    qadr: int
    straight: float
    bends: float


def find_knees(
    model: mujoco.MjModel, home: FloatArray, legs: dict[str, tuple[str, ...]], feet: dict[str, int]
) -> dict[str, Knee]:
    """Each leg's knee (legs without one are left out).

    Args:
        model: the robot's model.
        home: the keyframe's qpos (the other joints stay there).
        legs: the legs' joint names by side, hip first.
        feet: the foot body of each side.

    Returns:
        The knee of each side that has one.
    """
    data = mujoco.MjData(model)
    knees: dict[str, Knee] = {}
    for side, names in legs.items():
        root = model.joint(names[0]).id
        best: tuple[float, Knee] | None = None
        for name in names:
            j = model.joint(name).id
            if not model.jnt_limited[j]:
                continue
            lower, upper = (float(v) for v in model.jnt_range[j])
            angles = np.linspace(lower, upper, _SAMPLES)
            lengths = np.empty(_SAMPLES)
            for i, angle in enumerate(angles):
                data.qpos[:] = home
                data.qpos[model.jnt_qposadr[j]] = angle
                mujoco.mj_kinematics(model, data)
                lengths[i] = np.linalg.norm(data.xpos[feet[side]] - data.xanchor[root])
            span = float(lengths.max() - lengths.min())
            if span < _MIN_SPAN or (best is not None and span <= best[0]):
                continue
            straight = float(angles[int(np.argmax(lengths))])
            bends = 1.0 if upper - straight >= straight - lower else -1.0
            knee = Knee(name, int(model.jnt_dofadr[j]), int(model.jnt_qposadr[j]), straight, bends)
            best = (span, knee)
        if best is not None:
            knees[side] = best[1]
    return knees


class KneeBendLimit(mink.Limit):
    """Each knee stays at least ``bend`` (rad) from straight, on its bending side.

    The velocity-damper row of a joint bound (as mink's ``ConfigurationLimit``): with ``s`` the
    knee's bend beyond ``bend`` (``bends (q - straight) - bend``), ``-bends dq <= gain s``. A knee
    inside the band (a straight-legged start) bends out at most ``recovery`` (rad) per step, as
    :class:`~executive.planning.limits.PelvisHeightLimit` rises back to its floor.

    Args:
        model: the robot's model.
        knees: the knees (:func:`find_knees`).
        bend: rad each knee keeps from straight.
        gain: the fraction of its slack a knee may close per step.
        recovery: rad a knee inside the band bends out per step at most.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        knees: dict[str, Knee],
        bend: float,
        gain: float = 0.5,
        recovery: float = 0.005,
    ) -> None:
        self.knees = list(knees.values())
        self.bend, self.gain, self.recovery = float(bend), float(gain), float(recovery)
        self.G = np.zeros((len(self.knees), model.nv))
        for row, knee in enumerate(self.knees):
            self.G[row, knee.dof] = -knee.bends

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a position limit, like mink's ConfigurationLimit
        q = configuration.q
        slack = np.array([k.bends * (q[k.qadr] - k.straight) - self.bend for k in self.knees])
        h = np.where(slack >= 0.0, self.gain * slack, -np.minimum(-self.gain * slack, self.recovery))
        return mink.Constraint(G=self.G, h=h)
