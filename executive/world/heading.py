"""Headings about the world's vertical: the yaw of an orientation, and the rotation by a yaw.

Orientations are unit quaternions (w x y z), as MuJoCo stores them.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["yaw_of", "yaw_quat"]

FloatArray = NDArray[np.float64]


def yaw_of(quat: FloatArray) -> float:
    """The heading (rad) of an orientation: its z-y-x Euler yaw, its x axis's angle about the vertical."""
    w, x, y, z = (float(v) for v in quat)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def yaw_quat(yaw: float) -> FloatArray:
    """The rotation (w x y z) by ``yaw`` (rad) about the world's vertical."""
    return np.array([math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)])
