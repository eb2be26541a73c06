"""Live risk: the checks a guard re-runs on every tick while a motion executes.

Two quantities, each against a limit of ``risk.guard`` (:class:`GuardConfig`):

* **predicted clearance**: the signed distance (coal, :class:`CollisionModel`) between
  the robot (with the object it carries) and the environment *as currently
  estimated*, at the robot's measured configuration and at the planned knots of
  the next ``lookahead_s`` seconds. An obstacle that the estimate says has moved
  into the path trips the guard before the hand gets there.
* **CoM margin**: the signed distance of the measured centre of mass inside the
  support polygon of the feet's *current contacts* (Long et al. 2018, eq. 3-4; the
  same polygon geometry as the fall model, :mod:`executive.world.polygon`): both feet, or
  the stance sole alone while the other foot swings. The limit is the motion's
  (``com_limit``: ``min_com_margin``, or less for a step on a narrow sole); a step also
  counts contacts that span no polygon (a foot rolled onto an edge) as the CoM outside
  (:func:`edge_margin`).

The allowances are the planner's and the risk model's (a hand may touch the object
it grasps; a carried object its support while lifted or placed), so a planned
contact does not trip the guard.

An obstacle with its own ``clearance`` has its own limit (:func:`obstacle_guard_limits`).
How a tick stays cheap (certified lower bounds, the per-trajectory memo): docs/live_guards.md.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision import CollisionModel
from executive.schema.types import GuardConfig
from executive.world.model import World
from executive.world.polygon import convex_hull, signed_margin

__all__ = [
    "GuardVerdict",
    "LiveRiskMonitor",
    "contact_support_margin",
    "edge_margin",
    "foot_contact_rows",
    "interior_margin",
    "obstacle_guard_limits",
]

FloatArray = NDArray[np.float64]
_TRACK_LIMIT = 512  # trajectories memoised; beyond, the memo starts afresh
# A point at distance r from a geom's centre moves by |R1 - R0|_2 r when the geom turns from R0
# to R1, and |R1 - R0|_2 = |R1 - R0|_F / sqrt(2) for rotations (R1 R0^T - I has singular values
# 2 sin(theta/2), 2 sin(theta/2), 0); the factor a little above 1/sqrt(2) covers rounding.
_ROTATION_NORM = (1.0 + 1e-9) / math.sqrt(2.0)
_BOUND_SLACK = 1e-12  # m: rounding of the moves (about 2e-16 per metre of bounding radius)
_ONES2, _ONES3, _ONES9 = np.ones(2), np.ones(3), np.ones(9)


@dataclass(frozen=True)
class _NowReference:
    """The last exact distance at a measured configuration, and where the moving geoms were."""

    distance: float
    robot_body: str
    env_body: str
    geoms: NDArray[np.intp]  # the robot side first, then the environment's moving geoms
    pos: FloatArray  # (G, 3) geom_xpos then
    rot: FloatArray  # (G, 9) geom_xmat then
    radius: FloatArray  # (G,) geom_rbound times _ROTATION_NORM
    sides: NDArray[np.intp]  # where the robot side starts (0) and the environment's, if any


class _Track:
    """Memoised distances of one planned trajectory's knots (NaN: not computed yet).

    Keeps a reference to the knots, so their ``id`` (the memo's key) stays theirs while the
    track lives. A planned trajectory is never edited in place (the planner returns new
    arrays), so its knots' distances change only with the estimate's geometry.
    """

    def __init__(self, qpos: FloatArray) -> None:
        self.qpos = qpos
        self.dist = np.full(len(qpos), np.nan)
        self.missing = len(qpos)  # knots whose distance is not computed yet (NaN in dist)
        self.names: list[tuple[str, str]] = [("", "")] * len(qpos)
        # The last look-ahead window (lo, hi) and its least knot: a window's knots, once
        # computed, never change in this track, so the next ticks inside the same knot
        # interval reuse it.
        self.window = (-1, -1, -1)


_PAIRS: dict[int, FloatArray] = {}  # n -> the difference matrix of all ordered pairs i != j
_TURN = np.array([[0.0, -1.0], [1.0, 0.0]])  # (x, y) @ _TURN = (y, -x): a quarter turn clockwise
_CLEARLY_INSIDE = 1e-9  # m; the hull's own vertex tolerance (1e-12 x extent) is far below


def interior_margin(points: FloatArray, x: FloatArray) -> float | None:
    """Distance from ``x`` to the boundary of the convex hull of ``points`` (V, 2) when ``x`` is
    clearly inside it; None otherwise (outside, on the boundary, or no polygon).

    For ``x`` inside a convex polygon the distance is the least slack over its edges' outward
    unit normals ``n``: ``max_k n . (p_k - x)``. Any unit direction ``u`` gives at least that
    distance (the disc around ``x`` of that radius lies inside the polygon), and each hull edge
    joins two of the points, so the least over the normals of all ordered point pairs is that
    distance exactly, without building the hull. Collinear points give no positive value and
    return None. The caller then asks :mod:`executive.world.polygon`, whose hull tolerance decides
    those cases (it moves the boundary by at most 1e-12 x the points' extent, so where this
    returns a value the two agree to that).
    """
    n = len(points)
    diff = _PAIRS.get(n)
    if diff is None:  # (n (n-1), n): row (i, j) picks p_j - p_i
        i, j = np.nonzero(~np.eye(n, dtype=bool))
        diff = np.zeros((len(i), n))
        diff[np.arange(len(i)), j] = 1.0
        diff[np.arange(len(i)), i] = -1.0
        _PAIRS[n] = diff
    normal = diff @ (points @ _TURN)  # (e_y, -e_x) of every pair's edge e, not normalised
    length = np.hypot(normal[:, 0], normal[:, 1])
    slack = (normal @ (points - x).T).max(axis=1)
    repeated = length == 0.0  # a point given twice: no direction, no bound
    if repeated.any():
        length[repeated], slack[repeated] = 1.0, np.inf
    slack /= length
    margin = float(slack.min()) if slack.size else 0.0
    return margin if margin > _CLEARLY_INSIDE else None


def foot_contact_rows(world: World, data: mujoco.MjData, feet: frozenset[int]) -> list[int]:
    """Rows of ``data.contact`` between a foot geom and the floor (or, without a floor, any
    non-robot geom): the support contacts of ``support_polygon(..., from_contacts=True)``."""
    floor = world.ids.floor_geom
    robot = world.ids.robot_geoms
    rows = []
    if data.ncon:
        for i, (g1, g2) in enumerate(data.contact.geom.tolist()):
            other = g2 if g1 in feet else g1 if g2 in feet else None
            if other is None or (other != floor if floor >= 0 else other in robot):
                continue
            rows.append(i)
    return rows


def contact_support_margin(
    world: World, data: mujoco.MjData, feet: frozenset[int] | None = None, rows: list[int] | None = None
) -> float | None:
    """CoM margin in the polygon of the feet's physics contacts with the floor (None: no polygon).

    The polygon of ``support_polygon(world, data, from_contacts=True)``
    (:mod:`executive.risk.fall`): contacts of a foot geom with the floor, or with any
    non-robot geom when the world has no floor; the CoM is ``data.subtree_com`` of the base
    body; the margin that of :func:`executive.world.polygon.signed_margin`. The contacts are picked
    out in one pass; a CoM clearly inside (the standing robot, every tick) is measured by
    :func:`interior_margin` without building the hull; anything else (outside, on the edge, no
    polygon) by :func:`executive.world.polygon.convex_hull` and ``signed_margin`` themselves.
    """
    if rows is None:
        if feet is None:
            feet = frozenset(g for geoms in world.ids.foot_geoms.values() for g in geoms)
        rows = foot_contact_rows(world, data, feet)
    if len(rows) < 3:
        return None
    points = data.contact.pos[rows, :2]
    com = data.subtree_com[world.ids.base_body][:2]
    if math.isfinite(float(points.sum()) + float(com.sum())):  # any inf or NaN: the slow path
        inside = interior_margin(points, com)
        if inside is not None:
            return inside
    try:
        return float(signed_margin(convex_hull(points), com))
    except ValueError:  # no polygon (collinear points), or a broken state the detectors report
        return None


def edge_margin(points: FloatArray, x: FloatArray) -> float:
    """Signed margin of ``x`` over contact ``points`` (P, 2) that span no polygon: fewer than three,
    or all in a line (a foot rolled onto an edge). Such a support has no inside: minus the
    distance from ``x`` to the segment the points cover (their hull); -inf without a point.
    """
    if not len(points):
        return -math.inf
    start = points[0]
    far = points[int(np.argmax(((points - start) ** 2).sum(axis=1)))]
    line = far - start
    length2 = float(line @ line)
    if length2 == 0.0:
        return -float(np.hypot(*(x - start)))
    along = (points - start) @ line / length2  # the segment: the points' extremes along the line
    lo, hi = float(along.min()), float(along.max())
    u = min(max(float((x - start) @ line) / length2, lo), hi)
    return -float(np.hypot(*(x - start - u * line)))


class GuardVerdict(NamedTuple):
    """What one live check found. ``ok`` False names the limit crossed in ``reason``.

    A named tuple: one is made on every guarded tick (a frozen dataclass costs several times more).
    """

    ok: bool
    reason: str
    # least predicted robot-environment distance (m); its part "now" is a certified lower
    # bound (never above the true distance) when that bound already clears the limit
    min_distance: float
    at_s: float  # trajectory time of that distance (s)
    robot_body: str
    env_body: str
    com_margin: float | None  # m, None when not measured; a certified lower bound when it clears the limit
    crossed: str = ""  # the limit crossed: "clearance" or "com_margin" ("" when ok)

    def as_dict(self) -> dict[str, object]:
        return {
            "ok": self.ok,
            "reason": self.reason,
            "min_distance": self.min_distance,
            "at_s": self.at_s,
            "robot_body": self.robot_body,
            "env_body": self.env_body,
            "com_margin": self.com_margin,
            "crossed": self.crossed,
        }


class LiveRiskMonitor:
    """Guard checks on the estimate world (its obstacle and object poses are the current estimate).

    Thread-safe: one lock serialises the collision model (one ``MjData``) between the guards'
    checks in the tick and :meth:`prepare` in a planning thread.
    """

    def __init__(
        self, estimate: World, config: GuardConfig, collision_model: CollisionModel | None = None
    ) -> None:
        self.world = estimate
        self.config = config
        self.collision = collision_model or CollisionModel(estimate, estimate.scenario.risk)
        # Obstacles with their own clearance: body id -> metres added to their distances, so
        # that one comparison with min_distance applies each one's own limit (module doc).
        limits = obstacle_guard_limits(estimate, config)
        self._shift = {b: config.min_distance - limit for b, limit in limits.items()}
        model = self.collision.model
        self._shift_by_name = {model.body(b).name: v for b, v in self._shift.items()}
        self._object_qpos = [
            slice(adr, adr + 7) for adr in estimate.ids.object_qpos.values()
        ]  # free joints: 3 position + 4 quaternion
        self._feet: dict[int, tuple[World, frozenset[int]]] = {}  # id(world) -> its foot geoms
        # id(world) -> the last exact CoM margin's contacts: (the world, geom pairs, foot rows,
        # their points, the CoM, the margin)
        self._support: dict[
            int, tuple[World, bytes, NDArray[np.intp], FloatArray, tuple[float, float], float]
        ] = {}
        self.com_bounded = 0  # CoM margins a certified lower bound answered
        self._lock = threading.RLock()
        self._tracks: dict[tuple[int, str | None, frozenset[tuple[str, str]]], _Track] = {}
        m = self.collision.model
        # views into the model's own arrays (read afresh on each check through the views)
        self._geometry_arrays = (m.body_pos, m.body_quat, m.geom_pos, m.geom_quat, m.geom_size)
        self._geometry = self._geometry_key()
        self.knots_computed = 0  # planned knots whose distance was computed (not memoised)
        self.knots_adopted = 0  # planned knots whose distance another monitor computed (adopt)
        # The measured configuration's distance: the last exact one per (carried, allow), with
        # the poses of the geoms that move with the configuration (robot, objects) at that time.
        model = self.collision.model
        self._kinematics = mujoco.MjData(model)
        self._robot_geoms = np.array(estimate.ids.robot_geoms, dtype=np.intp)
        self._object_geom = {name: int(g) for name, g in estimate.ids.object_geoms.items()}
        self._now: dict[tuple[str | None, frozenset[tuple[str, str]]], _NowReference] = {}
        self.now_exact = 0  # checks that computed the measured configuration's distance exactly
        self.now_bounded = 0  # checks that a certified lower bound answered (it cleared the limit)

    def _geometry_key(self) -> bytes:
        """What a knot's distance depends on besides the knot: the estimate's geometry."""
        return b"".join(a.tobytes() for a in self._geometry_arrays)

    def _refresh(self) -> None:
        """Forget the memoised knots when the estimate's geometry changed (caller holds the lock)."""
        key = self._geometry_key()
        if key != self._geometry or len(self._tracks) > _TRACK_LIMIT:
            self._tracks.clear()
            self._now.clear()
            self._geometry = key

    def _track(self, qpos: FloatArray, carried: str | None, allow: frozenset[tuple[str, str]]) -> _Track:
        """The memo of a planned trajectory (caller holds the lock and has refreshed)."""
        key = (id(qpos), carried, allow)
        track = self._tracks.get(key)
        if track is None or track.qpos is not qpos:
            track = self._tracks[key] = _Track(qpos)
        return track

    def _fill(
        self, track: _Track, lo: int, hi: int, carried: str | None, allow: frozenset[tuple[str, str]]
    ) -> None:
        """Compute the knots in [lo, hi) not computed yet (caller holds the lock)."""
        if not track.missing:  # all computed (prepare filled the track ahead)
            return
        for k in np.flatnonzero(np.isnan(track.dist[lo:hi])).tolist():
            knot = self.collision.knot(
                track.qpos[lo + k], carried=carried, allow=allow, near=False, shift=self._shift
            )
            track.dist[lo + k] = self._guard_distance(knot.distance, knot.env_body_name)
            track.names[lo + k] = (knot.robot_body_name, knot.env_body_name)
            track.missing -= 1
            self.knots_computed += 1

    def prepare(
        self, trajectory_qpos: FloatArray, *, carried: str | None, allow: frozenset[tuple[str, str]]
    ) -> None:
        """Compute (and memoise) every knot of a planned trajectory now, e.g. in a planning thread.

        Pass the very array the guard will check (its identity keys the memo). Holds the lock
        one knot at a time, so a guard's check in the tick waits at most one knot's distance.
        """
        qpos = np.asarray(trajectory_qpos, dtype=float)
        for k in range(len(qpos)):
            with self._lock:
                self._refresh()
                self._fill(self._track(qpos, carried, allow), k, k + 1, carried, allow)

    def memo(
        self, trajectory_qpos: FloatArray
    ) -> list[tuple[str | None, frozenset[tuple[str, str]], FloatArray, list[tuple[str, str]]]]:
        """What is memoised of a planned trajectory's knots, to hand to another monitor (:meth:`adopt`).

        Args:
            trajectory_qpos: the very array the guard checks (its identity keys the memo).

        Returns:
            One ``(carried, allow, distances, closest pairs)`` per memo of that array (copies;
            NaN where a knot is not computed).
        """
        with self._lock:
            self._refresh()
            return [
                (carried, allow, track.dist.copy(), list(track.names))
                for (key, carried, allow), track in self._tracks.items()
                if key == id(trajectory_qpos) and track.qpos is trajectory_qpos
            ]

    def adopt(
        self,
        trajectory_qpos: FloatArray,
        *,
        carried: str | None,
        allow: frozenset[tuple[str, str]],
        distances: FloatArray,
        names: list[tuple[str, str]],
    ) -> None:
        """Memoise knot distances another monitor computed (:meth:`memo`), as :meth:`prepare` would.

        A knot's distance depends on the knot, ``carried``, ``allow`` and the estimate's geometry
        only, so distances from a monitor of the same scenario's estimate (a planning worker
        process's) are the ones this monitor would compute.

        Args:
            trajectory_qpos: the very array the guard will check (its identity keys the memo).
            carried, allow: as for :meth:`prepare`.
            distances: per knot, the guard's distance (NaN: not computed).
            names: per knot, the closest (robot body, environment body).
        """
        qpos = np.asarray(trajectory_qpos, dtype=float)
        dist = np.array(distances, dtype=float)
        if dist.shape != (len(qpos),) or len(names) != len(qpos):
            raise ValueError(f"{len(dist)} distances and {len(names)} names for {len(qpos)} knots")
        with self._lock:
            self._refresh()
            track = self._track(qpos, carried, allow)
            track.dist, track.names = dist, [(robot, env) for robot, env in names]
            track.missing = int(np.isnan(dist).sum())
            track.window = (-1, -1, -1)
            self.knots_adopted += len(qpos) - track.missing
            self.collision.warm(carried, allow)  # the pairs the guard's checks use, as prepare builds them

    def configuration(self, measured_qpos: FloatArray, planned_qpos: FloatArray) -> FloatArray:
        """The robot where it is measured, the objects where the plan has them (the estimate)."""
        q = np.array(measured_qpos, dtype=float, copy=True)
        for part in self._object_qpos:
            q[part] = planned_qpos[part]
        return q

    def _movers(self, carried: str | None) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Geoms that move with the configuration: the robot's side (its geoms and the carried
        object's) and the environment's (the objects); the table and obstacles do not. The
        carried object is on both sides: the collision model also checks it, as environment,
        against the robot's own geoms (the other hand), a pair in which both ends move."""
        robot = self._robot_geoms
        if carried is not None and carried in self._object_geom:
            robot = np.append(robot, self._object_geom[carried])
        env = np.array(list(self._object_geom.values()), dtype=np.intp)
        return robot, env

    def _now_distance(
        self, now: FloatArray, carried: str | None, allow: frozenset[tuple[str, str]], at_least: float | None
    ) -> tuple[float, str, str]:
        """Distance at the measured configuration ``now`` (caller holds the lock and has refreshed).

        Exact, or, when ``at_least`` is given, possibly a certified lower bound that is at least
        ``at_least``: every point of a geom moves by at most ``|dc| + |dR|_2 r`` (centre shift,
        change of its rotation matrix, bounding radius ``geom_rbound``) from where it was at the
        last exact computation, so the distance of any (robot side, environment) pair dropped by
        at most the largest such move of the robot side plus that of the environment's moving
        geoms. If that bound still clears ``at_least``, the true distance does too; otherwise
        the distance is computed exactly. A limit test on the result therefore decides exactly
        as a test on the exact distance would.
        """
        key = (carried, allow)
        ref = self._now.get(key)
        model, data = self.collision.model, self._kinematics
        posed = False  # whether data holds the kinematics of `now`
        if at_least is not None and ref is not None:
            data.qpos[:] = now
            mujoco.mj_kinematics(model, data)
            posed = True
            # Row norms as sqrt((x * x) @ 1): a product with a ones vector is cheaper than a
            # reduction along rows of 3 or 9 (one rounding more than np.linalg.norm: covered by
            # _BOUND_SLACK).
            shift = data.geom_xpos[ref.geoms]
            shift -= ref.pos
            turn = data.geom_xmat[ref.geoms]
            turn -= ref.rot
            np.square(shift, out=shift)
            np.square(turn, out=turn)
            move = np.sqrt(shift @ _ONES3)
            move += np.sqrt(turn @ _ONES9) * ref.radius
            # the robot side's largest move plus the environment's (reduceat: both maxima at once)
            bound = ref.distance - _BOUND_SLACK - float(np.maximum.reduceat(move, ref.sides).sum())
            if bound >= at_least:
                self.now_bounded += 1
                return bound, ref.robot_body, ref.env_body
        # the least only
        knot = self.collision.knot(now, carried=carried, allow=allow, near=False, shift=self._shift)
        guard_distance = self._guard_distance(knot.distance, knot.env_body_name)
        self.now_exact += 1
        if at_least is not None:
            robot, env = self._movers(carried)
            geoms = np.concatenate([robot, env])
            if not posed:  # the bound above has posed them already
                data.qpos[:] = now
                mujoco.mj_kinematics(model, data)
            self._now[key] = _NowReference(
                distance=guard_distance,
                robot_body=knot.robot_body_name,
                env_body=knot.env_body_name,
                geoms=geoms,
                sides=np.array([0, len(robot)] if len(env) else [0], dtype=np.intp),
                pos=data.geom_xpos[geoms].copy(),
                rot=data.geom_xmat[geoms].copy(),
                radius=model.geom_rbound[geoms] * _ROTATION_NORM,
            )
        return guard_distance, knot.robot_body_name, knot.env_body_name

    def _guard_distance(self, distance: float, env_body: str) -> float:
        """The distance the guard compares with ``min_distance``: shifted by the body's own
        limit (module doc); the distance itself for a body without one."""
        shift = self._shift_by_name.get(env_body)
        return float(distance) if shift is None else float(distance) + shift

    def clearance(
        self,
        measured_qpos: FloatArray,
        trajectory_qpos: FloatArray,
        trajectory_times: FloatArray,
        t: float,
        *,
        carried: str | None,
        allow: frozenset[tuple[str, str]],
        at_least: float | None = None,
    ) -> tuple[float, float, str, str]:
        """Least distance now and at the planned knots in (t, t + lookahead]: (d, time, robot, env).

        With obstacles of their own clearance, ``d`` is the guard's shifted distance (the module
        doc): the one compared with ``min_distance``; :meth:`check` reports the pair's own.

        ``at_least``: the distance now may be a certified lower bound, if that bound is at least
        this (see :meth:`_now_distance`); None: always exact.
        """
        times = np.asarray(trajectory_times, dtype=float)
        qpos = np.asarray(trajectory_qpos, dtype=float)
        k_now = min(int(times.searchsorted(t)), len(times) - 1)
        now = self.configuration(measured_qpos, qpos[k_now])
        with self._lock:
            self._refresh()
            d_now, robot_body, env_body = self._now_distance(now, carried, allow, at_least)
            out = (d_now, t, robot_body, env_body)
            lo = int(times.searchsorted(t, side="right"))
            hi = int(times.searchsorted(t + self.config.lookahead_s, side="right"))
            if hi > lo:
                track = self._track(qpos, carried, allow)
                if track.window[:2] == (lo, hi):
                    k = track.window[2]
                else:
                    self._fill(track, lo, hi, carried, allow)
                    k = lo + int(np.argmin(track.dist[lo:hi]))  # the first of equal minima, as a scan
                    track.window = (lo, hi, k)
                if track.dist[k] < out[0]:
                    out = (float(track.dist[k]), float(times[k]), *track.names[k])
        return out

    def com_margin(
        self, world: World, data: mujoco.MjData, at_least: float | None = None, *, on_edge: bool = False
    ) -> float | None:
        """Margin of the measured CoM in the polygon of the current foot contacts (None: no support).

        ``data`` must hold a stepped (or ``mj_forward``-ed) state: contacts and ``subtree_com``.

        ``on_edge``: contacts that span no polygon (fewer than three, or in a line: a foot rolled
        onto an edge, or none) give :func:`edge_margin` (at most 0) instead of None.

        ``at_least``: the margin may be a certified lower bound, if that bound is at least this.
        The margin of a point in a convex hull moves by at most the point's move plus the
        largest move of a hull vertex (each support value ``max_k u . p_k`` moves by at most
        that), so while the contacts are the same geom pairs in the same order as at the last
        exact margin, ``margin_then - max_k |p_k - p_k,then| - |c - c_then|`` is one. A test
        of the result against a limit at or below ``at_least`` decides as the exact margin would.
        """
        cached = self._feet.get(id(world))
        if cached is None or cached[0] is not world:
            feet = frozenset(g for geoms in world.ids.foot_geoms.values() for g in geoms)
            cached = self._feet[id(world)] = (world, feet)
        if at_least is None:
            rows = foot_contact_rows(world, data, cached[1])
            margin = contact_support_margin(world, data, rows=rows)
            return self._edge(world, data, rows) if margin is None and on_edge else margin
        contact = data.contact
        pairs = contact.geom.tobytes() if data.ncon else b""
        cx, cy, _ = data.subtree_com[world.ids.base_body].tolist()
        ref = self._support.get(id(world))
        if ref is not None and ref[0] is world and ref[1] == pairs:
            _, _, take, points0, (cx0, cy0), margin0 = ref
            shift = contact.pos[take, :2]
            shift -= points0
            np.square(shift, out=shift)
            move = math.sqrt(float((shift @ _ONES2).max()))  # the largest contact point move
            bound = margin0 - _BOUND_SLACK - move - math.hypot(cx - cx0, cy - cy0)
            if bound >= at_least:  # False for NaN
                self.com_bounded += 1
                return bound
        rows = foot_contact_rows(world, data, cached[1])
        margin = contact_support_margin(world, data, rows=rows)
        if margin is not None:
            take = np.array(rows, dtype=np.intp)  # fancy indexing takes an array faster than a list
            self._support[id(world)] = (world, pairs, take, contact.pos[take, :2], (cx, cy), margin)
        elif on_edge:
            return self._edge(world, data, rows)
        return margin

    @staticmethod
    def _edge(world: World, data: mujoco.MjData, rows: list[int]) -> float:
        """:func:`edge_margin` of the CoM over the foot contacts ``rows``."""
        return edge_margin(data.contact.pos[rows, :2], data.subtree_com[world.ids.base_body][:2])

    def check(
        self,
        measured_qpos: FloatArray,
        trajectory_qpos: FloatArray,
        trajectory_times: FloatArray,
        t: float,
        *,
        carried: str | None,
        allow: frozenset[tuple[str, str]],
        com_margin: float | None,
        com_limit: float | None = None,
    ) -> GuardVerdict:
        """Both checks against the limits; the first limit crossed is the reason.

        ``com_limit``: the least CoM margin (m; None: ``min_com_margin``), the motion's
        (``GuardedMotion.com_limit``).
        """
        cfg = self.config
        least = cfg.min_com_margin if com_limit is None else com_limit
        d, at, robot_body, env_body = self.clearance(
            measured_qpos,
            trajectory_qpos,
            trajectory_times,
            t,
            carried=carried,
            allow=allow,
            at_least=cfg.min_distance,
        )
        reason, crossed = "", ""
        shift = self._shift_by_name.get(env_body, 0.0)
        if d < cfg.min_distance:
            when = "now" if at <= t else f"in {at - t:.2f} s"
            own = ", its own from its clearance" if shift else ""
            reason, crossed = (
                (
                    f"guard: {robot_body} would come within {(d - shift) * 1000:.1f} mm of {env_body} {when} "
                    f"(limit {(cfg.min_distance - shift) * 1000:.0f} mm{own})"
                ),
                "clearance",
            )
        elif com_margin is not None and com_margin < least:
            reason, crossed = _com_reason(com_margin, least), "com_margin"
        if shift:
            d -= shift  # the verdict gives the pair's own distance
        return GuardVerdict(not reason, reason, d, at, robot_body, env_body, com_margin, crossed)


def _com_reason(margin: float, limit: float) -> str:
    """Why a CoM margin below its limit trips the guard, in words."""
    bound = f"(limit {limit * 1000:.0f} mm)"
    if margin == -math.inf:
        return f"guard: no foot touches the floor {bound}"
    if margin < 0.0:
        return f"guard: centre of mass {-margin * 1000:.1f} mm outside the foot contacts' support {bound}"
    return f"guard: centre of mass {margin * 1000:.1f} mm inside the support polygon {bound}"


def obstacle_guard_limits(world: World, config: GuardConfig) -> dict[int, float]:
    """Body id -> the guard's distance limit (m) of each obstacle with its own ``clearance`` c:
    ``max(c - config.min_distance, c / 2)`` (module doc). Obstacles without one are missing
    (their limit is ``config.min_distance``)."""
    model, geoms = world.model, world.ids.obstacle_geoms
    limits: dict[int, float] = {}
    for body in world.scenario.scene.obstacles:
        geom = geoms.get(body.name, -1)
        if body.clearance is not None and geom >= 0:
            c = float(body.clearance)
            limits[int(model.geom_bodyid[geom])] = max(c - config.min_distance, c / 2.0)
    return limits
