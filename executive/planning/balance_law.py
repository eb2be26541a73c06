"""The stepping balance feedback's law in numbers: its gains, its pelvis shift, what it leaves of a CoM error.

:class:`BalanceGains` are the dimensionless gains of the ankle balance a stepping behaviour runs
(:class:`executive.execution.balance.AnkleBalance`): rates over the linear inverted pendulum's
``omega = sqrt(g / h)`` (Kajita et al. 2003). The fall model reads the same numbers to know what
the loop leaves of a CoM model error ``e`` (the truth's CoM off the robot's model):

* on two feet the robot's CoM estimate learns ``e`` from its feet's CoP at ``c = estimate_rate *
  omega`` (from zero), and the pelvis shift integrates the estimated error at ``integral * omega``,
  moving the CoM by ``beta`` per metre of shift (:func:`shift_com_ratio`): two first-order lags in
  series, whose remaining error after ``tau`` seconds on two feet is ``r(tau) e`` with
  ``r = (c exp(-a tau) - a exp(-c tau)) / (c - a)``, ``a = beta * integral * omega``
  (:func:`residual_fractions`; on one foot the shift is held and ``r`` with it);
* the law moves the centre of pressure by ``(1 + convergence) (xi - xi_plan)`` (the DCM law,
  Englsberger et al. 2015): on one foot the CoP it asks for a CoM error ``r e`` at rest is
  ``(1 + convergence) r e`` from the planned CoM (:data:`BalanceGains.cop_gain`).

:func:`pelvis_shift_offsets` are the legs' joint offsets that move every foot by a shift relative
to the pelvis (damped least squares through each leg's Jacobian, the foot's orientation kept), as
the balance applies them. Measurements: docs/stepping.md ("Falls").
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["STEPPING_GAINS", "BalanceGains", "pelvis_shift_offsets", "residual_fractions", "shift_com_ratio"]

FloatArray = NDArray[np.float64]

#: The damping (m^2) of the legs' least-squares pelvis shift: a straight knee is singular.
SHIFT_DAMPING = 1e-4


@dataclass(frozen=True)
class BalanceGains:
    """The balance feedback's gains, each a rate (or gain) over ``omega``; the same for every robot.

    Attributes:
        convergence: the capture point error's decay rate over ``omega`` (1: the pendulum's own).
        integral: the rate over ``omega`` at which the CoM error on two feet shifts the pelvis.
        estimate_rate: the rate over ``omega`` at which the CoM estimate follows the model error
            its feet's CoP shows.
        cop_rate: the rate over ``omega`` at which the stance ankle integrates its CoP error.
    """

    convergence: float = 1.0
    integral: float = 0.25
    estimate_rate: float = 1.0
    cop_rate: float = 1.0

    @property
    def cop_gain(self) -> float:
        """The CoP the law asks per metre of capture point error: ``1 + convergence``."""
        return 1.0 + self.convergence


#: The gains the stepping behaviours' balance runs with (:class:`~executive.execution.balance.AnkleBalance`'s
#: defaults), which the fall model reads.
STEPPING_GAINS = BalanceGains()


def residual_fractions(
    times: FloatArray,
    phases: Sequence[tuple[float, float, bool]],
    omega: float,
    gains: BalanceGains,
    beta: float,
) -> FloatArray:
    """The fraction ``r`` of a CoM model error the balance leaves at each of ``times`` (module doc).

    Args:
        times: the query times (s, the phases' clock).
        phases: (start, end, on two feet) of the balance's phases in order, the first starting
            where the balance starts (the estimate and the shift at zero); times before the first
            start get 1, times after the last end the last phase's end value.
        omega: the pendulum's rate ``sqrt(g / h)`` (1/s).
        gains: the balance's gains.
        beta: the CoM's motion over the feet per metre of pelvis shift.

    Returns:
        ``r`` per time, in (0, 1].
    """
    a, c = beta * gains.integral * omega, gains.estimate_rate * omega
    times = np.asarray(times, dtype=float)
    out = np.ones(len(times))
    if not phases:
        return out
    t0, w = phases[0][0], 1.0
    for start, end, two_feet in phases:
        inside = (times > start) & (times <= end) if start > t0 else (times >= start) & (times <= end)
        out[inside] = _evolve(w, times[inside] - start, start - t0, a, c) if two_feet else w
        if two_feet:
            w = float(_evolve(w, np.array([end - start]), start - t0, a, c)[0])
    out[times > phases[-1][1]] = w
    return out


def _evolve(w0: float, elapsed: FloatArray, since: float, a: float, c: float) -> FloatArray:
    """The remaining error ``w`` after ``elapsed`` s on two feet from ``w0``, the estimate having run
    ``since`` s: ``w' = -a w + a exp(-c t)`` (the estimate's error ``exp(-c t)``), solved exactly."""
    lag = a * math.exp(-c * since)
    if abs(a - c) < 1e-9:
        return np.asarray((w0 + lag * elapsed) * np.exp(-a * elapsed), dtype=float)
    return np.asarray(
        w0 * np.exp(-a * elapsed) + lag * (np.exp(-c * elapsed) - np.exp(-a * elapsed)) / (a - c)
    )


def pelvis_shift_offsets(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    legs: Mapping[int, Sequence[int]],
    shift: FloatArray,
    jac: FloatArray | None = None,
) -> dict[int, FloatArray]:
    """Per foot body, its leg's joint offsets that move the foot by ``shift`` (xy, m) relative to the
    pelvis, its orientation kept: damped least squares through the leg's Jacobian in ``data``
    (its kinematics and ``mj_comPos`` done).

    Args:
        model, data: the model and the configuration the offsets are taken at.
        legs: foot body -> the dof addresses of its leg's joints.
        shift: the feet's move relative to the pelvis (world xy, m).
        jac: a (6, nv) scratch array (allocated when None).

    Returns:
        Foot body -> the offsets (rad), one per dof of ``legs[body]``.
    """
    jac = np.zeros((6, model.nv)) if jac is None else jac
    goal = np.array([shift[0], shift[1], 0.0, 0.0, 0.0, 0.0])
    out = {}
    for body, dofs in legs.items():
        mujoco.mj_jacBody(model, data, jac[:3], jac[3:], body)
        leg = jac[:, list(dofs)]
        out[body] = leg.T @ np.linalg.solve(leg @ leg.T + SHIFT_DAMPING * np.eye(6), goal)
    return out


def shift_com_ratio(
    model: mujoco.MjModel, qpos: FloatArray, base: int, legs: Mapping[int, Sequence[int]], step: float = 0.01
) -> float:
    """How far the CoM moves over the feet per metre the balance shifts the pelvis, at ``qpos``.

    The legs' offsets of :func:`pelvis_shift_offsets` for a ``step`` (m) shift, along x and along
    y, applied to ``qpos``; the CoM's move relative to the feet's mean over the shift, averaged
    over the two axes (the legs carry part of the mass along: below 1).

    Args:
        model: the robot's model; qpos: its configuration; base: the robot's base body.
        legs: foot body -> the dof addresses of its leg's joints (hinges: dof = qpos offset).
        step: the trial shift (m).
    """
    data = mujoco.MjData(model)

    def com_over_feet(q: FloatArray) -> FloatArray:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        feet = np.mean([data.xpos[b][:2] for b in legs], axis=0)
        return np.asarray(data.subtree_com[base][:2] - feet, dtype=float)

    start = com_over_feet(qpos)
    ratios = []
    for axis in range(2):
        shift = np.zeros(2)
        shift[axis] = step
        com_over_feet(qpos)
        q = np.array(qpos, dtype=float)
        for body, offsets in pelvis_shift_offsets(model, data, legs, shift).items():
            for dof, delta in zip(legs[body], offsets, strict=True):
                q[model.jnt_qposadr[model.dof_jntid[dof]]] += delta
        ratios.append(float(start[axis] - com_over_feet(q)[axis]) / step)
    return float(np.mean(ratios))
