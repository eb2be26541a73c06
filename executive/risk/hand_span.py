"""A hand's span across its grasp site, measured on the model: for hands without slide jaws.

A dexterous hand (the Unitree G1's Dex3: a thumb against two fingers) has no jaw travel to
read off its actuators. Its opening is measured instead with MuJoCo forward kinematics at the
profile's gripper targets: the hand's joints are put where its position servos drive them,
and parallel rays from the site's region along the closing axis (+y of the site, thumb to
fingers) and against it find the nearest collision surface on each side
(``mj_rayMesh`` / ``mju_rayGeom``). The span is the sum of the two distances: the free
opening between the opposing contact surfaces. The finger depth is how far the hand's
collision geoms (their bounding boxes) reach past the site along its approach axis (z).

Usage::

    span = hand_span(world, "left")                 # open (the profile's open targets)
    closed = hand_span(world, "left", closed=True)  # the closed targets
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.model_geometry import geom_corners
from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = ["HandSpan", "hand_collision_geoms", "hand_span", "pose_hand", "posed_hand", "ray_to_hand"]

FloatArray = NDArray[np.float64]

#: m either side of the site, across the closing axis, that the opening is measured over (a pad's width).
FAN_HALF_WIDTH = 0.03


@dataclass(frozen=True)
class HandSpan:
    """A hand's geometry around its grasp site at one set of gripper targets (m).

    Attributes:
        opening: free span between the opposing surfaces along the site's closing axis (y),
            inf when nothing of the hand closes across the site.
        near: distance from the site to the surface along +y (the fingers' side).
        far: distance from the site to the surface along -y (the thumb's side).
        finger_depth: how far the hand reaches past its site along the approach (site z).
    """

    opening: float
    near: float
    far: float
    finger_depth: float


def hand_collision_geoms(world: World, side: str) -> list[int]:
    """The collision geoms of the ``side`` hand's subtree."""
    model = world.model
    bodies = set(world.ids.hand_bodies[side])
    return [
        g
        for g in range(model.ngeom)
        if int(model.geom_bodyid[g]) in bodies and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]


def posed_hand(world: World, side: str, targets: tuple[float, ...] | None = None) -> mujoco.MjData:
    """A scratch MjData at the home keyframe with the ``side`` gripper's joints at ``targets``.

    Args:
        world: the world whose robot has the hand.
        side: the arm.
        targets: one value per gripper actuator, driven into the joint it transmits to (position
            servos settle at their target); None keeps the keyframe's (the open hand).

    Returns:
        The data, with kinematics computed.
    """
    data = mujoco.MjData(world.model)
    pose_hand(world, side, targets, data)
    return data


def pose_hand(world: World, side: str, targets: tuple[float, ...] | None, data: mujoco.MjData) -> None:
    """Put ``data`` (of ``world.model``) at the home keyframe with the ``side`` gripper's joints
    at ``targets`` (None: the keyframe's) and compute its kinematics (see :func:`posed_hand`)."""
    model = world.model
    mujoco.mj_resetDataKeyframe(model, data, world.ids.keyframe)
    if targets is not None:
        for act, value in zip(world.ids.gripper_actuators[side], targets, strict=True):
            joint = int(model.actuator_trnid[act, 0])
            data.qpos[model.jnt_qposadr[joint]] = value
    mujoco.mj_kinematics(model, data)


def ray_to_hand(
    model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int], start: FloatArray, way: FloatArray
) -> float:
    """Distance from ``start`` along the unit vector ``way`` to the first of ``geoms`` (inf: none)."""
    best = np.inf
    for g in geoms:
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            hit = mujoco.mj_rayMesh(model, data, g, start, way)
        else:
            hit = mujoco.mju_rayGeom(
                data.geom_xpos[g], data.geom_xmat[g], model.geom_size[g], start, way, int(model.geom_type[g])
            )
        if hit >= 0.0:
            best = min(best, float(hit))
    return float(best)


def hand_span(world: World, side: str, *, closed: bool = False) -> HandSpan:
    """Measure the ``side`` hand at its profile's open (or closed) gripper targets.

    Args:
        world: the world whose robot has the hand.
        side: the arm ("left" or "right").
        closed: measure at the closed targets instead of the open ones.

    Returns:
        The :class:`HandSpan`. Open, the targets are the keyframe's (the world builder opens
        the hands there).
    """
    model = world.model
    grip = world.profile.arms[side].gripper
    targets = tuple(grip.closed) if closed else None
    with scratch_data(model) as data:
        pose_hand(world, side, targets, data)
        site = world.ids.hand_sites[side]
        origin = data.site_xpos[site].copy()
        frame = data.site_xmat[site].reshape(3, 3)
        closing, approach, lateral = frame[:, 1].copy(), frame[:, 2].copy(), frame[:, 0].copy()
        geoms = hand_collision_geoms(world, side)
        corners = np.vstack([geom_corners(model, data, g) for g in geoms])
        depth = max(float(np.max((corners - origin) @ approach)), 0.0)
        # Parallel rays through the region an object between the jaws fills: across the site's
        # lateral axis (x) and down its approach axis to the fingertips; each side's nearest hit.
        starts = [
            origin + a * lateral + b * approach
            for a in np.linspace(-FAN_HALF_WIDTH, FAN_HALF_WIDTH, 5)
            for b in np.linspace(0.0, depth, 3)
        ]
        near = min(ray_to_hand(model, data, geoms, p, closing) for p in starts)
        far = min(ray_to_hand(model, data, geoms, p, -closing) for p in starts)
    return HandSpan(opening=near + far, near=near, far=far, finger_depth=depth)
