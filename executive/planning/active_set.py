"""What binds a stalled move: the active set of the IK step's QP, named.

When :class:`~executive.planning.ik_loop.IKLoop` gives up short of a hand's target,
:func:`active_limits` solves the step's QP once more where it stalled (the QP every step solves,
:meth:`~executive.planning.limits.JointBounds.step_qp`) and reads DAQP's Lagrange multipliers: a
constraint whose multiplier is not zero is active, it holds the step back. Each active one is named
as a :class:`~executive.planning.types.Binding` from the solver's own row: a collision pair at its
clearance (its geoms, their distance and required clearance), a joint at its range's bound or its
velocity limit, the pelvis at the safe posture's floor, the torso at its tilt limit, the CoM at the
support polygon's edge. None active: the tasks' costs balance short of the target (a local minimum
of the step's objective).
"""

from __future__ import annotations

import daqp  # type: ignore[import-not-found]  # no stubs; mink solves with it already (solver="daqp")
import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.limits import (
    GeomPairCollisionLimit,
    PelvisHeightLimit,
    SupportPolygonLimit,
    TiltLimit,
)
from executive.planning.problem import MoveQP, PlanningProblem
from executive.planning.types import Binding

__all__ = ["active_limits"]

FloatArray = NDArray[np.float64]

#: Order of the kinds in a report: what the hand meets first, then the robot's own limits.
_ORDER = ("collision", "joint_range", "joint_velocity", "ball_joint", "pelvis", "tilt", "balance")


def active_limits(
    problem: PlanningProblem, configuration: mink.Configuration, qp: MoveQP, dt: float, damping: float
) -> tuple[Binding, ...] | None:
    """The limits active in the IK step's QP at ``configuration`` (the move's tasks as set now).

    Args:
        problem: the world's IK problem (its joint bounds, posture limits, model).
        configuration: the configuration the move stalled at.
        qp: the move's QP (tasks, limits, constraints, the pairs' required clearance).
        dt: the IK step's time step (s).
        damping: the step's damping.

    Returns:
        The active limits, the collision pairs first, each kind by its multiplier (largest
        first); None when the QP has no solution there (nothing to read).
    """
    step = problem.joints.step_qp(configuration, qp.tasks, dt, damping, qp.limits, qp.constraints)
    _x, _cost, exitflag, info = daqp.solve(
        step.hessian, step.linear, step.matrix, step.upper, step.lower, step.sense
    )
    if exitflag <= 0:
        return None
    lam = np.asarray(info["lam"], dtype=float)
    n = len(problem.joints.free)
    out = _dof_bindings(problem, configuration.q, lam[:n], dt)
    rows = lam[n:]
    ball = step.spans[0][0] if step.spans else 0  # limited ball joints' rows come first
    if np.any(rows[:ball] != 0.0):
        out.append(Binding("ball_joint", "a ball joint", 0.0, 0.0))
    for limit, (start, stop) in zip(qp.limits, step.spans, strict=True):
        multipliers = rows[start:stop]
        if np.any(multipliers != 0.0):
            out += _limit_bindings(problem, configuration, qp, limit, multipliers)
    out.sort(key=lambda b: (_ORDER.index(b.kind), -b.multiplier))
    return tuple(out)


def _dof_bindings(problem: PlanningProblem, q: FloatArray, lam: FloatArray, dt: float) -> list[Binding]:
    """The free dofs at an active bound: the joint's range where the range's bound is the
    tighter one (DAQP: lam > 0 upper, < 0 lower), else its velocity limit."""
    joints, model = problem.joints, problem.model
    range_low, range_high = joints.bounds(q, dt, velocity=False)
    low, high = joints.bounds(q, dt)
    out = []
    for i in np.flatnonzero(lam != 0.0).tolist():
        upper = bool(lam[i] > 0.0)
        joint = int(model.dof_jntid[joints.free[i]])
        name = str(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, joint))
        qadr = int(model.jnt_qposadr[joint])
        side = "upper" if upper else "lower"
        if (range_high[i] <= high[i]) if upper else (range_low[i] >= low[i]):
            bound = float(model.jnt_range[joint, 1 if upper else 0])
            out.append(Binding("joint_range", name, float(q[qadr]), bound, side, abs(float(lam[i]))))
        else:
            rate = float(high[i] if upper else -low[i]) / dt
            out.append(Binding("joint_velocity", name, rate, rate, side, abs(float(lam[i]))))
    return out


def _limit_bindings(
    problem: PlanningProblem,
    configuration: mink.Configuration,
    qp: MoveQP,
    limit: mink.Limit,
    lam: FloatArray,
) -> list[Binding]:
    """The active rows of one limit of the move, named (``lam``: its rows' multipliers)."""
    data = configuration.data
    strength = float(np.max(np.abs(lam)))
    if isinstance(limit, GeomPairCollisionLimit):
        return _pair_bindings(problem, data, qp, limit, lam)
    if isinstance(limit, PelvisHeightLimit):
        drop = problem.standing_height - float(data.xpos[limit.body][2])
        largest = float(problem.posture_limits.max_pelvis_drop)
        return [Binding("pelvis", "pelvis", drop, largest, multiplier=strength)]
    if isinstance(limit, TiltLimit):
        tilt = float(np.degrees(np.arccos(np.clip(data.xmat[limit.body][8], -1.0, 1.0))))
        largest = float(np.degrees(np.arccos(limit.min_cos)))
        return [Binding("tilt", "torso", tilt, largest, multiplier=strength)]
    if isinstance(limit, SupportPolygonLimit):
        com = limit.loaded.position(data) if limit.loaded is not None else data.subtree_com[limit.body]
        margin = qp.polygon.margin(com[:2])
        return [Binding("balance", "CoM", margin, problem.config.support_margin, multiplier=strength)]
    return []


def _pair_bindings(
    problem: PlanningProblem,
    data: mujoco.MjData,
    qp: MoveQP,
    limit: GeomPairCollisionLimit,
    lam: FloatArray,
) -> list[Binding]:
    """The collision pairs whose rows are active: their geoms, distance and required clearance."""
    model = problem.model
    out = []
    for row in np.flatnonzero(lam != 0.0).tolist():
        pair = int(limit.row_pairs[row])
        g1, g2 = (int(g) for g in limit.pairs[pair])
        distance = mujoco.mj_geomDistance(model, data, g1, g2, limit.detection_distance, None)
        name = f"{_geom_label(model, g1)} vs {_geom_label(model, g2)}"
        clearance = float(qp.required[pair])
        out.append(Binding("collision", name, float(distance), clearance, multiplier=abs(float(lam[row]))))
    return out


def _geom_label(model: mujoco.MjModel, geom: int) -> str:
    """A geom's name, or its body's for an unnamed geom."""
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
    if name:
        return str(name)
    return str(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[geom])))
