"""Floor geometry of stepping: footholds of a configuration, a foot's pose over a foothold, and
the footholds of a goal stance (a pelvis pose on the floor).

Yaw is the heading about the world's vertical; a foothold keeps the foot as flat as it stood at
the start (its tilt is carried over, only the yaw changes).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.stepping_types import Foothold
from executive.world.heading import yaw_of, yaw_quat

__all__ = [
    "circular_mean",
    "foot_pose",
    "foothold_of",
    "stance_footholds",
    "stance_of",
    "stance_offsets",
]

FloatArray = NDArray[np.float64]


def circular_mean(a: float, b: float) -> float:
    """The mean of two angles (rad), the short way round."""
    return a + 0.5 * math.remainder(b - a, 2.0 * math.pi)


def foothold_of(data: mujoco.MjData, side: str, body: int) -> Foothold:
    """The foothold of the foot ``body`` (of side ``side``) in ``data``'s kinematics."""
    return Foothold(side, float(data.xpos[body][0]), float(data.xpos[body][1]), yaw_of(data.xquat[body]))


def foot_pose(start: mink.SE3, foothold: Foothold, lift: float = 0.0) -> mink.SE3:
    """The foot body's pose over ``foothold``, ``lift`` (m) above the floor.

    Args:
        start: the foot body's pose standing flat on the floor (its height and tilt are kept).
        foothold: where the foot goes (its origin's x, y and its yaw).
        lift: height (m) above its standing height.

    Returns:
        The pose: ``start``'s orientation turned about the vertical to the foothold's yaw, at
        the foothold's x, y and ``start``'s height plus ``lift``.
    """
    quat = start.wxyz_xyz[:4]
    turned = np.empty(4)
    mujoco.mju_mulQuat(turned, yaw_quat(foothold.yaw - yaw_of(quat)), quat)
    position = np.array([foothold.x, foothold.y, float(start.wxyz_xyz[6]) + lift])
    return mink.SE3(np.concatenate([turned / np.linalg.norm(turned), position]))


def stance_offsets(
    pelvis_xy: FloatArray, pelvis_yaw: float, footholds: Mapping[str, Foothold]
) -> dict[str, Foothold]:
    """Each foothold in the pelvis's floor frame (x forward, y left; yaw relative to the pelvis's).

    Args:
        pelvis_xy: the pelvis's position on the floor (m).
        pelvis_yaw: the pelvis's heading (rad).
        footholds: the feet's footholds (world), by side.

    Returns:
        The offsets, by side (as footholds in the pelvis's frame).
    """
    c, s = math.cos(pelvis_yaw), math.sin(pelvis_yaw)
    out = {}
    for side, f in footholds.items():
        dx, dy = f.x - float(pelvis_xy[0]), f.y - float(pelvis_xy[1])
        out[side] = Foothold(
            side, c * dx + s * dy, -s * dx + c * dy, math.remainder(f.yaw - pelvis_yaw, 2 * math.pi)
        )
    return out


def stance_footholds(x: float, y: float, yaw: float, offsets: Mapping[str, Foothold]) -> dict[str, Foothold]:
    """The footholds of a stance whose pelvis stands at (x, y) with heading ``yaw``.

    Args:
        x: the pelvis's x on the floor (m).
        y: its y (m).
        yaw: its heading (rad).
        offsets: each foot in the pelvis's floor frame (:func:`stance_offsets`).

    Returns:
        The footholds (world), by side.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    return {
        side: Foothold(
            side, x + c * o.x - s * o.y, y + s * o.x + c * o.y, math.remainder(yaw + o.yaw, 2 * math.pi)
        )
        for side, o in offsets.items()
    }


def stance_of(
    footholds: Mapping[str, Foothold], offsets: Mapping[str, Foothold]
) -> tuple[float, float, float]:
    """Where the pelvis stands over ``footholds`` (x, y (m), yaw (rad)) when the feet stand as
    ``offsets`` puts them about it: :func:`stance_footholds` inverted (the heading the feet's
    mean, the position their mean, each less its offset).

    Args:
        footholds: the feet's footholds (world), by side.
        offsets: each foot in the pelvis's floor frame (:func:`stance_offsets`), by side.

    Returns:
        The pelvis's x, y and heading.
    """
    sides = [side for side in footholds if side in offsets]
    turns = [math.remainder(footholds[side].yaw - offsets[side].yaw, 2 * math.pi) for side in sides]
    yaw = math.atan2(sum(math.sin(t) for t in turns), sum(math.cos(t) for t in turns))
    c, s = math.cos(yaw), math.sin(yaw)
    xs = [footholds[side].x - (c * offsets[side].x - s * offsets[side].y) for side in sides]
    ys = [footholds[side].y - (s * offsets[side].x + c * offsets[side].y) for side in sides]
    return sum(xs) / len(sides), sum(ys) / len(sides), yaw
