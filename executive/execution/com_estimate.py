"""The robot's CoM as its controller can know it: its own model's, corrected by its feet's force sensors.

A robot computes its CoM from its model (the masses and centres of its links) and its measured
configuration (joint encoders; the base's pose and velocity from its IMU and leg odometry). A
model error moves the true CoM by an offset the robot does not know. Its feet's force sensors
measure the centre of pressure ``p`` under them, which the linear inverted pendulum ties to the
true CoM ``c`` (Kajita et al. 2003): ``c_ddot = omega^2 (c - p)``. :class:`CoMEstimate` takes the
model's CoM ``c_m`` in the measured configuration and estimates the model's error
``b = c - c_m`` (horizontal) from each control period's ``p + c_m_ddot / omega^2 - c_m``
(``c_m_ddot``: the model CoM's measured velocity differenced over the period), low-passed at
``rate * omega`` from zero (the model's CoM until the feet show otherwise).
The balance feedback (:class:`executive.execution.balance.AnkleBalance`) runs on it; see
docs/stepping.md ("What the balance measures").

:func:`foot_pressure` is a foot's force sensor: the normal force of its soles' floor contacts and
their centre of pressure.
"""

from __future__ import annotations

import math
from collections.abc import Collection

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.world.model import World

__all__ = ["CoMEstimate", "foot_pressure"]

FloatArray = NDArray[np.float64]


def foot_pressure(
    model: mujoco.MjModel, data: mujoco.MjData, soles: Collection[int], floor: int
) -> tuple[float, FloatArray]:
    """A foot's force sensor: the total normal force (N) of its sole geoms' floor contacts and their
    centre of pressure (world xy; the soles' contact points weighted by their normal forces).

    Args:
        model, data: the world's model and its current state (contacts).
        soles: the foot's sole geoms.
        floor: the floor geom.

    Returns:
        (force, centre of pressure); the centre is (0, 0) when the foot carries nothing.
    """
    wrench = np.zeros(6)
    total, moment = 0.0, np.zeros(2)
    for i in range(data.ncon):
        contact = data.contact[i]
        g1, g2 = int(contact.geom1), int(contact.geom2)
        if (g1 == floor and g2 in soles) or (g2 == floor and g1 in soles):
            mujoco.mj_contactForce(model, data, i, wrench)
            total += float(wrench[0])
            moment += float(wrench[0]) * contact.pos[:2]
    return total, (moment / total if total > 0.0 else moment)


class CoMEstimate:
    """The CoM of the robot's own model in its measured state, plus the error its feet's CoP shows.

    Args:
        world: the truth world (its state is what the robot measures; :meth:`World.own_model` is
            the model the robot knows itself by).
        rate: the model error's estimate follows its measurement at ``rate * omega`` (1/s).

    Attributes:
        bias: the estimated model error (m, world xy): the true CoM minus the model's.
    """

    def __init__(self, world: World, rate: float = 1.0) -> None:
        self.model = world.own_model()
        self._data = mujoco.MjData(self.model)
        self._truth = world.model
        self.base = world.ids.base_body
        self.floor = world.ids.floor_geom
        self.soles = {side: set(world.ids.foot_geoms[side]) for side in world.profile.feet}
        self.rate = rate
        self.bias = np.zeros(2)
        self._last: tuple[float, FloatArray] | None = None  # (time, the model CoM's velocity)

    def update(self, data: mujoco.MjData, omega: float) -> tuple[FloatArray, FloatArray]:
        """The CoM (world xyz) and its velocity (world xyz) as the robot estimates them now.

        Args:
            data: the robot's measured state (configuration, velocities, the feet's contacts).
            omega: the pendulum's rate ``sqrt(g / h)`` (1/s).

        Returns:
            The model's CoM plus :attr:`bias` (updated with this period's CoP), and the model
            CoM's velocity.
        """
        d = self._data
        d.qpos[:], d.qvel[:] = data.qpos, data.qvel
        mujoco.mj_kinematics(self.model, d)
        mujoco.mj_comPos(self.model, d)
        mujoco.mj_comVel(self.model, d)
        mujoco.mj_subtreeVel(self.model, d)
        com, velocity = d.subtree_com[self.base].copy(), d.subtree_linvel[self.base].copy()
        force, moment = 0.0, np.zeros(2)
        for side in self.soles:  # every foot's sensor: a foot touching down counts as it lands
            f, cop = foot_pressure(self._truth, data, self.soles[side], self.floor)
            force, moment = force + f, moment + f * cop
        if self._last is not None and data.time < self._last[0]:  # a new run: the model's CoM again
            self._last = None
            self.bias[:] = 0.0
        if force > 0.0 and self._last is not None and data.time > self._last[0]:
            dt = float(data.time) - self._last[0]
            accel = (velocity[:2] - self._last[1][:2]) / dt
            seen = moment / force + accel / omega**2 - com[:2]
            self.bias += (1.0 - math.exp(-self.rate * omega * dt)) * (seen - self.bias)
        self._last = (float(data.time), velocity)
        com[:2] += self.bias
        return com, velocity
