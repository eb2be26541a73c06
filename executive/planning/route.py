"""A hand's way to its target: via points over obstacles, and the lead of its task along the way.

Differential IK with collision avoidance (mink's velocity dampers) slides along
an obstacle, but stops dead when the target lies straight behind it (the
obstacle's normal is parallel to the way to go: a saddle). Pick-and-place
planners lift over such obstacles; so does this helper: it sweeps the hand's
footprint (and that of a carried object) along the straight line from start to
target and, where that footprint overlaps an obstacle's footprint below the
obstacle's top, returns two via points at a clearance height, one before and
one after the obstacle. :func:`hand_routes` gives each moving hand its route (the via points,
then the target); :func:`lead` points each hand's task a bounded step ahead along it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.rotation import rotation_log
from executive.planning.types import HandTarget, PlannerConfig, se3, site_quat
from executive.world.model import WorldIds

__all__ = ["Footprint", "footprint", "hand_routes", "lead", "via_points", "world_box"]

FloatArray = NDArray[np.float64]

_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)


@dataclass(frozen=True)
class Footprint:
    """Extent of the moving geoms about the hand site, world-aligned: lo/hi offsets (m)."""

    lo: FloatArray  # (3,) most negative offsets (x, y, z) of any corner from the site
    hi: FloatArray  # (3,)


def _corners(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> FloatArray:
    # geom_aabb: local bounding box (centre, half sizes) of the geom.
    centre, half = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]
    rot = data.geom_xmat[geom].reshape(3, 3)
    return np.asarray(data.geom_xpos[geom] + (centre + _SIGNS * half) @ rot.T, dtype=float)


def world_box(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> tuple[FloatArray, FloatArray]:
    """World-aligned bounding box (lo, hi) of a geom."""
    corners = _corners(model, data, geom)
    return corners.min(axis=0), corners.max(axis=0)


def footprint(model: mujoco.MjModel, data: mujoco.MjData, site: int, geoms: Sequence[int]) -> Footprint:
    """World-aligned extent of ``geoms`` about the site (at the current pose)."""
    corners = np.vstack([_corners(model, data, g) for g in geoms]) - data.site_xpos[site]
    return Footprint(corners.min(axis=0), corners.max(axis=0))


def _hits(
    points: FloatArray, extent: Footprint, lo: FloatArray, hi: FloatArray, clearance: float
) -> NDArray[np.bool_]:
    """Which of ``points`` put the footprint within ``clearance`` of the box (lo, hi), not wholly under it."""
    over_x = (points[:, 0] + extent.hi[0] > lo[0] - clearance) & (
        points[:, 0] + extent.lo[0] < hi[0] + clearance
    )
    over_y = (points[:, 1] + extent.hi[1] > lo[1] - clearance) & (
        points[:, 1] + extent.lo[1] < hi[1] + clearance
    )
    below = points[:, 2] + extent.lo[2] < hi[2] + clearance
    under = points[:, 2] + extent.hi[2] > lo[2] - clearance  # not wholly above the hand
    return np.asarray(over_x & over_y & below & under)


def _segment(a: FloatArray, b: FloatArray, samples: int) -> FloatArray:
    u = np.linspace(0.0, 1.0, samples)
    return np.asarray(a[None, :] + u[:, None] * (b - a)[None, :], dtype=float)


def via_points(
    start: FloatArray,
    target: FloatArray,
    extent: Footprint,
    obstacles: Sequence[tuple[FloatArray, FloatArray]],
    clearance: float,
    samples: int = 40,
) -> list[FloatArray]:
    """Site positions to pass through (before ``target``) to clear ``obstacles`` (lo, hi boxes).

    An obstacle wholly above the footprint (a glovebox port's top rim, a lintel) is passed
    under, not over. Empty when the straight line is clear. Otherwise two points at the height
    where the footprint's bottom is ``clearance`` above the highest blocking
    top: above the last clear sample before the obstacle and the first clear
    sample after it (or above start/target when those are already over it). Empty too when
    that way over is itself blocked (the rim of an opening the hand passes through, with the
    wall above it): the hand then goes straight, sliding along what it meets.
    """
    points = _segment(start, target, samples)
    blocked = np.zeros(samples, dtype=bool)
    top = -np.inf
    for lo, hi in obstacles:
        hit = _hits(points, extent, lo, hi, clearance)
        if np.any(hit):
            blocked |= hit
            top = max(top, float(hi[2]))
    if not np.any(blocked):
        return []
    height = top + clearance - float(extent.lo[2])
    first, last = int(np.argmax(blocked)), samples - 1 - int(np.argmax(blocked[::-1]))
    before = points[max(first - 1, 0)].copy()
    after = points[min(last + 1, samples - 1)].copy()
    before[2] = max(before[2], height)
    after[2] = max(after[2], height)
    over = _segment(before, after, samples)
    # 1 um less: the lift height puts the footprint exactly at the clearance over the top.
    if any(np.any(_hits(over, extent, lo, hi, clearance - 1e-6)) for lo, hi in obstacles):
        return []
    return [before, after]


def hand_routes(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    ids: WorldIds,
    targets: Sequence[HandTarget],
    carried: tuple[str, str] | None,
    allowed: set[int],
    clearance: float,
    *,
    straight: bool = False,
) -> dict[str, list[mink.SE3]]:
    """Per moving hand: via points over the obstacles and objects in its way, then its target.

    The footprint is a world-aligned box about the hand and what it carries, so a hand turned
    across its way (a push's, the palm across the push) overlaps neighbours it does not touch.
    A contact motion (``straight``: a push's leg, whose hand must stay on the object's face) has
    no via points: its target alone, the collision limit keeping the arm clear.

    Args:
        model: the planner's model.
        data: its data at the move's start.
        ids: the world's indices.
        targets: one target per moving hand.
        carried: (hand side, object name) of a carried object, which moves with that hand.
        allowed: geoms the hands may touch (not in the way).
        clearance: the footprint's clearance above (or below) what it passes (m).
        straight: no via points (the straight line to each target).

    Returns:
        Each moving hand's goals (side -> poses), the target last.
    """
    carried_geom = ids.object_geoms[carried[1]] if carried else None
    blockers = [
        g
        for g in [*ids.obstacle_geoms.values(), *ids.object_geoms.values()]
        if g not in allowed and g != carried_geom
    ]
    boxes = [world_box(model, data, g) for g in blockers]
    routes: dict[str, list[mink.SE3]] = {}
    for t in targets:
        site = ids.hand_sites[t.side]
        moving = [g for g in ids.robot_geoms if int(model.geom_bodyid[g]) in ids.hand_bodies[t.side]]
        if carried is not None and carried[0] == t.side and carried_geom is not None:
            moving.append(carried_geom)
        extent = footprint(model, data, site, moving)
        start = data.site_xpos[site].copy()
        goal = np.asarray(t.position, dtype=float)
        vias = [] if straight else via_points(start, goal, extent, boxes, clearance)
        routes[t.side] = [se3(v, t.quat) for v in vias] + [se3(t.position, t.quat)]
    return routes


def lead(
    hands: Mapping[str, mink.FrameTask],
    data: mujoco.MjData,
    hand_sites: Mapping[str, int],
    goals: Mapping[str, mink.SE3],
    cfg: PlannerConfig,
) -> None:
    """Point each hand task at most ``lead_distance`` / ``lead_angle_rad`` ahead of the hand.

    The hand then follows the straight line (and the shortest rotation) to its goal,
    while the balance and posture tasks keep up, instead of lunging at a far goal
    with whatever joints are cheapest and curving back later.

    Args:
        hands: the hands' frame tasks by side; those in ``goals`` get a new target.
        data: the configuration's data (the hands' current poses).
        hand_sites: each hand's site id by side.
        goals: each moving hand's current goal by side.
        cfg: the planner's configuration (its lead distance and angle).
    """
    for side, goal in goals.items():
        site = hand_sites[side]
        position, quat = data.site_xpos[site], site_quat(data, site)
        delta = goal.wxyz_xyz[4:] - position
        turn = rotation_log(quat, goal.wxyz_xyz[:4])  # hand to goal, in the hand frame
        dist, ang = float(np.linalg.norm(delta)), float(np.linalg.norm(turn))
        alpha = min(1.0, cfg.lead_distance / max(dist, 1e-12), cfg.lead_angle_rad / max(ang, 1e-12))
        if alpha >= 1.0:
            hands[side].set_target(goal)
            continue
        # mink.SO3.exp and the product, with the same MuJoCo routines mink uses.
        axis = alpha * turn
        theta = mujoco.mju_normalize3(axis)
        step, rotation = np.empty(4), np.empty(4)
        mujoco.mju_axisAngle2Quat(step, axis, theta)
        mujoco.mju_mulQuat(rotation, quat, step)
        hands[side].set_target(mink.SE3(np.concatenate([rotation, position + alpha * delta])))
