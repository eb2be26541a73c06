"""Via points over obstacles for a hand's straight-line move.

Differential IK with collision avoidance (mink's velocity dampers) slides along
an obstacle, but stops dead when the target lies straight behind it (the
obstacle's normal is parallel to the way to go: a saddle). Pick-and-place
planners lift over such obstacles; so does this helper: it sweeps the hand's
footprint (and that of a carried object) along the straight line from start to
target and, where that footprint overlaps an obstacle's footprint below the
obstacle's top, returns two via points at a clearance height, one before and
one after the obstacle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["Footprint", "footprint", "via_points"]

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
