"""The stance leg's servo compliance in single support: a CoM error grows as the robot stands on one foot.

On two feet the legs form a closed chain and a CoM error e stays e. On one foot the stance
ankle's position servo (stiffness k, N m/rad) is all that holds the body up: the error's
gravity moment m g e bends it by theta, which moves the CoM further (by h theta), until
k theta = m g (e + h theta): theta_s = m g e / (k - m g h), and the centre of pressure, at
k theta / (m g) from the ankle, is at A e with A = 1 / (1 - m g h / k) (gravity's toppling
stiffness m g h against the servo's k). The load comes onto the one foot at the lift as a step,
and an undamped second-order system's step response peaks at twice its static deflection:
theta = 2 theta_s, so the centre of pressure peaks at 2 A e (the CoM at (2 A - 1) e). The sole
must hold the centre of pressure, so the fall model takes the persistent CoM bias e through the
gain G = 2 A at every single-support knot (:func:`single_support_gain`): e must lie in
(P_k - mu_k) / G_k (:func:`shrink_polygons`). A robot whose ankle is no stiffer than m g h
cannot stand on one foot at all (G infinite: the polygon shrinks to the planned CoM).
Measurements: docs/stepping.md, "Falls".
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.fall_batch import KnotPolygons
from executive.world.model import World

__all__ = ["ankle_stiffness", "shrink_polygons", "single_support_gain"]

FloatArray = NDArray[np.float64]

#: The largest gain used (an ankle no stiffer than gravity's toppling stiffness).
GAIN_CAP = 1e6


def ankle_stiffness(world: World, side: str) -> float:
    """The softer of the ankle servos' stiffnesses (N m/rad) of foot ``side``: the first two hinge
    joints above its sole, their position actuators' kp; inf when none is servoed."""
    model = world.model
    body = int(model.geom_bodyid[world.ids.foot_geoms[side][0]])
    hinges: list[int] = []
    while body > 0 and len(hinges) < 2:
        start, count = int(model.body_jntadr[body]), int(model.body_jntnum[body])
        hinges += [j for j in range(start, start + count) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        body = int(model.body_parentid[body])
    kps = [
        float(model.actuator_gainprm[a, 0])
        for a in range(model.nu)
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
        and int(model.actuator_trnid[a, 0]) in hinges[:2]
    ]
    return min(kps) if kps else float("inf")


def single_support_gain(mass: float, gravity: float, height: FloatArray, stiffness: float) -> FloatArray:
    """Peak centre-of-pressure shift per unit CoM bias on one foot: 2 A, A = 1 / (1 - m g h / k) (module doc).

    Args:
        mass: the robot's mass (kg); gravity: g (m/s^2); height: the CoM height(s) above the sole (m).
        stiffness: the stance ankle's servo stiffness k (N m/rad).

    Returns:
        The gain per height, at least 2; :data:`GAIN_CAP` once m g h >= k.
    """
    toppling = mass * gravity * np.asarray(height, dtype=float) / stiffness
    with np.errstate(divide="ignore"):
        static = np.where(toppling < 1.0, 1.0 / np.maximum(1.0 - toppling, 1e-12), np.inf)
    return np.asarray(np.minimum(2.0 * static, GAIN_CAP), dtype=float)


def shrink_polygons(polygons: KnotPolygons, mus: FloatArray, gains: FloatArray) -> KnotPolygons:
    """Each knot's polygon shrunk about its planned support point: mu_k + (P_k - mu_k) / G_k.

    A bias e keeps mu_k + G_k e inside P_k iff mu_k + e is inside the shrunk polygon, so the
    fall model's Gaussian and persistent-bias probabilities apply unchanged. Knots with gain 1
    keep their vertices as they are.
    """
    groups = {}
    for m, (knots, verts) in polygons.groups.items():
        g = gains[knots][:, None, None]
        mu = mus[knots][:, None, :]
        groups[m] = (knots, np.where(g == 1.0, verts, mu + (verts - mu) / g))
    return KnotPolygons(groups)
