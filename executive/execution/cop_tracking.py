"""The stance ankle's torque control from its foot's force sensor: the measured CoP driven to the command.

A position servo turns a target offset into a torque only as far as its joint stays where it is;
on a leg whose joints give under the load the centre of pressure a balance law commands is not the
one the foot presses, and on one foot the difference stands as a CoM error. :class:`CoPTracking`
closes the loop on the foot's force sensor (the damping control of position-controlled humanoids,
Kajita et al. 2010): on one foot each ankle hinge's target offset integrates the moment error
``F (p_cmd - p)`` (``F``, ``p``: the foot's measured normal force and centre of pressure,
:func:`executive.execution.com_estimate.foot_pressure`; ``p_cmd`` clipped to the sole) over its
servo gain at ``rate * omega``, bounded by the hinge's CoP authority (the servo angle for the
whole weight's CoP at the sole's edge, :func:`executive.planning.stepping_ankles.balance_reserves`);
on two feet the offsets decay at the same rate. :class:`executive.execution.balance.AnkleBalance`
runs it under its capture-point law.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.execution.com_estimate import foot_pressure
from executive.planning.limits import SupportPolygon
from executive.planning.stepping_ankles import balance_reserves, find_ankles
from executive.world.model import World

__all__ = ["CoPTracking", "clip_to"]

FloatArray = NDArray[np.float64]


def clip_to(polygon: SupportPolygon, point: FloatArray) -> FloatArray:
    """``point`` (xy) if inside ``polygon``, else where the segment from its centre to it leaves it."""
    centre = polygon.centre
    out = np.asarray(point, dtype=float)[:2] - centre
    reach = polygon.normals @ out
    slack = polygon.offsets - polygon.normals @ centre
    scale = min([1.0] + [float(s / r) for s, r in zip(slack, reach, strict=True) if r > s])
    return np.asarray(centre + scale * out, dtype=float)


class CoPTracking:
    """Integral CoP control on the stance foot's ankle hinges (target offsets, rad).

    Args:
        world: the truth world (the model the servos act in, the feet's soles and the floor).
        ankles: side -> (offset index, joint id) of each foot's ankle hinges.
        kp: each offset's servo gain (N m/rad), in the order of the offsets.
        rate: the moment error's integration rate over ``omega``.

    Attributes:
        offsets: the integrated target offsets (rad), one per servo of the balance.
        bound: joint id -> the largest offset (rad) of each ankle hinge.
    """

    def __init__(
        self,
        world: World,
        ankles: Mapping[str, Sequence[tuple[int, int]]],
        kp: FloatArray,
        rate: float,
    ) -> None:
        self.model = world.model
        self.floor = world.ids.floor_geom
        self.soles = {side: list(world.ids.foot_geoms[side]) for side in ankles}
        self._sole_sets = {side: set(geoms) for side, geoms in self.soles.items()}
        self.ankles = {side: list(hinges) for side, hinges in ankles.items()}
        self.kp = np.asarray(kp, dtype=float)
        self.rate = rate
        self.offsets = np.zeros(len(self.kp))
        feet = {side: int(self.model.body(world.profile.feet[side].body).id) for side in ankles}
        found = find_ankles(
            self.model, world.profile.leg_joints, feet, [j for h in ankles.values() for _, j in h]
        )
        data = mujoco.MjData(self.model)
        data.qpos[:] = world.home_qpos()
        mujoco.mj_kinematics(self.model, data)
        self.bound = balance_reserves(self.model, data, found, feet, {}, self.soles, world.ids.base_body, 0.0)

    def reset(self) -> None:
        """Start from zero offsets (a new run)."""
        self.offsets[:] = 0.0

    def update(
        self, data: mujoco.MjData, stance: str | None, command: FloatArray | None, omega: float, dt: float
    ) -> FloatArray:
        """This period's offsets: on one foot (``stance``) integrated towards the commanded CoP
        ``command`` (world xy), on two (``stance`` None) decayed.

        Args:
            data: the robot's measured state (the foot's contacts, its hinges' axes).
            stance: the foot on the floor, or None on two feet.
            command: the CoP the balance law commands (world xy; ignored on two feet).
            omega: the pendulum's rate (1/s).
            dt: the control period (s).

        Returns:
            :attr:`offsets`.
        """
        step = 1.0 - math.exp(-self.rate * omega * dt)
        if stance is None or command is None:
            self.offsets *= 1.0 - step
            return self.offsets
        force, cop = foot_pressure(self.model, data, self._sole_sets[stance], self.floor)
        if force <= 0.0:
            return self.offsets
        sole = SupportPolygon.from_feet(self.model, data, self.soles[stance])
        error = force * (clip_to(sole, command) - cop)
        moment = np.array([-error[1], error[0], 0.0])
        for index, joint in self.ankles[stance]:
            bound = self.bound.get(joint, 0.0)
            change = step * float(data.xaxis[joint] @ moment) / self.kp[index]
            self.offsets[index] = float(np.clip(self.offsets[index] + change, -bound, bound))
        return self.offsets
