"""Inequality limits of the whole-body planner, and the IK step's QP that stacks them.

Each limit is a ``mink.Limit`` that ``mink.solve_ik`` (or :class:`JointBounds`, which solves the
same QP with DAQP on the dofs that may move) stacks into ``G dq <= h``: the CoM inside the feet's
support polygon (:class:`SupportPolygon`, :class:`SupportPolygonLimit`), the robot's safe posture
(:class:`TiltLimit`, :class:`PelvisHeightLimit`) and collision avoidance between explicit geom
pairs, a carried object moving with its hand (:class:`GeomPairCollisionLimit`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import daqp  # type: ignore[import-not-found]  # no stubs; mink solves with it already (solver="daqp")
import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.loaded_com import LoadedCoM
from executive.world.polygon import convex_hull, halfplanes

__all__ = [
    "ConfigurationLimit",
    "GeomPairCollisionLimit",
    "JointBounds",
    "PelvisHeightLimit",
    "StepQP",
    "SupportPolygon",
    "SupportPolygonLimit",
    "TiltLimit",
    "can_collide",
    "geom_pairs",
]

FloatArray = NDArray[np.float64]


# --- support polygon ------------------------------------------------------------------------


@dataclass(frozen=True)
class SupportPolygon:
    """A convex polygon in the ground plane: vertices counter-clockwise, edges as ``A x <= b``.

    ``normals`` (m, 2) are the unit outward edge normals, ``offsets`` (m,) their
    offsets, so a point x is inside iff ``normals @ x <= offsets``.
    """

    vertices: FloatArray
    normals: FloatArray
    offsets: FloatArray

    @classmethod
    def from_points(cls, points: FloatArray) -> SupportPolygon:
        hull = convex_hull(np.asarray(points, dtype=float)[:, :2])
        normals, offsets = halfplanes(hull)
        return cls(hull, normals, offsets)

    @classmethod
    def from_feet(cls, model: mujoco.MjModel, data: mujoco.MjData, geoms: Iterable[int]) -> SupportPolygon:
        """Footprint of the sole geoms: corners of each geom's bounding box, projected to xy."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        corners = []
        for g in geoms:
            # geom_aabb: local bounding box (centre, half sizes); equals the box itself for a box geom.
            centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            rot = data.geom_xmat[g].reshape(3, 3)
            corners.append(data.geom_xpos[g] + (centre + signs * half) @ rot.T)
        return cls.from_points(np.vstack(corners))

    @property
    def centre(self) -> FloatArray:
        """Centroid of the polygon's area (shoelace formula)."""
        x, y = self.vertices[:, 0], self.vertices[:, 1]
        x1, y1 = np.roll(x, -1), np.roll(y, -1)
        cross = x * y1 - x1 * y
        area = 0.5 * float(np.sum(cross))
        if abs(area) < 1e-12:
            return np.asarray(self.vertices.mean(axis=0), dtype=float)
        return np.array([np.sum((x + x1) * cross), np.sum((y + y1) * cross)]) / (6.0 * area)

    def margin(self, point: FloatArray) -> float:
        """Signed distance (m) from ``point`` (xy) to the nearest edge line; positive inside."""
        return float(np.min(self.offsets - self.normals @ np.asarray(point, dtype=float)[:2]))

    def margins(self, points: FloatArray) -> FloatArray:
        """:meth:`margin` of each row of ``points`` (N, 2 or more; the first two columns are xy)."""
        xy = np.asarray(points, dtype=float)[:, :2]
        return np.asarray(np.min(self.offsets[None, :] - xy @ self.normals.T, axis=1), dtype=float)


class SupportPolygonLimit(mink.Limit):
    """CoM xy of the subtree of ``body`` stays inside ``polygon`` shrunk by ``margin``.

    Rows ``a_i^T J_c dq <= gain (b_i - margin - a_i^T c)``, with ``J_c`` from
    ``mj_jacSubtreeCom`` (the Jacobian mink's ``ComTask`` uses). With ``com`` (a
    :class:`~executive.planning.loaded_com.LoadedCoM` of ``body``), the CoM of the robot and the
    object its hand carries instead.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        body: int,
        polygon: SupportPolygon,
        margin: float,
        gain: float = 0.5,
        com: LoadedCoM | None = None,
    ) -> None:
        self.model = model
        self.body = body
        self.normals = polygon.normals
        self.bounds = polygon.offsets - margin
        self.gain = gain
        self.loaded = com
        self._jac = np.empty((3, model.nv))

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a position limit, like mink's ConfigurationLimit
        data = configuration.data
        if self.loaded is not None:
            self.loaded.jacobian(data, self._jac)
            com = self.loaded.position(data)[:2]
        else:
            mujoco.mj_jacSubtreeCom(self.model, data, self._jac, self.body)
            com = data.subtree_com[self.body][:2]
        G = self.normals @ self._jac[:2]
        h = self.gain * (self.bounds - self.normals @ com)
        return mink.Constraint(G=G, h=h)


class TiltLimit(mink.Limit):
    """A body's z axis stays within ``max_tilt`` (rad) of the world's vertical.

    With ``z`` the body's z axis and ``e`` the world's, ``d(z . e)/dt = omega . (z x e)``,
    so the row is ``-(z x e)^T J_rot dq <= gain (z . e - cos max_tilt)`` (the same
    velocity-damper form as :class:`SupportPolygonLimit`). Rotations about the vertical
    (a waist yaw) are not limited.
    """

    def __init__(self, model: mujoco.MjModel, body: int, max_tilt: float, gain: float = 0.5) -> None:
        self.model = model
        self.body = body
        self.min_cos = float(np.cos(max_tilt))
        self.gain = gain
        self._jac = np.empty((3, model.nv))

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt
        data = configuration.data
        mat = data.xmat[self.body]  # row-major: z axis = (mat[2], mat[5], mat[8])
        mujoco.mj_jacBody(self.model, data, None, self._jac, self.body)
        axis = np.array([mat[5], -mat[2], 0.0])  # z x (0, 0, 1)
        G = -(axis @ self._jac)[None, :]
        h = np.array([self.gain * (float(mat[8]) - self.min_cos)])
        return mink.Constraint(G=G, h=h)


class PelvisHeightLimit(mink.Limit):
    """A body's origin (the pelvis) stays at least at ``min_height`` (m) above the world's z = 0.

    With ``z`` the body's height and ``J_z`` the z row of its translational Jacobian, the row is
    ``-J_z dq <= gain (z - min_height)`` (the velocity-damper form of
    :class:`SupportPolygonLimit`): the body approaches its floor at most ``gain`` of the way
    per step, never crossing it to first order. Below the floor (second-order drift of the
    steps, or a start below it) the bound is ``-min(gain (min_height - z), recovery)``: it rises
    back by at most ``recovery`` (m) per step, as :class:`GeomPairCollisionLimit`'s pairs. The
    safe posture's pelvis limit
    (:class:`executive.robot.posture.SafePosture`).
    """

    def __init__(
        self, model: mujoco.MjModel, body: int, min_height: float, gain: float = 0.5, recovery: float = 0.002
    ) -> None:
        self.model = model
        self.body = body
        self.min_height = float(min_height)
        self.recovery = recovery
        self.gain = gain
        self._jac = np.empty((3, model.nv))

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a position limit, like mink's ConfigurationLimit
        data = configuration.data
        mujoco.mj_jacBody(self.model, data, self._jac, None, self.body)
        height = float(data.xpos[self.body][2])
        G = -self._jac[2:3]
        gap = height - self.min_height
        h = np.array([self.gain * gap if gap >= 0.0 else -min(-self.gain * gap, self.recovery)])
        return mink.Constraint(G=G, h=h)


class ConfigurationLimit(mink.ConfigurationLimit):
    """mink's joint range limit, except that a joint outside its range goes no further out.

    mink asks such a joint to move back into range within the step (a negative bound),
    which contradicts a frozen dof's ``dq = 0`` (a robot's own keyframe may hold a finger
    a little past its range): the bounds are clipped at zero instead.
    """

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        constraint = super().compute_qp_inequalities(configuration, dt)
        if constraint.h is None:
            return constraint
        return mink.Constraint(G=constraint.G, h=np.maximum(constraint.h, 0.0))


class StepQP(NamedTuple):
    """One IK step's QP in DAQP's form, ``min 1/2 x^T hessian x + linear^T x`` subject to
    ``lower <= [x; matrix x] <= upper`` (``sense`` marks the equality rows), on the free dofs of
    :class:`JointBounds`: the first ``len(free)`` bounds are the dofs' own (range and velocity),
    the rest the general rows, each limit's at ``spans[i]`` (start, stop; empty when inactive)."""

    hessian: FloatArray
    linear: FloatArray
    matrix: FloatArray
    upper: FloatArray
    lower: FloatArray
    sense: NDArray[np.intc]
    spans: list[tuple[int, int]]


class JointBounds:
    """The joint range limit (:class:`ConfigurationLimit`) and mink's ``VelocityLimit`` as
    bounds on each dof of the step, and the IK step's QP on the dofs that may move.

    mink stacks both limits as rows ``[P; -P] dq <= h`` of the QP's general inequalities;
    they are bounds on single dofs, and DAQP takes those as simple bounds. The dofs frozen by
    equality constraints (fingers, objects' free joints) are left out of the QP (a variable
    fixed at zero by an equality contributes nothing else). The QP is mink's
    (``mink.solve_ik``), its unique solution the same: the feasible set and the (strictly
    convex) objective are unchanged.
    """

    def __init__(self, model: mujoco.MjModel, velocities: Mapping[str, float], frozen: Sequence[int]) -> None:
        self.model = model
        self.config = ConfigurationLimit(model)
        self.free = np.array(sorted(set(range(model.nv)) - set(int(d) for d in frozen)), dtype=int)
        where = np.full(model.nv, -1, dtype=int)
        where[self.free] = np.arange(len(self.free))
        hinge = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
        joints = [
            j
            for j in range(model.njnt)
            if model.jnt_limited[j] and int(model.jnt_type[j]) in hinge and where[model.jnt_dofadr[j]] >= 0
        ]
        self._range_qadr = np.array([model.jnt_qposadr[j] for j in joints], dtype=int)
        self._range_at = np.array([where[model.jnt_dofadr[j]] for j in joints], dtype=int)
        self._lower = np.array([model.jnt_range[j, 0] for j in joints], dtype=float)
        self._upper = np.array([model.jnt_range[j, 1] for j in joints], dtype=float)
        # Limited ball joints keep mink's row (a bound on the rotation angle, not on a dof).
        self._ball_rows = len(self.config._ball_qposadr)
        velocity = mink.VelocityLimit(model, velocities)
        keep = where[velocity.indices] >= 0
        self._velocity_at = where[velocity.indices][keep]
        self._velocity = np.asarray(velocity.limit, dtype=float)[keep]
        self._posture_columns: dict[int, FloatArray] = {}

    def _identity_columns(self, task: mink.PostureTask, configuration: mink.Configuration) -> FloatArray:
        """The diagonal of a posture task's Jacobian (1, or 0 where mink leaves a dof out)."""
        columns = self._posture_columns.get(id(task))
        if columns is None:
            columns = np.diag(task.compute_jacobian(configuration)).copy()
            self._posture_columns[id(task)] = columns
        return columns

    def bounds(self, q: FloatArray, dt: float, velocity: bool = True) -> tuple[FloatArray, FloatArray]:
        """(lower, upper) bounds of the free dofs' step at ``q``: range (mink's gain, bounds
        clipped at zero as :class:`ConfigurationLimit`'s) and, if ``velocity``, ``v dt``."""
        n = len(self.free)
        lower, upper = np.full(n, -1e30), np.full(n, 1e30)
        gain = self.config.gain
        q_range = q[self._range_qadr]
        upper[self._range_at] = np.maximum(gain * (self._upper - q_range), 0.0)
        lower[self._range_at] = -np.maximum(gain * (q_range - self._lower), 0.0)
        if velocity:
            step = dt * self._velocity
            upper[self._velocity_at] = np.minimum(upper[self._velocity_at], step)
            lower[self._velocity_at] = np.maximum(lower[self._velocity_at], -step)
        return lower, upper

    def project(
        self, configuration: mink.Configuration, constraints: Sequence[mink.Task], dt: float
    ) -> FloatArray:
        """``solve(configuration, [], dt, 1.0, [], constraints, velocity=False)``: the least-norm
        step that meets the constraints (within the joint ranges), as a velocity (nv,).

        Without the ranges that step is ``A^T (A A^T)^-1 b``; when it keeps within them it is
        the QP's solution, else the QP is solved.
        """
        free = self.free
        rows = [task.compute_jacobian(configuration)[:, free] for task in constraints]
        target = [-task.gain * task.compute_error(configuration) for task in constraints]
        matrix, rhs = np.vstack(rows), np.concatenate(target)
        try:
            x = matrix.T @ np.linalg.solve(matrix @ matrix.T, rhs)
        except np.linalg.LinAlgError:
            return self.solve(configuration, [], dt, 1.0, [], constraints, velocity=False)
        lower, upper = self.bounds(configuration.q, dt, velocity=False)
        if not (np.all(x >= lower) and np.all(x <= upper)):
            return self.solve(configuration, [], dt, 1.0, [], constraints, velocity=False)
        out = np.zeros(self.model.nv)
        out[free] = x / dt
        return out

    def solve(
        self,
        configuration: mink.Configuration,
        tasks: Sequence[mink.Task],
        dt: float,
        damping: float,
        limits: Sequence[mink.Limit],
        constraints: Sequence[mink.Task],
        velocity: bool = True,
    ) -> FloatArray:
        """mink's IK step (``mink.solve_ik`` with these limits plus this range and, if
        ``velocity``, velocity limit): the velocity (nv,), zero on the frozen dofs.

        Raises mink.NoSolutionFound when the QP is infeasible.
        """
        qp = self.step_qp(configuration, tasks, dt, damping, limits, constraints, velocity)
        x, _obj, exitflag, _info = daqp.solve(qp.hessian, qp.linear, qp.matrix, qp.upper, qp.lower, qp.sense)
        if exitflag <= 0:
            raise mink.NoSolutionFound("daqp")
        out = np.zeros(self.model.nv)
        out[self.free] = np.asarray(x) / dt
        return out

    def step_qp(
        self,
        configuration: mink.Configuration,
        tasks: Sequence[mink.Task],
        dt: float,
        damping: float,
        limits: Sequence[mink.Limit],
        constraints: Sequence[mink.Task],
        velocity: bool = True,
    ) -> StepQP:
        """The QP :meth:`solve` hands DAQP (same arguments), with each limit's rows.

        Returns:
            The step's QP on the free dofs (:class:`StepQP`).
        """
        hessian, linear = self._objective(configuration, tasks, damping)
        matrix, upper, lower, sense, spans = self._rows(configuration, dt, limits, constraints, velocity)
        return StepQP(hessian, linear, matrix, upper, lower, sense, spans)

    def _objective(
        self, configuration: mink.Configuration, tasks: Sequence[mink.Task], damping: float
    ) -> tuple[FloatArray, FloatArray]:
        """The step QP's Hessian and linear term on the free dofs (mink's ``_compute_qp_objective``:
        the tasks' ``J^T W^2 J`` and ``-e^T W J`` stacked, plus ``damping`` and the tasks'
        Levenberg-Marquardt damping on the diagonal)."""
        free, n = self.free, len(self.free)
        weighted: list[FloatArray] = []
        errors: list[FloatArray] = []
        mu = 0.0
        diagonal, linear = np.zeros(n), np.zeros(n)
        for task in tasks:
            if isinstance(task, mink.PostureTask):
                # J = I (zero columns on the floating base): its J^T W^2 J is diagonal, added
                # as such instead of stacking an nv x nv block (mink's _weighted_residual).
                error = task.compute_error(configuration)
                cost = np.asarray(task.cost, dtype=float)
                weighted_error = cost * (-task.gain * error)
                mu += task.lm_damping * float(weighted_error @ weighted_error)
                square = (cost * cost * self._identity_columns(task, configuration))[free]
                diagonal += square
                linear += task.gain * square * error[free]
                continue
            residual = task.compute_qp_residual(configuration)
            assert residual is not None  # mink's tasks here all have the J^T J form
            jac, err, task_mu = residual
            weighted.append(jac[:, free])
            errors.append(err)
            mu += task_mu
        if weighted:
            w = np.vstack(weighted)
            hessian = w.T @ w
            linear -= np.concatenate(errors) @ w
        else:
            hessian = np.zeros((n, n))
        hessian.flat[:: n + 1] += damping + mu + diagonal
        return hessian, linear

    def _rows(
        self,
        configuration: mink.Configuration,
        dt: float,
        limits: Sequence[mink.Limit],
        constraints: Sequence[mink.Task],
        velocity: bool,
    ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.intc], list[tuple[int, int]]]:
        """The step QP's constraints in DAQP's form: the general rows (limits' inequalities, then
        the constraints' equalities) on the free dofs, the upper and lower bounds of the free
        dofs and the rows stacked, each one's sense (equality rows marked), and each limit's
        rows (start, stop) among the general rows."""
        free, n = self.free, len(self.free)
        rows: list[FloatArray] = []
        upper: list[FloatArray] = []
        lower, high = self.bounds(configuration.q, dt, velocity)
        bounds_low = [lower]
        upper.append(high)
        if self._ball_rows:
            ball = self.config.compute_qp_inequalities(configuration, dt)
            assert ball.G is not None and ball.h is not None
            rows.append(ball.G[-self._ball_rows :, free])
            upper.append(ball.h[-self._ball_rows :])
        spans: list[tuple[int, int]] = []
        for limit in limits:
            start = sum(len(r) for r in rows)
            constraint = limit.compute_qp_inequalities(configuration, dt)
            if not constraint.inactive:
                assert constraint.G is not None and constraint.h is not None
                rows.append(constraint.G[:, free])
                upper.append(np.asarray(constraint.h, dtype=float))
            spans.append((start, sum(len(r) for r in rows)))
        inequalities = sum(len(r) for r in rows)
        bounds_low.append(np.full(inequalities, -1e30))
        equalities = 0
        for task in constraints:
            jacobian = task.compute_jacobian(configuration)[:, free]
            rows.append(jacobian)
            upper.append(-task.gain * task.compute_error(configuration))
            equalities += len(jacobian)
        bounds_low.append(np.full(equalities, -1e30))
        matrix = np.ascontiguousarray(np.vstack(rows)) if rows else np.zeros((0, n))
        sense = np.zeros(n + inequalities + equalities, dtype=np.intc)
        sense[n + inequalities :] = 5  # equality (DAQP: active and immutable), as qpsolvers sets it
        return matrix, np.concatenate(upper), np.concatenate(bounds_low), sense, spans


# --- collision pairs ------------------------------------------------------------------------


def can_collide(model: mujoco.MjModel, g1: int, g2: int) -> bool:
    """MuJoCo's own pair filters: contype/conaffinity, same body, parent-child, <exclude>."""
    if not (
        model.geom_contype[g1] & model.geom_conaffinity[g2]
        or model.geom_contype[g2] & model.geom_conaffinity[g1]
    ):
        return False
    b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
    if model.body_weldid[b1] == model.body_weldid[b2]:
        return False
    w1, w2 = int(model.body_weldid[b1]), int(model.body_weldid[b2])
    p1, p2 = int(model.body_weldid[model.body_parentid[w1]]), int(model.body_weldid[model.body_parentid[w2]])
    # Parent-child filter (mjDSBL_FILTERPARENT); the world body (0) is nobody's filtered parent.
    if (p1 == w2 and w2 != 0) or (p2 == w1 and w1 != 0):
        return False
    # <exclude> signatures are (body1 << 16) + body2 (MuJoCo's mj_collision filter).
    signatures = model.exclude_signature[: model.nexclude]
    return not np.any((signatures == (b1 << 16) + b2) | (signatures == (b2 << 16) + b1))


def geom_pairs(
    model: mujoco.MjModel, groups: Iterable[tuple[Sequence[int], Sequence[int]]]
) -> list[tuple[int, int]]:
    """Sorted, de-duplicated geom pairs of the cross products of ``groups`` MuJoCo could collide."""
    out = {
        (min(a, b), max(a, b))
        for first, second in groups
        for a in first
        for b in second
        if a != b and can_collide(model, a, b)
    }
    return sorted(out)


class GeomPairCollisionLimit(mink.Limit):
    """Normal-velocity limit between geom pairs (after mink's ``CollisionAvoidanceLimit``).

    For a pair at distance ``d < detection_distance`` with witness points p1, p2
    and unit normal n = (p2 - p1)/|p2 - p1|, the row is
    ``-n^T (J_p2 - J_p1) dq <= gain (d - d_min)`` (``d_min`` one value for all pairs or one
    per pair): mink's velocity damper, written for the displacement ``dq`` that mink's QP
    solves for. Once ``d <= d_min`` the bound is ``-min(gain (d_min - d), recovery)``: a pair
    that second-order drift (the rows are first order) has taken inside ``d_min`` is pushed
    back out by at most ``recovery`` per step (mink's bound is 0 there, and a pair sliding
    along a surface then creeps inwards step after step); ``recovery = 0`` is mink's.
    ``attach`` maps a geom to the body whose Jacobian moves it (a carried object
    moves with the palm, not with its own free joint, whose dofs the planner freezes).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        pairs: Sequence[tuple[int, int]],
        min_distance: float | FloatArray,
        detection_distance: float,
        gain: float,
        attach: dict[int, int] | None = None,
        recovery: float = 0.0,
    ) -> None:
        self.model = model
        self.recovery = recovery
        self.pairs = np.array(pairs, dtype=int).reshape(-1, 2)
        # One clearance for every pair, or one per pair.
        self.min_distance = np.broadcast_to(np.asarray(min_distance, dtype=float), (len(self.pairs),)).copy()
        self.detection_distance = detection_distance
        self.gain = gain
        bodies = np.array(model.geom_bodyid, dtype=int)
        for geom, body in (attach or {}).items():
            bodies[geom] = body
        self.jac_body = bodies
        # Geoms welded to the world (table, obstacles) have a zero Jacobian: not asked of MuJoCo.
        self._moves = model.body_weldid[bodies] != 0
        self._fromto = np.empty((len(self.pairs), 6))  # witness segment per pair, last asked
        self._first = np.ascontiguousarray(self.pairs[:, 0])
        self._second = np.ascontiguousarray(self.pairs[:, 1])
        self._pair_list = [(a, b) for a, b in self.pairs.tolist()]
        self._reach = model.geom_rbound[self.pairs[:, 0]] + model.geom_rbound[self.pairs[:, 1]]
        self._cores = _Cores(model, self.pairs)
        # The last full query (every candidate within the detection distance): the qpos it was
        # made at and the candidates closer than the detection distance (pair index, distance;
        # their witness segments stay in _fromto). The QP step that follows at the same
        # configuration reuses it instead of asking MuJoCo again.
        self._cache_qpos: FloatArray | None = None
        self._cache: tuple[NDArray[np.int_], FloatArray] = (np.zeros(0, dtype=int), np.zeros(0))
        self.row_pairs = np.zeros(0, dtype=int)  # the pair of each row of the last constraint

    def distances(self, data: mujoco.MjData, cutoff: float | None = None) -> FloatArray:
        """Signed distance of every pair (capped at the detection distance).

        ``cutoff``: only pairs whose bounding spheres come within it are asked (the rest, farther
        than ``cutoff`` for sure, read as the detection distance); for callers that only compare
        distances against clearances no larger than ``cutoff``. The distances asked are the same
        ``mj_geomDistance`` values either way.
        """
        out = np.full(len(self.pairs), self.detection_distance)
        dmax = self.detection_distance
        reach = dmax if cutoff is None else min(float(cutoff), dmax)
        model, pairs, fromto = self.model, self._pair_list, self._fromto
        asked = self._candidates(data, reach)
        for i in asked.tolist():
            g1, g2 = pairs[i]
            out[i] = mujoco.mj_geomDistance(model, data, g1, g2, dmax, fromto[i])
        if reach >= dmax:
            near = asked[out[asked] < dmax]  # the QP rows skip pairs at the detection distance
            self._cache_qpos, self._cache = data.qpos.copy(), (near, out[near])
        else:  # some witness segments were overwritten at another configuration
            self._cache_qpos = None
        return out

    def _candidates(self, data: mujoco.MjData, cutoff: float | None = None) -> NDArray[np.int_]:
        """Bounding-sphere broadphase (as mink's): pairs that may be within ``cutoff`` (default:
        the detection distance). (At one configuration the tighter :class:`_Cores` bound costs
        more numpy than the distances it saves; :meth:`knot_candidates` uses it.)"""
        limit = self.detection_distance if cutoff is None else cutoff
        delta = data.geom_xpos[self._first] - data.geom_xpos[self._second]
        gap = np.sqrt(np.einsum("ij,ij->i", delta, delta)) - self._reach
        return np.flatnonzero(gap <= limit)

    def knot_candidates(
        self, xpos: FloatArray, xmat: FloatArray, cutoff: float | FloatArray
    ) -> tuple[NDArray[np.int_], NDArray[np.int_]]:
        """The broadphase of :meth:`_candidates` at many configurations at once.

        ``xpos`` (K, ngeom, 3) and ``xmat`` (K, ngeom, 9): the geoms' poses at K configurations;
        ``cutoff``: one distance for all pairs or one per pair. Returns (knot, pair) index arrays
        of the pairs that may be within their cutoff there (every other pair is farther than
        its cutoff for sure), in knot order.
        """
        if len(self.pairs) == 0 or len(xpos) == 0:
            empty = np.zeros(0, dtype=int)
            return empty, empty
        limit = np.broadcast_to(np.asarray(cutoff, dtype=float), (len(self.pairs),))
        # Pairs whose centres' boxes over all K configurations stay apart are never near.
        lo, hi = xpos.min(axis=0), xpos.max(axis=0)
        first, second = self._first, self._second
        apart = np.maximum(np.maximum(lo[first] - hi[second], lo[second] - hi[first]), 0.0)
        some = np.flatnonzero(np.sqrt(np.einsum("ij,ij->i", apart, apart)) - self._reach <= limit)
        delta = xpos[:, first[some]] - xpos[:, second[some]]
        gap = np.sqrt(np.einsum("kij,kij->ki", delta, delta)) - self._reach[some]
        knots, pairs = np.nonzero(gap <= limit[some])
        pairs = some[pairs]
        keep = self._cores.bounds(xpos, xmat, knots, pairs) <= limit[pairs]
        return knots[keep], pairs[keep]

    def _queries(self, data: mujoco.MjData) -> tuple[NDArray[np.int_], FloatArray]:
        """(pairs, distances) of the candidates closer than the detection distance at ``data``'s
        configuration (witness segments in ``_fromto``), from the cache when the last full
        :meth:`distances` query was made at the same qpos."""
        if self._cache_qpos is None or not np.array_equal(self._cache_qpos, data.qpos):
            self.distances(data)
        return self._cache

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a bound on the displacement, see the class docstring
        model, data = self.model, configuration.data
        near, dist = self._queries(data)
        if len(near) == 0:
            return mink.Constraint()
        fromto = self._fromto[near]
        normal = fromto[:, 3:] - fromto[:, :3]
        length = np.sqrt(np.einsum("ij,ij->i", normal, normal))
        touching = length < 1e-9  # no witness direction: use the centres
        if np.any(touching):
            centres = data.geom_xpos[self._second[near]] - data.geom_xpos[self._first[near]]
            normal[touching] = centres[touching]
            length[touching] = np.sqrt(np.einsum("ij,ij->i", centres, centres))[touching]
        keep = length >= 1e-9
        if not np.all(keep):
            near, dist, fromto = near[keep], dist[keep], fromto[keep]
            normal, length = normal[keep], length[keep]
            if len(near) == 0:
                return mink.Constraint()
        # Penetrating: fromto points run the other way (mink flips the sign too).
        normal *= (np.where(dist < 0, -1.0, 1.0) / length)[:, None]
        # Contact-normal Jacobian of the witness points (mink's compute_contact_normal_jacobian).
        jac = np.zeros((len(near), 2, 3, model.nv))
        moves, body = self._moves, self.jac_body
        for k, i in enumerate(near.tolist()):
            g1, g2 = self._pair_list[i]
            if moves[g1]:
                mujoco.mj_jac(model, data, jac[k, 0], None, fromto[k, :3], int(body[g1]))
            if moves[g2]:
                mujoco.mj_jac(model, data, jac[k, 1], None, fromto[k, 3:], int(body[g2]))
        rows = -np.einsum("ni,nij->nj", normal, jac[:, 1] - jac[:, 0])
        gap = dist - self.min_distance[near]
        # The QP variable of mink.build_ik is the displacement dq = v dt, so the damper bounds
        # the approach per step by gain * gap (mink's own limit divides by dt as well, which
        # for dt < 1 lets a step close more than the whole gap). Inside d_min: see the class doc.
        bounds = np.where(gap > 0, self.gain * gap, -np.minimum(-self.gain * gap, self.recovery))
        self.row_pairs = near
        return mink.Constraint(G=rows, h=bounds)


class _Cores:
    """A lower bound on the distance of geom pairs, tighter than their bounding spheres.

    A box's bounding sphere is far larger than the box when it is flat (a table top), so the
    sphere test passes every hand near the table. Here each geom of a pair is taken exactly
    as a box (boxes), as a segment with a radius (capsules; cylinders lie inside theirs), as a
    ball (spheres; any other shape: its bounding sphere), and the distance from that shape to
    the other geom's bounding sphere bounds the pair's distance from below; the larger of the
    two ways round is taken. Planes, height fields and SDFs have no bound (always asked).

    All three shapes are a box of half sizes ``half`` (zero for a ball, zero but along z for a
    capsule's segment) grown by ``radius`` (zero for a box), so one formula serves them all.
    """

    def __init__(self, model: mujoco.MjModel, pairs: NDArray[np.int_]) -> None:
        box, capsule, cylinder, sphere, plane, hfield, sdf = (
            int(t)  # numpy compares an array with an int fast, with a pybind11 enum element by element
            for t in (
                mujoco.mjtGeom.mjGEOM_BOX,
                mujoco.mjtGeom.mjGEOM_CAPSULE,
                mujoco.mjtGeom.mjGEOM_CYLINDER,
                mujoco.mjtGeom.mjGEOM_SPHERE,
                mujoco.mjtGeom.mjGEOM_PLANE,
                mujoco.mjtGeom.mjGEOM_HFIELD,
                mujoco.mjtGeom.mjGEOM_SDF,
            )
        )
        # Both ways round: the shape of ``first[i]`` against the sphere of ``second[i]``.
        self.first = np.concatenate([pairs[:, 0], pairs[:, 1]]).astype(int)
        self.second = np.concatenate([pairs[:, 1], pairs[:, 0]]).astype(int)
        kind = model.geom_type[self.first]
        size = model.geom_size[self.first]
        is_box = kind == box
        is_capsule = (kind == capsule) | (kind == cylinder)
        self.half = np.zeros((len(kind), 3))
        self.half[is_box] = size[is_box]
        self.half[is_capsule, 2] = size[is_capsule, 1]
        radius = np.where(is_capsule | (kind == sphere), size[:, 0], model.geom_rbound[self.first])
        radius[is_box] = 0.0
        other = model.geom_type[self.second]
        # The other geom's bounding sphere, and no bound at all (-inf) for unbounded shapes.
        self.shrink = radius + model.geom_rbound[self.second]
        for unbounded in (plane, hfield, sdf):
            self.shrink[(kind == unbounded) | (other == unbounded)] = np.inf
        self.count = len(pairs)

    def bounds(
        self, xpos: FloatArray, xmat: FloatArray, knots: NDArray[np.int_], pairs: NDArray[np.int_]
    ) -> FloatArray:
        """Lower bounds (m) on the distance of ``pairs``.

        ``xpos`` (K, ngeom, 3), ``xmat`` (K, ngeom, 9): the geoms' poses at K configurations,
        ``knots`` the configuration of each pair.
        """
        both = np.concatenate([pairs, pairs + self.count])
        first, second = self.first[both], self.second[both]
        at = np.concatenate([knots, knots])
        offset = xpos[at, second] - xpos[at, first]
        axes = xmat[at, first]
        # The offset in the first geom's frame (xmat is row-major: its columns are the axes).
        local = np.einsum("nij,ni->nj", axes.reshape(-1, 3, 3), offset)
        outside = np.maximum(np.abs(local) - self.half[both], 0.0)
        bound = np.sqrt(np.einsum("ni,ni->n", outside, outside)) - self.shrink[both]
        half = len(pairs)
        return np.asarray(np.maximum(bound[:half], bound[half:]), dtype=float)
