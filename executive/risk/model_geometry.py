"""Geometry read off a MuJoCo model: how far a geom reaches, its points, where a hand site is.

Shared by the grasp, hold and hand models so that each measures geoms the same way.

Usage::

    w = 2.0 * half_extent(model, geom, np.array([0.0, 1.0, 0.0]))  # width along the geom's y
    corners = geom_corners(model, data, geom)                       # (8, 3) world
    position, rotation = site_pose_at(world, qpos, "left")
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = ["body_half_extent", "geom_corners", "geom_points", "half_extent", "site_pose_at"]

FloatArray = NDArray[np.float64]
#: The signs of a box's 8 corners about its centre, in units of its half sizes.
_CORNER_SIGNS = np.array([[i, j, k] for i in (-1.0, 1.0) for j in (-1.0, 1.0) for k in (-1.0, 1.0)])
_CORNER_SIGNS.flags.writeable = False


def half_extent(model: mujoco.MjModel, geom: int, axis_local: FloatArray) -> float:
    """Half the extent of a geom along a unit axis of its own frame (box, sphere, cylinder; else rbound)."""
    size = model.geom_size[geom]
    kind = int(model.geom_type[geom])
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return float(np.abs(axis_local) @ size)
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(size[0])
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:  # axis z, radius size[0], half length size[1]
        return float(size[0] * np.hypot(axis_local[0], axis_local[1]) + size[1] * abs(axis_local[2]))
    return float(model.geom_rbound[geom])


def body_half_extent(model: mujoco.MjModel, geom: int, axis_body: FloatArray) -> float:
    """Half the extent of a geom along a unit axis of its body's frame (see :func:`half_extent`)."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[geom])
    return half_extent(model, geom, rot.reshape(3, 3).T @ axis_body)


def geom_corners(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> FloatArray:
    """World corners (8, 3) of a geom's local bounding box (the box itself for a box geom)."""
    centre, half = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]
    rot = data.geom_xmat[geom].reshape(3, 3)
    return np.asarray(data.geom_xpos[geom] + (centre + _CORNER_SIGNS * half) @ rot.T, dtype=float)


def geom_points(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> FloatArray:
    """World positions (n, 3) of a geom's mesh vertices (its bounding box's corners for a primitive).

    MuJoCo stores a mesh's vertices in its geom's frame.
    """
    if model.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH:
        return geom_corners(model, data, geom)
    mesh = int(model.geom_dataid[geom])
    start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    local = np.asarray(model.mesh_vert[start : start + count], dtype=float)
    return np.asarray(data.geom_xpos[geom] + local @ data.geom_xmat[geom].reshape(3, 3).T, dtype=float)


def site_pose_at(world: World, qpos: FloatArray, side: str) -> tuple[FloatArray, FloatArray]:
    """The ``side`` hand site's position and rotation (world) in a configuration ``qpos``.

    Args:
        world: the world (its model; its data is left alone).
        qpos: (nq,) a full configuration.
        side: an arm of the profile.

    Returns:
        (position (3,), rotation (3, 3) with columns the site's x, y, z axes).
    """
    with scratch_data(world.model) as data:
        data.qpos[:] = qpos
        mujoco.mj_kinematics(world.model, data)
        site = world.ids.hand_sites[side]
        return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()
