"""The collision model's broad phase: lower bounds on pair distances that spare coal calls.

:func:`sphere_box_bounds` bounds every pair of a layout at one or many configurations (robot
bounding sphere vs environment oriented box); :class:`TravelBound` adds, along a trajectory, the
bound from each pair's last coal distance less how far its geoms can have moved since.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision_setup import PairLayout

__all__ = ["TravelBound", "sphere_box_bounds"]

FloatArray = NDArray[np.float64]


class TravelBound:
    """Lower bounds on pair distances along a trajectory, every knot's computed up front.

    Two bounds per pair and knot, the larger wins: the broad phase's (robot bounding sphere vs
    environment oriented box, :func:`sphere_box_bounds`), and one from the pair's last
    coal distance ``d_j``: a rigid geom's points move by at most ``|dp| + r ||dR||_F`` between two
    knots (``p`` its frame origin, ``R`` its rotation, ``r`` its bounding radius ``geom_rbound``
    about that origin: ``|dR u| <= ||dR||_F |u|``), so with ``T`` the geoms' travel summed since
    knot j, ``d_k >= d_j - T_robot - T_env`` (triangle inequality), less ``slack`` for coal's
    tolerance.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        layout: PairLayout,
        xpos: FloatArray,
        xmat: FloatArray,
        slack: float = 1e-4,
    ) -> None:
        # xpos (K, E + R, 3) and xmat (K, E + R, 9): the environment geoms, then the robot geoms.
        n_env = len(layout.env)
        geoms = np.concatenate([layout.env, layout.robot])
        radius = np.asarray(model.geom_rbound[geoms], dtype=float)
        plane = np.asarray(model.geom_type[geoms] == int(mujoco.mjtGeom.mjGEOM_PLANE))
        dp, dm = np.diff(xpos, axis=0), np.diff(xmat, axis=0)
        step = np.sqrt(np.einsum("kgi,kgi->kg", dp, dp)) + radius * np.sqrt(np.einsum("kgi,kgi->kg", dm, dm))
        step = np.where(plane & (step > 0.0), np.inf, step)
        cum = np.concatenate([np.zeros((1, len(geoms))), np.cumsum(step, axis=0)])
        self.cum_e, self.cum_r = cum[:, :n_env], cum[:, n_env:]
        sphere = sphere_box_bounds(model, layout, xpos[:, n_env:], xpos[:, :n_env], xmat[:, :n_env])
        self.sphere = np.where(layout.mask, sphere, np.inf)  # excluded pairs: never a candidate
        self.slack = slack
        shape = (n_env, len(layout.robot))
        self.last = np.full(shape, -np.inf)  # distance at the pair's last coal query
        self.last_r = np.zeros(shape)  # cum_r of its robot geom then
        self.last_e = np.zeros(shape)  # cum_e of its environment geom then
        self.k = 0

    def bounds(self) -> FloatArray:
        """(E, R) lower bounds on every pair's distance at knot ``self.k`` (inf: pair excluded)."""
        k = self.k
        travel = (self.cum_r[k][None, :] - self.last_r) + (self.cum_e[k][:, None] - self.last_e)
        # fmax: a NaN (an unbounded travel less itself) leaves the broad-phase bound.
        return np.fmax(self.sphere[k], self.last - travel - self.slack)

    def record(self, ei: int, ri: int, distance: float) -> None:
        """Note that layout pair (env ei, robot ri) is ``distance`` apart at knot ``self.k``."""
        self.last[ei, ri] = distance
        self.last_r[ei, ri] = self.cum_r[self.k, ri]
        self.last_e[ei, ri] = self.cum_e[self.k, ei]


def sphere_box_bounds(
    model: mujoco.MjModel, layout: PairLayout, centres: FloatArray, pos: FloatArray, rot: FloatArray
) -> FloatArray:
    """(..., E, R) lower bounds: robot bounding spheres (centres (..., R, 3)) vs environment oriented
    boxes (``geom_aabb`` in frames pos (..., E, 3), rot (..., E, 9), world = rot @ local)."""
    rot = rot.reshape(*rot.shape[:-1], 3, 3)
    rel = centres[..., None, :, :] - pos[..., :, None, :]  # (..., E, R, 3)
    local = np.matmul(rel, rot)  # local_j = sum_i rel_i rot_ij, per environment geom
    aabb = model.geom_aabb[layout.env]  # (E, 6): centre, half sizes in the geom frame
    outside = np.maximum(np.abs(local - aabb[:, None, :3]) - aabb[:, None, 3:], 0.0)
    gap = np.sqrt(np.einsum("...j,...j->...", outside, outside)) - model.geom_rbound[layout.robot]
    return np.asarray(gap, dtype=float)
