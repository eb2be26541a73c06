"""Trajectories of the planner and the time parameterisation of a geometric IK path.

The differential-IK iterations give a geometric path ``q_0 .. q_N``. It is
re-timed in two steps:

1. a path parameter ``s`` in "seconds at full speed": each IK step costs
   ``max_j |dq_j| / v_j`` (the step's duration if the slowest joint ran at its
   limit ``v_j``), so ``|dq_j / ds| <= v_j`` along the piecewise-linear path;
2. a minimum-jerk profile ``s(t) = S (10 u^3 - 15 u^4 + 6 u^5)``, ``u = t / T``
   (Flash & Hogan 1985), whose peak rate is ``1.875 S / T`` and peak
   acceleration ``5.7735 S / T^2``. ``T`` is the smallest duration with
   ``ds/dt <= 1`` (so no joint exceeds its limit, also between knots: the
   path is piecewise linear in ``s``) and ``d2s/dt2 <= a / v`` (the tangential
   part of the joint acceleration bounded by ``a``).

Knots are uniform in time. Interpolation is linear in qpos with free-joint
quaternions normalised, both when building knots and in :meth:`Trajectory.sample`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning_limits import GeomPairCollisionLimit, SupportPolygon
from executive.planning_types import PlannerConfig, PlanningError, Relative, attach_object

__all__ = [
    "Frames",
    "TimedJoints",
    "Trajectory",
    "build_trajectory",
    "interpolate_path",
    "min_jerk",
    "normalise_quats",
    "path_parameter",
    "retime",
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
    com_path: FloatArray  # (K, 3) whole-robot CoM, robot bodies only
    carried: tuple[str, str] | None  # (side, object name)
    free_quat_adr: tuple[int, ...] = field(default=())

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def sample(self, t: float) -> FloatArray:
        """qpos at time ``t`` (clamped to [0, duration]): linear between knots, quaternions normalised."""
        t = min(max(float(t), 0.0), self.duration)
        k = int(np.searchsorted(self.times, t, side="right")) - 1
        k = min(max(k, 0), len(self.times) - 2)
        t0, t1 = float(self.times[k]), float(self.times[k + 1])
        alpha = (t - t0) / (t1 - t0)
        q = (1.0 - alpha) * self.qpos[k] + alpha * self.qpos[k + 1]
        normalise_quats(q, self.free_quat_adr)
        return q


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


def normalise_quats(q: FloatArray, quat_adr: tuple[int, ...]) -> None:
    for a in quat_adr:
        q[a : a + 4] /= np.linalg.norm(q[a : a + 4])


def min_jerk(u: FloatArray) -> FloatArray:
    """Minimum-jerk blend 10u^3 - 15u^4 + 6u^5 on [0, 1] (zero rate and acceleration at both ends)."""
    u = np.clip(u, 0.0, 1.0)
    return np.asarray(u**3 * (10.0 + u * (-15.0 + 6.0 * u)), dtype=float)


def path_parameter(
    model: mujoco.MjModel, path: FloatArray, dof_index: NDArray[np.int_], limits: FloatArray
) -> FloatArray:
    """Cumulative ``s`` (s at full speed) of each path point: steps cost ``max_j |dq_j| / v_j``.

    Tangent-space steps come from ``mj_differentiatePos`` (as in mink's PostureTask).
    """
    s = np.zeros(len(path))
    dq = np.empty(model.nv)
    for i in range(1, len(path)):
        mujoco.mj_differentiatePos(model, dq, 1.0, path[i - 1], path[i])
        s[i] = s[i - 1] + float(np.max(np.abs(dq[dof_index]) / limits))
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
    out = np.empty((len(s_query), path.shape[1]))
    last = len(path) - 1
    for k, s in enumerate(s_query):
        i = min(int(np.searchsorted(s_path, s, side="right")) - 1, last)
        i = max(i, 0)
        if i == last or s_path[i + 1] <= s_path[i]:
            out[k] = path[i]
        else:
            alpha = (s - s_path[i]) / (s_path[i + 1] - s_path[i])
            out[k] = (1.0 - alpha) * path[i] + alpha * path[i + 1]
        normalise_quats(out[k], quat_adr)
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
    clearance0: FloatArray,
) -> Trajectory:
    """Re-time an IK path and check every knot: clearance (as at the start, or min_distance) and balance.

    A carried object is re-attached to its hand at every knot, so it moves rigidly with it.
    """
    s_path = path_parameter(model, path, joints.dofs, joints.limits)
    # Tangential acceleration a = |dq/ds| s'' <= v s'': bound s'' by a / v (v the largest limit).
    ratio = cfg.acceleration_limit / float(np.max(joints.limits))
    times, s_knots = retime(float(s_path[-1]), ratio, cfg.knot_spacing, cfg.max_knots, cfg.min_duration)
    qpos = interpolate_path(path, s_path, s_knots, frames.quat_adr)
    data = mujoco.MjData(model)
    hands = {s: np.empty((len(times), 3)) for s in frames.hand_sites}
    com = np.empty((len(times), 3))
    # Pairs must keep min_distance, or (when they start closer) not come closer than at the start.
    floor = np.minimum(clearance0, cfg.min_distance) - cfg.clearance_tolerance
    for k in range(len(times)):
        data.qpos[:] = qpos[k]
        mujoco.mj_kinematics(model, data)
        if relative is not None:
            attach_object(data, relative)
            qpos[k] = data.qpos
            mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        for s, site in frames.hand_sites.items():
            hands[s][k] = data.site_xpos[site]
        com[k] = data.subtree_com[frames.base_body]
        gaps = collisions.distances(data) - floor
        if np.any(gaps < 0):
            i = int(np.argmin(gaps))
            g1, g2 = (str(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)) for g in collisions.pairs[i])
            raise PlanningError(
                name,
                None,
                0.0,
                0.0,
                len(path) - 1,
                f"motion '{name}': geoms '{g1}' and '{g2}' come within "
                f"{gaps[i] + floor[i]:.4f} m at t = {times[k]:.2f} s (clearance {cfg.min_distance:.3f} m)",
            )
    worst = min(polygon.margin(c) for c in com)
    if worst < cfg.support_margin - 1e-9:
        raise PlanningError(
            name,
            None,
            0.0,
            0.0,
            len(path) - 1,
            f"motion '{name}': the CoM comes {worst:.4f} m from the support polygon's edge "
            f"(needs {cfg.support_margin:.3f} m)",
        )
    return Trajectory(name, times, qpos, hands, com, carried, frames.quat_adr)
