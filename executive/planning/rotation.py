"""Rotations between two unit quaternions (wxyz), computed as mink computes them.

:func:`rotation_log` is mink's ``(SO3(a).inverse() @ SO3(b)).log()`` and :func:`rotation_angle` its
norm, with MuJoCo's quaternion routines; the planner steers and measures its hands with them.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["relative_quat", "rotation_angle", "rotation_log"]

FloatArray = NDArray[np.float64]


def relative_quat(a: FloatArray, b: FloatArray) -> FloatArray:
    """a^-1 b of two unit quaternions, sign-fixed to w >= 0 as mink's SO3.log does.

    Args:
        a: the first orientation (wxyz).
        b: the second orientation (wxyz).

    Returns:
        The rotation from a to b (wxyz, w >= 0).
    """
    inverse, out = np.empty(4), np.empty(4)
    mujoco.mju_negQuat(inverse, a)
    mujoco.mju_mulQuat(out, inverse, b)
    return out * np.sign(out[0])


def rotation_log(a: FloatArray, b: FloatArray) -> FloatArray:
    """``(SO3(a).inverse() @ SO3(b)).log()`` of mink: the rotation vector from a to b.

    Args:
        a: the first orientation (wxyz).
        b: the second orientation (wxyz).

    Returns:
        The rotation vector (3,), in a's frame; zero when a and b (nearly) coincide.
    """
    q = relative_quat(a, b)
    v = q[1:].copy()
    norm = mujoco.mju_normalize3(v)
    if norm < 1e-10:  # mink's epsilon for float64
        return np.zeros(3)
    return np.asarray(2.0 * math.atan2(norm, float(q[0])) * v, dtype=float)


def rotation_angle(a: FloatArray, b: FloatArray) -> float:
    """The norm of :func:`rotation_log`: the angle (rad) between the two orientations.

    Args:
        a: the first orientation (wxyz).
        b: the second orientation (wxyz).

    Returns:
        The angle in [0, pi] (rad).
    """
    q = relative_quat(a, b)
    norm = math.sqrt(float(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))
    if norm < 1e-10:
        return 0.0
    return 2.0 * math.atan2(norm, float(q[0]))
