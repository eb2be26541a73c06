"""The capture point of a walking or standing robot, at one state and along a trajectory.

Capture point (Pratt et al. 2006; Koolen et al. 2012, IJRR 31(9)): xi = c + c_dot / omega,
omega = sqrt(g / h), h the CoM height above the ground. The fall model reports how far inside
the support polygon it stays. ``capture_point`` is re-exported by :mod:`executive.risk.fall`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["capture_point", "capture_points"]

FloatArray = NDArray[np.float64]


def capture_point(
    com: ArrayLike, com_velocity: ArrayLike, gravity: float = 9.81, ground_height: float = 0.0
) -> FloatArray:
    """Instantaneous capture point xi = c + c_dot / omega (xy), omega = sqrt(g / h), h = c_z - ground."""
    c = np.asarray(com, dtype=float).reshape(3)
    cd = np.asarray(com_velocity, dtype=float).reshape(-1)
    height = float(c[2] - ground_height)
    if gravity <= 0.0 or height <= 0.0:
        raise ValueError(
            f"capture_point: need g > 0 and the CoM above the ground, got g={gravity}, h={height}"
        )
    omega = float(np.sqrt(gravity / height))
    return np.asarray(c[:2] + cd[:2] / omega, dtype=float)


def capture_points(coms: FloatArray, times: FloatArray, gravity: float, ground: float) -> FloatArray:
    """Capture point (K, 2) at each knot of a CoM path ``coms`` (K, 3) at ``times`` (K,).

    The CoM velocity by finite differences (zero for one knot); ``ground`` the floor's height (m).

    Raises:
        ValueError: ``gravity`` not above 0, or a CoM not above the ground.
    """
    velocity = np.asarray(np.gradient(coms, times, axis=0)) if len(times) >= 2 else np.zeros_like(coms)
    height = coms[:, 2] - ground
    if gravity <= 0.0 or np.any(height <= 0.0):
        raise ValueError(
            f"capture_point: need g > 0 and the CoM above the ground, got g={gravity}, "
            f"h={float(np.min(height))}"
        )
    return np.asarray(coms[:, :2] + velocity[:, :2] / np.sqrt(gravity / height)[:, None], dtype=float)
