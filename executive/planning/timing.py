"""Trajectories of the planner and the time parameterisation of a geometric IK path.

:class:`Trajectory` is a timed whole-body motion; :func:`build_trajectory` re-times the planner's
IK path (minimum-jerk, within the joints' speed and acceleration limits and the ZMP's margin)
and checks every knot's clearance and balance. Interpolation is linear in qpos with free-joint
quaternions normalised, both when building knots and in :meth:`Trajectory.sample`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from executive.planning.limits import GeomPairCollisionLimit, SupportPolygon
from executive.planning.loaded_com import LoadedCoM
from executive.planning.types import PlannerConfig, PlanningError, Relative
from executive.world.scratch import scratch_data

__all__ = [
    "Frames",
    "TimedJoints",
    "Trajectory",
    "build_trajectory",
    "concatenate",
    "interpolate_path",
    "min_jerk",
    "path_parameter",
    "retime",
    "zmp_path",
]

FloatArray = NDArray[np.float64]

#: Peak rate and peak acceleration of the minimum-jerk profile on [0, 1].
MIN_JERK_PEAK_RATE = 1.875
MIN_JERK_PEAK_ACCEL = 10.0 / np.sqrt(3.0)


@dataclass(frozen=True)
class Trajectory:
    """A time-parameterised whole-body motion on the world's model.

    ``qpos`` rows are full configurations of the world's model (robot and
    objects); a carried object moves rigidly with its hand. ``free_quat_adr``
    lists the qpos addresses of free-joint quaternions (normalised by
    :meth:`sample`).
    """

    name: str
    times: FloatArray  # (K,) s from the segment start, times[0] == 0, strictly increasing
    qpos: FloatArray  # (K, nq)
    hand_paths: Mapping[str, FloatArray]  # side -> (K, 3) hand site positions
    com_path: FloatArray  # (K, 3) the CoM balanced: the robot's (a carrying walk's: with its object)
    carried: tuple[str, str] | None  # (side, object name)
    free_quat_adr: tuple[int, ...] = field(default=())

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def sample(self, t: float) -> FloatArray:
        """qpos at time ``t`` (clamped to [0, duration]): linear between knots, quaternions normalised."""
        return self.sample_many(np.array([float(t)]))[0]

    def sample_many(self, times: ArrayLike) -> FloatArray:
        """:meth:`sample` at each of ``times`` at once: (len(times), nq)."""
        t = np.clip(np.asarray(times, dtype=float), 0.0, self.duration)
        return interpolate_path(self.qpos, self.times, t, self.free_quat_adr)


class TimedJoints(NamedTuple):
    """Dofs whose speed the timing bounds, and their (scaled) limits."""

    dofs: NDArray[np.int_]
    limits: FloatArray


class Frames(NamedTuple):
    """What a trajectory records per knot: hand sites (side -> site id), the robot base body,
    and the qpos addresses of free-joint quaternions."""

    hand_sites: dict[str, int]
    base_body: int
    quat_adr: tuple[int, ...]


def min_jerk(u: FloatArray) -> FloatArray:
    """Minimum-jerk blend 10u^3 - 15u^4 + 6u^5 on [0, 1] (zero rate and acceleration at both ends).

    Flash & Hogan 1985; its peak rate is 1.875 and its peak acceleration 5.7735 (u = t / T)."""
    u = np.clip(u, 0.0, 1.0)
    return np.asarray(u**3 * (10.0 + u * (-15.0 + 6.0 * u)), dtype=float)


def path_parameter(
    model: mujoco.MjModel,
    path: FloatArray,
    dof_index: NDArray[np.int_],
    limits: FloatArray,
    points: FloatArray | None = None,
    point_speed: float = np.inf,
) -> FloatArray:
    """Cumulative ``s`` (s at full speed) of each path point: steps cost ``max_j |dq_j| / v_j``.

    Tangent-space steps come from ``mj_differentiatePos`` (as in mink's PostureTask).
    ``points`` (N, P, 3): positions of P tracked points (the hands) at each path point; a
    step costs at least ``max_p |dx_p| / point_speed`` too (a Cartesian speed limit).
    """
    s = np.zeros(len(path))
    if len(path) < 2:
        return s
    joints = model.dof_jntid[dof_index]
    linear = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    if np.all(np.isin(model.jnt_type[joints], linear)):
        # A hinge or slide dof's tangent step is its qpos difference (mj_differentiatePos).
        qadr = model.jnt_qposadr[joints] + (dof_index - model.jnt_dofadr[joints])
        steps = np.diff(np.asarray(path)[:, qadr], axis=0)
    else:
        steps = np.empty((len(path) - 1, len(dof_index)))
        dq = np.empty(model.nv)
        for i in range(1, len(path)):
            mujoco.mj_differentiatePos(model, dq, 1.0, path[i - 1], path[i])
            steps[i - 1] = dq[dof_index]
    cost = np.max(np.abs(steps) / limits, axis=1)
    if points is not None:
        moved = np.max(np.linalg.norm(np.diff(points, axis=0), axis=-1), axis=1) / point_speed
        cost = np.maximum(cost, moved)
    s[1:] = np.cumsum(cost)
    return s


def retime(
    s_total: float,
    acceleration_ratio: float,
    knot_spacing: float,
    max_knots: int,
    min_duration: float,
) -> tuple[FloatArray, FloatArray]:
    """Knot times and their path parameter for a min-jerk traversal of ``[0, s_total]``.

    ``acceleration_ratio`` bounds d2s/dt2 (1/s). Peak ds/dt is at most 1 (the
    duration is padded by 1e-6 relative, so floating point cannot push a
    finite-difference velocity over its limit).
    """
    duration = max(
        MIN_JERK_PEAK_RATE * s_total,
        float(np.sqrt(MIN_JERK_PEAK_ACCEL * s_total / acceleration_ratio)),
        min_duration,
    ) * (1.0 + 1e-6)
    count = min(max(int(np.ceil(duration / knot_spacing)) + 1, 2), max_knots)
    times = np.linspace(0.0, duration, count)
    return times, s_total * min_jerk(times / duration)


def interpolate_path(
    path: FloatArray, s_path: FloatArray, s_query: FloatArray, quat_adr: tuple[int, ...]
) -> FloatArray:
    """qpos at ``s_query`` on the piecewise-linear path ``(s_path, path)``."""
    last = len(path) - 1
    s_query = np.asarray(s_query, dtype=float)
    i = np.clip(np.searchsorted(s_path, s_query, side="right") - 1, 0, last)
    j = np.minimum(i + 1, last)
    span = s_path[j] - s_path[i]
    inside = (i < last) & (span > 0.0)
    alpha = np.where(inside, (s_query - s_path[i]) / np.where(inside, span, 1.0), 0.0)[:, None]
    out = np.asarray((1.0 - alpha) * path[i] + alpha * path[j], dtype=float)
    for a in quat_adr:
        out[:, a : a + 4] /= np.linalg.norm(out[:, a : a + 4], axis=1, keepdims=True)
    return out


def build_trajectory(
    model: mujoco.MjModel,
    cfg: PlannerConfig,
    path: FloatArray,
    name: str,
    joints: TimedJoints,
    frames: Frames,
    carried: tuple[str, str] | None,
    relative: Relative | None,
    polygon: SupportPolygon,
    collisions: GeomPairCollisionLimit,
    floor: FloatArray,
    loaded: LoadedCoM | None = None,
) -> Trajectory:
    """Re-time an IK path and check every knot: clearance and balance.

    The path ``q_0 .. q_N`` is re-timed in two steps:

    1. a path parameter ``s`` in "seconds at full speed" (:func:`path_parameter`): each IK step
       costs ``max_j |dq_j| / v_j`` (the step's duration if the slowest joint ran at its
       limit ``v_j``), so ``|dq_j / ds| <= v_j`` along the piecewise-linear path; the hands'
       speed is bounded too (``cfg.hand_speed``);
    2. a minimum-jerk profile ``s(t)`` (:func:`retime`) with the smallest duration ``T`` with
       ``ds/dt <= 1`` (so no joint exceeds its limit, also between knots: the path is
       piecewise linear in ``s``) and ``d2s/dt2 <= a / v`` (the tangential part of the joint
       acceleration bounded by ``a``), stretched while the zero-moment point comes too near
       the support polygon's edge.

    Knots are uniform in time. ``floor`` (m, one per collision pair) is the distance each pair
    must keep: its required clearance, or its distance at the start when it starts closer.
    A carried object is re-attached to its hand at every knot, so it moves rigidly with it.
    ``loaded``: the CoM the knots balance and record (the robot's and a carried object's,
    :class:`~executive.planning.loaded_com.LoadedCoM`); None: the robot's alone.

    Raises PlanningError when no timing keeps the zero-moment point inside, or a knot breaks
    a clearance or the CoM's support margin.
    """
    # The hands' (and so a carried object's) speed is bounded too: the servos' tracking error
    # grows with it, and clearance is planned against that error.
    points = _hand_points(model, path, list(frames.hand_sites.values()))
    s_path = path_parameter(model, path, joints.dofs, joints.limits, points, cfg.hand_speed)
    # Tangential acceleration a = |dq/ds| s'' <= v s'': bound s'' by a / v (v the largest limit).
    ratio = cfg.acceleration_limit / float(np.max(joints.limits))
    with scratch_data(model) as data:
        times, knots = _zmp_timed_knots(
            model, data, cfg, path, s_path, ratio, name, relative, polygon, frames, loaded
        )
        _check_clearance(model, data, cfg, collisions, knots, times, floor, name, len(path))
    # The last round's knots, a carried object re-attached to its hand (as _knot_kinematics left them).
    qpos, com = knots.qpos, knots.com
    hands = {s: knots.hands[:, i].copy() for i, s in enumerate(frames.hand_sites)}
    worst = float(np.min(polygon.margins(com)))
    if worst < cfg.support_margin - 1e-9:
        raise _timing_failure(
            name,
            len(path),
            f"motion '{name}': the CoM comes {worst:.4f} m from the support polygon's edge "
            f"(needs {cfg.support_margin:.3f} m)",
        )
    return Trajectory(name, times, qpos, hands, com, carried, frames.quat_adr)


def _timing_failure(name: str, path_points: int, message: str) -> PlanningError:
    """The timed motion ``name`` breaks a limit: no hand fell short (both reached, errors 0)
    after all the path's IK iterations (``path_points - 1``)."""
    return PlanningError(name, None, 0.0, 0.0, path_points - 1, message)


def _hand_points(model: mujoco.MjModel, path: FloatArray, sites: list[int]) -> FloatArray:
    """The positions (N, sides, 3) of the hand ``sites`` at each of the path's N points."""
    points = np.empty((len(path), len(sites), 3))
    with scratch_data(model) as scratch:
        for i, q in enumerate(path):
            scratch.qpos[:] = q
            mujoco.mj_kinematics(model, scratch)
            points[i] = scratch.site_xpos[sites]
    return points


def _zmp_timed_knots(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    cfg: PlannerConfig,
    path: FloatArray,
    s_path: FloatArray,
    ratio: float,
    name: str,
    relative: Relative | None,
    polygon: SupportPolygon,
    frames: Frames,
    loaded: LoadedCoM | None = None,
) -> tuple[FloatArray, _Knots]:
    """Knot times and kinematics of the path's min-jerk timing (:func:`retime`, ``ratio`` the
    bound of d2s/dt2), stretched by ``cfg.zmp_stretch`` until the zero-moment point keeps
    ``cfg.zmp_margin`` inside the support polygon (or as far in as the CoM itself).

    Raises PlanningError when ``cfg.zmp_retime_rounds`` stretches do not get there.
    """
    duration = cfg.min_duration
    for _ in range(cfg.zmp_retime_rounds):
        times, s_knots = retime(float(s_path[-1]), ratio, cfg.knot_spacing, cfg.max_knots, duration)
        qpos = interpolate_path(path, s_path, s_knots, frames.quat_adr)
        knots = _knot_kinematics(model, data, qpos, relative, frames, loaded)
        com = knots.com
        zmp = zmp_path(times, com)
        worst_zmp = float(np.min(polygon.margins(zmp)))
        # A CoM held near the edge cannot have its ZMP further in than itself: then ask for less.
        needed = min(cfg.zmp_margin, float(np.min(polygon.margins(com))) - 0.005)
        if worst_zmp >= needed or float(s_path[-1]) == 0.0:
            return times, knots
        # The CoM's acceleration scales with 1/T^2 on the same path: stretch and check again.
        duration = float(times[-1]) * cfg.zmp_stretch
    raise _timing_failure(
        name,
        len(path),
        f"motion '{name}': the zero-moment point comes {worst_zmp:.4f} m from the support polygon's "
        f"edge even at {times[-1]:.1f} s (needs {needed:.3f} m)",
    )


def _check_clearance(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    cfg: PlannerConfig,
    collisions: GeomPairCollisionLimit,
    knots: _Knots,
    times: FloatArray,
    floor: FloatArray,
    name: str,
    path_points: int,
) -> None:
    """Every collision pair at every knot at least its ``floor`` (m) less ``cfg.clearance_tolerance``
    apart (``mj_geomDistance`` on the knots' geom poses); else PlanningError naming the first
    knot that breaks a clearance and its worst pair."""
    floor = np.asarray(floor, dtype=float) - cfg.clearance_tolerance
    # Pairs that the broadphase (on the knots' geom poses) puts farther apart than their floor
    # cannot break it: not asked. (Its bounds hold for distances from 0 up: a floor below 0, a
    # pair that starts penetrating, is asked whenever the pair may touch.)
    at, pairs = collisions.knot_candidates(knots.geom_xpos, knots.geom_xmat, np.maximum(floor, 0.0))
    fromto = np.empty(6)
    distance = np.empty(len(at))
    dmax = collisions.detection_distance
    last = -1
    for j, (k, g1, g2) in enumerate(zip(at.tolist(), *collisions.pairs[pairs].T.tolist(), strict=True)):
        if k != last:  # the knot's geom poses, as its kinematics left them (all mj_geomDistance reads)
            data.geom_xpos[:] = knots.geom_xpos[k]
            data.geom_xmat[:] = knots.geom_xmat[k]
            last = k
        distance[j] = mujoco.mj_geomDistance(model, data, g1, g2, dmax, fromto)
    gaps = distance - floor[pairs]
    if not np.any(gaps < 0):
        return
    k = int(at[np.argmax(gaps < 0)])  # the first knot that breaks a clearance, its worst pair
    at_k = np.flatnonzero(at == k)
    j = int(at_k[np.argmin(gaps[at_k])])
    i = int(pairs[j])
    n1, n2 = (str(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)) for g in collisions.pairs[i])
    raise _timing_failure(
        name,
        path_points,
        f"motion '{name}': geoms '{n1}' and '{n2}' come within "
        f"{distance[j]:.4f} m at t = {times[k]:.2f} s "
        f"(clearance {floor[i] + cfg.clearance_tolerance:.3f} m)",
    )


class _Knots(NamedTuple):
    """Per knot, a carried object re-attached to its hand: the knots' qpos (K, nq), the
    whole-robot CoM (K, 3), the hand sites' positions (K, sides, 3) and every geom's pose,
    (K, ngeom, 3) and (K, ngeom, 9)."""

    qpos: FloatArray
    com: FloatArray
    hands: FloatArray
    geom_xpos: FloatArray
    geom_xmat: FloatArray


def _knot_kinematics(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    qpos: FloatArray,
    relative: Relative | None,
    frames: Frames,
    loaded: LoadedCoM | None = None,
) -> _Knots:
    """Forward kinematics at every knot, a carried object re-attached to its hand; the CoM is
    ``loaded``'s (the robot's and the object its hand carries) when given, else the robot's.

    The object is attached after the loop, for all knots at once (``attach_object``'s formula),
    and its geoms posed from its free joint as ``mj_kinematics`` poses them: the robot's
    kinematics do not depend on it.
    """
    count = len(qpos)
    com = np.empty((count, 3))
    attached = np.array(qpos, dtype=float)
    sites = list(frames.hand_sites.values())
    hands = np.empty((count, len(sites), 3))
    xpos = np.empty((count, model.ngeom, 3))
    xmat = np.empty((count, model.ngeom, 9))
    site = relative[0] if relative is not None else 0
    site_pos, site_mat, site_quat = np.empty((count, 3)), np.empty((count, 9)), np.empty((count, 4))
    for k in range(count):
        data.qpos[:] = attached[k]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        com[k] = data.subtree_com[frames.base_body] if loaded is None else loaded.position(data)
        hands[k] = data.site_xpos[sites]
        xpos[k] = data.geom_xpos
        xmat[k] = data.geom_xmat
        if relative is not None:
            site_pos[k] = data.site_xpos[site]
            site_mat[k] = data.site_xmat[site]
            mujoco.mju_mat2Quat(site_quat[k], data.site_xmat[site])
    if relative is not None:
        _attach_all(model, relative, site_pos, site_mat, site_quat, attached, xpos, xmat)
    return _Knots(attached, com, hands, xpos, xmat)


def _quat_mul(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton products of quaternions (w x y z), row by row (``mju_mulQuat``)."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _quat_mat(q: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) of unit quaternions (w x y z) (``mju_quat2Mat``)."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def _attach_all(
    model: mujoco.MjModel,
    relative: Relative,
    site_pos: FloatArray,
    site_mat: FloatArray,
    site_quat: FloatArray,
    qpos: FloatArray,
    xpos: FloatArray,
    xmat: FloatArray,
) -> None:
    """:func:`attach_object` at every knot (hand pose x relative pose into the object's free
    joint), and the object's geoms posed from it: in place in ``qpos``, ``xpos``, ``xmat``."""
    _site, body, qadr, rel = relative
    rel_quat, rel_pos = rel.wxyz_xyz[:4], rel.wxyz_xyz[4:]
    position = site_pos + np.einsum("kij,j->ki", site_mat.reshape(-1, 3, 3), rel_pos)
    quat = _quat_mul(site_quat, rel_quat)
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    qpos[:, qadr : qadr + 3] = position
    qpos[:, qadr + 3 : qadr + 7] = quat
    # A free joint's body sits at its qpos (mj_kinematics); its geoms at their offsets in it.
    rotation = _quat_mat(quat)
    for geom in np.flatnonzero(model.geom_bodyid == body).tolist():
        xpos[:, geom] = position + rotation @ model.geom_pos[geom]
        local = np.empty(9)
        mujoco.mju_quat2Mat(local, model.geom_quat[geom])
        xmat[:, geom] = (rotation @ local.reshape(3, 3)).reshape(-1, 9)


def zmp_path(times: FloatArray, com: FloatArray, window: float = 0.1, gravity: float = 9.81) -> FloatArray:
    """Zero-moment point xy of a CoM path on flat ground (linear inverted pendulum).

    ``p = c_xy - (c_z / g) c''_xy``; the acceleration is a central difference over
    ``window`` seconds (the servos do not follow faster wiggles of the piecewise-linear
    path anyway), one-sided at the ends, where the min-jerk profile starts and stops at rest.
    """
    n = len(times)
    if n < 3:
        return np.asarray(com[:, :2], dtype=float)
    dt = float(times[-1] - times[0]) / (n - 1)
    h = max(1, min(round(window / dt), (n - 1) // 2))
    idx = np.arange(n)
    lo, hi = np.clip(idx - h, 0, n - 1), np.clip(idx + h, 0, n - 1)
    # Central second difference where both neighbours exist; zero-padded (at rest) outside.
    before = np.where((idx - h >= 0)[:, None], com[lo, :2], com[0, :2])
    after = np.where((idx + h <= n - 1)[:, None], com[hi, :2], com[-1, :2])
    acc = (after - 2.0 * com[:, :2] + before) / (h * dt) ** 2
    return np.asarray(com[:, :2] - (com[:, 2:3] / gravity) * acc, dtype=float)


def concatenate(trajectories: list[Trajectory], name: str) -> Trajectory:
    """One trajectory through every knot of ``trajectories`` in order (times made cumulative)."""
    times, qpos, com = [], [], []
    hands: dict[str, list[np.ndarray]] = {side: [] for side in trajectories[0].hand_paths}
    offset = 0.0
    for k, traj in enumerate(trajectories):
        skip = 1 if k > 0 else 0  # a step starts where the previous ended: drop the repeated knot
        times.append(traj.times[skip:] + offset)
        qpos.append(traj.qpos[skip:])
        com.append(traj.com_path[skip:])
        for side in hands:
            hands[side].append(traj.hand_paths[side][skip:])
        offset += traj.duration
    return Trajectory(
        name=name,
        times=np.concatenate(times),
        qpos=np.concatenate(qpos),
        hand_paths={side: np.concatenate(parts) for side, parts in hands.items()},
        com_path=np.concatenate(com),
        carried=None,
        free_quat_adr=trajectories[0].free_quat_adr,
    )
