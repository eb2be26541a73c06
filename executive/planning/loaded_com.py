"""The CoM a robot balances while a hand carries an object: the robot's and the object's together.

An object in the hand weighs on the robot: robot and object topple together, so the support
polygon must hold their common centre of mass ``(M c + m x) / (M + m)`` (``M``, ``c``: the
robot's mass and CoM; ``m``, ``x``: the object's mass and CoM). In the world's model the object is
a free body of its own (not in the robot's subtree, which ``mj_comPos`` and mink's ``ComTask``
take), moved with its hand by the planner (:func:`executive.planning.types.attach_object`), so
the object's CoM moves with the hand's body: its Jacobian is the hand body's at that point.
:class:`LoadedCoM` gives the common CoM and its Jacobian (the robot's alone when nothing is
carried, the same numbers as ``subtree_com`` and ``mj_jacSubtreeCom``); :class:`LoadedComTask`
is mink's CoM task on it.
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.world.model import World

__all__ = ["LoadedCoM", "LoadedComTask"]

FloatArray = NDArray[np.float64]


class LoadedCoM:
    """The CoM of the robot and the object a hand carries (if any), and its Jacobian.

    Args:
        world: the world (its model: the robot's base, hand sites and objects).
        carried: (hand side, object name) of the object a hand carries, or None (the robot alone).

    Attributes:
        mass: the robot's mass plus the carried object's (kg).
        load: the carried object's body id, or -1.
    """

    def __init__(self, world: World, carried: tuple[str, str] | None = None) -> None:
        model, ids = world.model, world.ids
        self.model = model
        self.base = ids.base_body
        self.robot_mass = float(model.body_subtreemass[self.base])
        self.load, self.hand, self.load_mass = -1, -1, 0.0
        if carried is not None:
            side, name = carried
            self.load = int(ids.object_bodies[name])
            self.hand = int(model.site_bodyid[ids.hand_sites[side]])
            self.load_mass = float(model.body_mass[self.load])
        self.mass = self.robot_mass + self.load_mass
        self._jac = np.zeros((3, model.nv))

    def position(self, data: mujoco.MjData) -> FloatArray:
        """The common CoM (world xyz) in ``data`` (its kinematics and ``mj_comPos`` done)."""
        com = np.array(data.subtree_com[self.base], dtype=float)
        if self.load < 0:
            return com
        return (self.robot_mass * com + self.load_mass * data.xipos[self.load]) / self.mass

    def jacobian(self, data: mujoco.MjData, out: FloatArray) -> FloatArray:
        """The common CoM's Jacobian (3, nv) in ``data`` (its kinematics and ``mj_comPos`` done),
        written into ``out``: the robot's ``mj_jacSubtreeCom`` and the hand's Jacobian at the
        object's CoM, weighted by their masses."""
        mujoco.mj_jacSubtreeCom(self.model, data, out, self.base)
        if self.load < 0:
            return out
        mujoco.mj_jac(self.model, data, self._jac, None, data.xipos[self.load], self.hand)
        out *= self.robot_mass / self.mass
        out += (self.load_mass / self.mass) * self._jac
        return out


class LoadedComTask(mink.ComTask):
    """mink's ``ComTask`` on the common CoM of :class:`LoadedCoM` (the robot alone: mink's own,
    which takes body 1's subtree: the robot's base must be body 1)."""

    def __init__(self, com: LoadedCoM, cost: FloatArray | list[float], gain: float = 1.0) -> None:
        super().__init__(cost=cost, gain=gain)
        self.loaded = com
        self._buffer = np.zeros((3, com.model.nv))

    def compute_error(self, configuration: mink.Configuration) -> FloatArray:
        if self.loaded.load < 0:
            return np.asarray(super().compute_error(configuration), dtype=float)
        if self.target_com is None:
            raise mink.exceptions.TargetNotSet(self.__class__.__name__)
        return np.asarray(self.loaded.position(configuration.data) - self.target_com, dtype=float)

    def compute_jacobian(self, configuration: mink.Configuration) -> FloatArray:
        if self.loaded.load < 0:
            return np.asarray(super().compute_jacobian(configuration), dtype=float)
        return np.array(self.loaded.jacobian(configuration.data, self._buffer))
