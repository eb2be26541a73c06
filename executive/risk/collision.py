"""Collision risk of a trajectory: coal signed distances, the seed metric, and P(collision).

:class:`CollisionModel` finds the closest robot-environment approach at every knot (coal signed
distances behind a broad phase; its doc says which pairs). :func:`assess_collision` scores a
trajectory: the seed metric (Long et al. 2018, "Collision Risk": instantaneous risk
``(1 - d/d_safety)^b``, trajectory score ``peak_weight * peak + exposure_weight * exposure``) and
the probability of a collision when the environment bodies' horizontal positions are uncertain,
to first order along coal's witness normals, over the union of all knots
(:mod:`executive.risk.collision_probability`; the union bounds ``max_k P_k <= P <= min(1, sum_k
P_k)`` alongside). :func:`monte_carlo_collision_probability` samples the same errors and
recomputes coal distances, to validate it (the first order's bias: docs/measurements.md).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import coal
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision_probability import (
    CollisionModelError,
    NearPair,
    ProbabilityEstimate,
    collision_probability,
    gaussian_union_probability,
)
from executive.risk.report import RiskReport
from executive.risk.shapes import coal_geometry
from executive.schema.types import CollisionRiskConfig, RiskConfig, Uncertainty
from executive.world.model import World, is_descendant

__all__ = [
    "Allow",
    "CollisionModel",
    "CollisionModelError",
    "CollisionProfile",
    "CollisionSetup",
    "KnotDistance",
    "MonteCarloResult",
    "NearPair",
    "ProbabilityEstimate",
    "SeedScore",
    "TrajectoryLike",
    "assess_collision",
    "breach_summary",
    "collision_probability",
    "gaussian_union_probability",
    "instantaneous_risk",
    "monte_carlo_collision_probability",
    "report_from_profile",
    "seed_collision_score",
]

FloatArray = NDArray[np.float64]
#: Pairs excluded from a query: an environment geom/body name (all robot geoms), or a
#: (robot geom or body name, environment geom or body name) pair.
Allow = Collection[str | tuple[str, str]]


class TrajectoryLike(Protocol):
    """What the collision model reads of a trajectory (``executive.planning.planner.Trajectory``)."""

    @property
    def times(self) -> FloatArray: ...

    @property
    def qpos(self) -> FloatArray: ...

    @property
    def carried(self) -> tuple[str, str] | None: ...


# --- the seed metric ---------------------------------------------------------------------------


def instantaneous_risk(distance: float | FloatArray, d_safety: float, exponent: float) -> FloatArray:
    """Seed instantaneous risk ``(1 - d/d_safety)^b`` for ``d < d_safety``, 1 for ``d <= 0``, else 0.

    Long et al. 2018, "Collision Risk": the minimum robot-obstacle distance inside a safety margin.
    """
    d = np.asarray(distance, dtype=float)
    ratio = np.clip(1.0 - d / d_safety, 0.0, 1.0)
    return np.where(d < d_safety, ratio**exponent, 0.0)


def _risk(distance: float, d_safety: float, exponent: float) -> float:
    """Scalar :func:`instantaneous_risk` (no numpy overhead per knot)."""
    if distance >= d_safety:
        return 0.0
    if distance <= 0.0:
        return 1.0
    return float((1.0 - distance / d_safety) ** exponent)


class SeedScore(NamedTuple):
    """Seed trajectory score = peak_weight * peak + exposure_weight * exposure."""

    score: float
    peak: float  # instantaneous risk at the trajectory's absolute minimum distance
    exposure: float  # fraction of the duration with d < d_safety


def seed_collision_score(
    times: FloatArray, distances: FloatArray, d_safety: float, config: CollisionRiskConfig
) -> SeedScore:
    """The seed's weighted sum of the peak term and the exposure term over a distance profile.

    Long et al. 2018, "Collision Risk": the absolute minimum distance over the trajectory
    and the time spent in proximity, combined by a weighted sum. Distances are taken as
    linear between knots, so the time within ``d_safety`` counts partial intervals exactly.
    """
    t = np.asarray(times, dtype=float)
    d = np.asarray(distances, dtype=float)
    if t.shape != d.shape or t.ndim != 1 or len(t) == 0:
        raise CollisionModelError(f"times {t.shape} and distances {d.shape} must be equal-length 1-D")
    peak = float(instantaneous_risk(float(np.min(d)), d_safety, config.exponent))
    duration = float(t[-1] - t[0])
    if len(t) == 1 or duration <= 0.0:
        exposure = float(np.mean(d < d_safety))
    else:
        lo, hi = np.minimum(d[:-1], d[1:]), np.maximum(d[:-1], d[1:])
        span = np.where(hi > lo, hi - lo, 1.0)
        frac = np.where(hi > lo, np.clip((d_safety - lo) / span, 0.0, 1.0), (lo < d_safety).astype(float))
        exposure = float(np.sum(frac * np.diff(t)) / duration)
    score = config.peak_weight * peak + config.exposure_weight * exposure
    return SeedScore(float(score), peak, exposure)


# --- the model ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class CollisionSetup:
    """Which geoms form the robot and the environment, and what is uncertain.

    robot_geoms: the robot's collision geoms (feet included; the floor is never a pair).
    env_geoms: table, obstacles and objects (the carried object moves to the robot side).
    object_geoms: object name -> geom, the objects a trajectory may carry.
    env_sigma: environment body id -> horizontal 1-sigma (m); missing means exact.
    part_factors: robot body id -> (body part, severity factor) (``Severity.body_parts``).
    hand_geoms: side -> robot geoms of the hand subtree.
    support_geoms: the geoms objects rest on (the table's), for :meth:`CollisionModel.support_allow`.
    env_clearance: environment body id -> its own ``d_safety`` (m) (an obstacle's ``clearance``);
        missing: ``risk.d_safety``.
    env_severity: environment body id -> its own collision severity (an obstacle's ``severity``);
        missing: ``risk.severity.collision``.
    breach_bodies: environment body ids whose touch breaches containment (``category: breach``).
    """

    robot_geoms: tuple[int, ...]
    env_geoms: tuple[int, ...]
    object_geoms: Mapping[str, int] = field(default_factory=dict)
    env_sigma: Mapping[int, float] = field(default_factory=dict)
    part_factors: Mapping[int, tuple[str, float]] = field(default_factory=dict)
    hand_geoms: Mapping[str, tuple[int, ...]] = field(default_factory=dict)
    support_geoms: tuple[int, ...] = ()
    env_clearance: Mapping[int, float] = field(default_factory=dict)
    env_severity: Mapping[int, float] = field(default_factory=dict)
    breach_bodies: frozenset[int] = frozenset()

    @classmethod
    def from_world(
        cls, world: World, risk_config: RiskConfig, uncertainty: Uncertainty | None = None
    ) -> CollisionSetup:
        """Groups of ``world``: robot geoms vs table, obstacles and objects; sigmas from the scenario."""
        model, ids = world.model, world.ids
        unc = uncertainty if uncertainty is not None else world.scenario.uncertainty
        obstacles = tuple(ids.obstacle_geoms.values())
        objects = tuple(ids.object_geoms.values())
        env = tuple(g for g in (*ids.table_geoms, *obstacles, *objects) if g >= 0)
        sigma: dict[int, float] = {}
        for g in obstacles:
            sigma[int(model.geom_bodyid[g])] = float(unc.obstacle_position)
        for g in objects:
            sigma[int(model.geom_bodyid[g])] = float(unc.object_position)
        robot_bodies = set(ids.robot_bodies)
        parts: dict[str, set[int]] = {}
        if ids.head_body is not None:
            parts["head"] = {b for b in robot_bodies if is_descendant(model, b, ids.head_body)}
        parts["hand"] = {b for bodies in ids.hand_bodies.values() for b in bodies}
        forearms = {arm.forearm_body for arm in world.profile.arms.values() if arm.forearm_body}
        parts["forearm"] = {int(model.body(name).id) for name in forearms}
        factors: dict[int, tuple[str, float]] = {}
        for name, factor in risk_config.severity.body_parts:
            bodies = parts.get(name)
            if bodies is None:  # any other part name: a robot body of that name and its subtree
                found = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
                bodies = {b for b in robot_bodies if found >= 0 and is_descendant(model, b, found)}
            for b in bodies:
                if b not in factors or factor > factors[b][1]:
                    factors[b] = (name, float(factor))
        hands = {
            side: tuple(g for g in ids.robot_geoms if int(model.geom_bodyid[g]) in set(bodies))
            for side, bodies in ids.hand_bodies.items()
        }
        clearance, severity, breach = _obstacle_losses(world)
        return cls(
            robot_geoms=tuple(ids.robot_geoms),
            env_geoms=env,
            object_geoms=dict(ids.object_geoms),
            env_sigma=sigma,
            part_factors=factors,
            hand_geoms=hands,
            support_geoms=tuple(g for g in ids.table_geoms if g >= 0),
            env_clearance=clearance,
            env_severity=severity,
            breach_bodies=breach,
        )


def _obstacle_losses(world: World) -> tuple[dict[int, float], dict[int, float], frozenset[int]]:
    """The scene obstacles' own clearance, severity and breach category by body id (the
    :class:`CollisionSetup` fields ``env_clearance``, ``env_severity``, ``breach_bodies``)."""
    model, geoms = world.model, world.ids.obstacle_geoms
    clearance: dict[int, float] = {}
    severity: dict[int, float] = {}
    breach: set[int] = set()
    for body in world.scenario.scene.obstacles:
        geom = geoms.get(body.name, -1)
        if geom < 0:
            continue
        b = int(model.geom_bodyid[geom])
        if body.clearance is not None:
            clearance[b] = float(body.clearance)
        if body.severity is not None:
            severity[b] = float(body.severity)
        if body.category == "breach":
            breach.add(b)
    return clearance, severity, frozenset(breach)


@dataclass(frozen=True)
class KnotDistance:
    """The closest robot-environment approach at one configuration.

    distance: signed minimum distance (m), negative when penetrating.
    normal: unit vector from the environment geom to the robot geom.
    risk: the seed's instantaneous risk: at ``distance``, or with obstacles of their own
        clearance the largest over the near pairs, each against its body's ``d_safety``.
    near: every pair within the cutoff (for the probability), closest pair included.
    scaled: with obstacles of their own clearance, ``min_pairs d / d_safety(body)`` times
        ``risk.d_safety`` (the distance the seed metric scores); None: ``distance``.
    """

    distance: float
    robot_geom: int
    env_geom: int
    robot_geom_name: str
    env_geom_name: str
    robot_body_name: str
    env_body_name: str
    point_robot: FloatArray
    point_env: FloatArray
    normal: FloatArray
    risk: float
    pairs_checked: int
    pairs_skipped: int
    near: tuple[NearPair, ...] = ()
    scaled: float | None = None


@dataclass(frozen=True)
class CollisionProfile:
    """Per-knot closest approaches of a trajectory."""

    times: FloatArray
    knots: tuple[KnotDistance, ...]

    @property
    def distances(self) -> FloatArray:
        return np.array([k.distance for k in self.knots])

    @property
    def scaled_distances(self) -> FloatArray:
        """Per knot the distance the seed metric scores (:attr:`KnotDistance.scaled`)."""
        return np.array([k.distance if k.scaled is None else k.scaled for k in self.knots])

    @property
    def risks(self) -> FloatArray:
        return np.array([k.risk for k in self.knots])

    @property
    def pairs_checked(self) -> int:
        return sum(k.pairs_checked for k in self.knots)

    @property
    def pairs_skipped(self) -> int:
        return sum(k.pairs_skipped for k in self.knots)


class _Layout(NamedTuple):
    """Index arrays and coal functors for one (carried object, allow set) query."""

    robot: NDArray[np.int_]  # robot-side geoms (carried object last)
    env: NDArray[np.int_]  # environment geoms
    mask: NDArray[np.bool_]  # (E, R) pair is considered
    cutoff: FloatArray  # (E,) broad-phase cutoff per environment geom
    robot_list: list[int]
    env_list: list[int]
    env_body: list[int]
    cutoff_list: list[float]
    functors: list[list[coal.ComputeDistance]]  # [env][robot]
    n_pairs: int


class _TravelBound:
    """Lower bounds on pair distances along a trajectory, every knot's computed up front.

    Two bounds per pair and knot, the larger wins: the broad phase's (robot bounding sphere vs
    environment oriented box, :meth:`CollisionModel._lower_bounds`), and one from the pair's last
    coal distance ``d_j``: a rigid geom's points move by at most ``|dp| + r ||dR||_F`` between two
    knots (``p`` its frame origin, ``R`` its rotation, ``r`` its bounding radius ``geom_rbound``
    about that origin: ``|dR u| <= ||dR||_F |u|``), so with ``T`` the geoms' travel summed since
    knot j, ``d_k >= d_j - T_robot - T_env`` (triangle inequality), less ``slack`` for coal's
    tolerance.
    """

    def __init__(
        self, model: mujoco.MjModel, layout: _Layout, xpos: FloatArray, xmat: FloatArray, slack: float = 1e-4
    ) -> None:
        # xpos (K, E + R, 3) and xmat (K, E + R, 9): the environment geoms, then the robot geoms.
        n_env = len(layout.env)
        geoms = np.concatenate([layout.env, layout.robot])
        radius = np.asarray(model.geom_rbound[geoms], dtype=float)
        plane = np.asarray(model.geom_type[geoms] == int(mujoco.mjtGeom.mjGEOM_PLANE))
        dp, dm = np.diff(xpos, axis=0), np.diff(xmat, axis=0)
        step = np.sqrt(np.einsum("kgi,kgi->kg", dp, dp)) + radius * np.sqrt(np.einsum("kgi,kgi->kg", dm, dm))
        step = np.where(plane & (step > 0.0), np.inf, step)
        cum = np.concatenate([np.zeros((1, len(geoms))), np.cumsum(step, axis=0)])
        self.cum_e, self.cum_r = cum[:, :n_env], cum[:, n_env:]
        sphere = _sphere_box_bounds(model, layout, xpos[:, n_env:], xpos[:, :n_env], xmat[:, :n_env])
        self.sphere = np.where(layout.mask, sphere, np.inf)  # excluded pairs: never a candidate
        self.slack = slack
        shape = (n_env, len(layout.robot))
        self.last = np.full(shape, -np.inf)  # distance at the pair's last coal query
        self.last_r = np.zeros(shape)  # cum_r of its robot geom then
        self.last_e = np.zeros(shape)  # cum_e of its environment geom then
        self.k = 0

    def bounds(self) -> FloatArray:
        """(E, R) lower bounds on every pair's distance at knot ``self.k`` (inf: pair excluded)."""
        k = self.k
        travel = (self.cum_r[k][None, :] - self.last_r) + (self.cum_e[k][:, None] - self.last_e)
        # fmax: a NaN (an unbounded travel less itself) leaves the broad-phase bound.
        return np.fmax(self.sphere[k], self.last - travel - self.slack)

    def record(self, ei: int, ri: int, distance: float) -> None:
        self.last[ei, ri] = distance
        self.last_r[ei, ri] = self.cum_r[self.k, ri]
        self.last_e[ei, ri] = self.cum_e[self.k, ei]


def _sphere_box_bounds(
    model: mujoco.MjModel, layout: _Layout, centres: FloatArray, pos: FloatArray, rot: FloatArray
) -> FloatArray:
    """(..., E, R) lower bounds: robot bounding spheres (centres (..., R, 3)) vs environment oriented
    boxes (``geom_aabb`` in frames pos (..., E, 3), rot (..., E, 9), world = rot @ local)."""
    rot = rot.reshape(*rot.shape[:-1], 3, 3)
    rel = centres[..., None, :, :] - pos[..., :, None, :]  # (..., E, R, 3)
    local = np.matmul(rel, rot)  # local_j = sum_i rel_i rot_ij, per environment geom
    aabb = model.geom_aabb[layout.env]  # (E, 6): centre, half sizes in the geom frame
    outside = np.maximum(np.abs(local - aabb[:, None, :3]) - aabb[:, None, 3:], 0.0)
    gap = np.sqrt(np.einsum("...j,...j->...", outside, outside)) - model.geom_rbound[layout.robot]
    return np.asarray(gap, dtype=float)


class CollisionModel:
    """coal shapes of a world's geoms, built once; distance queries per configuration and trajectory.

    ``CollisionModel(world, risk_config)`` uses the scenario's uncertainty; see
    :meth:`from_setup` for any MuJoCo model. Not thread-safe (it owns one ``MjData``).

    Pairs: every robot geom (plus the carried object's geom, which moves to the
    robot side) against the table, obstacles and objects not carried, and the
    carried object against the robot's own geoms (its own pose error is that
    pair's sigma; the holding hand is allowed by the step); the floor is never a
    pair (feet stand on it) and robot-robot pairs are not considered.
    ``allow`` removes pairs per query: an environment geom/body name, or a (robot
    geom/body, environment geom/body) pair; see :meth:`hand_allow`
    (the hand vs the object it grasps) and :meth:`support_allow`
    (a carried object vs the table it leaves or reaches).

    Signed distances come from coal (``coal.ComputeDistance``; negative inside,
    via GJK/EPA; coal docs, "DistanceRequest.enable_signed_distance"). A broad
    phase bounds each pair from below by the distance of the robot geom's bounding
    sphere (``geom_rbound``) to the environment geom's oriented bounding box
    (``geom_aabb``) and calls coal only for pairs that can come within
    ``d_safety + margin + n_sigma * sigma``; the knot's minimum stays exact (pairs
    beyond are then visited in the order of their bounds until none can beat it).
    """

    def __init__(
        self,
        world: World,
        risk_config: RiskConfig | None = None,
        *,
        uncertainty: Uncertainty | None = None,
        margin: float = 0.02,
        n_sigma: float = 6.0,
    ) -> None:
        config = risk_config if risk_config is not None else world.scenario.risk
        self._init(
            world.model, CollisionSetup.from_world(world, config, uncertainty), config, margin, n_sigma
        )

    @classmethod
    def from_setup(
        cls,
        model: mujoco.MjModel,
        setup: CollisionSetup,
        risk_config: RiskConfig,
        *,
        margin: float = 0.02,
        n_sigma: float = 6.0,
    ) -> CollisionModel:
        """A model over any MuJoCo model with explicit geom groups."""
        self = cls.__new__(cls)
        self._init(model, setup, risk_config, margin, n_sigma)
        return self

    def _init(
        self, model: mujoco.MjModel, setup: CollisionSetup, config: RiskConfig, margin: float, n_sigma: float
    ) -> None:
        if config.d_safety <= 0.0:
            raise CollisionModelError(f"risk.d_safety must be > 0, got {config.d_safety}")
        self.model = model
        self.setup = setup
        self.risk_config = config
        self.margin = float(margin)
        self.n_sigma = float(n_sigma)
        self._data = mujoco.MjData(model)
        candidates = {*setup.robot_geoms, *setup.env_geoms, *setup.object_geoms.values()}
        self._shapes: dict[int, coal.CollisionGeometry] = {}
        for g in sorted(candidates):
            shape = coal_geometry(model, g)
            if shape is not None:  # planes and unsupported types are skipped
                self._shapes[g] = shape
        self._transforms = {g: coal.Transform3s() for g in self._shapes}
        self._functors: dict[tuple[int, int], coal.ComputeDistance] = {}
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._result = coal.DistanceResult()
        self._layouts: dict[tuple[str | None, frozenset[str | tuple[str, str]]], _Layout] = {}
        self._geom_names = [model.geom(g).name or f"geom{g}" for g in range(model.ngeom)]
        self._body_names = [model.body(b).name or f"body{b}" for b in range(model.nbody)]

    # --- names and allow sets ---------------------------------------------------------------

    def hand_allow(self, side: str, object_name: str) -> frozenset[tuple[str, str]]:
        """Pairs to allow while ``side``'s hand approaches or holds ``object_name``."""
        if side not in self.setup.hand_geoms:
            raise CollisionModelError(f"no hand '{side}'; sides: {sorted(self.setup.hand_geoms)}")
        obj = self._object_geom(object_name)
        return frozenset((self._geom_names[g], self._geom_names[obj]) for g in self.setup.hand_geoms[side])

    def support_allow(self, object_name: str) -> frozenset[tuple[str, str]]:
        """Pairs to allow while a carried object leaves or reaches its support (the table's geoms)."""
        obj = self._object_geom(object_name)
        return frozenset((self._geom_names[obj], self._geom_names[g]) for g in self.setup.support_geoms)

    def step_allow(
        self,
        side: str,
        kind: str,
        obj: str,
        allow_contact: tuple[str, ...],
        carried: tuple[str, str] | None,
    ) -> frozenset[tuple[str, str]]:
        """Pairs a motion step may bring into contact: the hand the object it grasps (a step whose
        ``allow_contact`` names it), the hand what it carries (or pushes), and a carried object its
        support while lifted, placed or pushed. The other hand near a carried object (a handover's receiver
        rising beside it) is not allowed: the failure detector calls that touch a collision."""
        allow: set[tuple[str, str]] = set()
        if obj in allow_contact:
            allow |= self.hand_allow(side, obj)
        if carried is not None:
            allow |= self.hand_allow(*carried)
        for name in allow_contact:  # an obstacle the hand presses (a press step names its target)
            pressed = self._resolve(name, self.setup.env_geoms) - set(self.setup.support_geoms)
            pressed -= set(self.setup.object_geoms.values())
            hand = self.setup.hand_geoms.get(side, ())
            allow |= {(self._geom_names[h], self._geom_names[g]) for h in hand for g in pressed}
        if kind in ("lift", "place", "push"):  # a pushed object slides on its support
            allow |= self.support_allow(obj)
        return frozenset(allow)

    def _object_geom(self, name: str) -> int:
        if name not in self.setup.object_geoms:
            raise CollisionModelError(f"no object '{name}'; objects: {sorted(self.setup.object_geoms)}")
        return int(self.setup.object_geoms[name])

    def _resolve(self, name: str, pool: Sequence[int]) -> set[int]:
        """Geoms of ``pool`` named ``name`` or on a body named ``name``."""
        found = {g for g in pool if self._geom_names[g] == name}
        found |= {g for g in pool if self._body_names[int(self.model.geom_bodyid[g])] == name}
        return found

    def warm(self, carried: str | None = None, allow: Allow = ()) -> None:
        """Build now the geom pairs of queries carrying ``carried`` with ``allow`` removed (the
        first such query would; built once and kept)."""
        self._layout(carried, allow)

    def _layout(self, carried: str | None, allow: Allow) -> _Layout:
        """The pairs of a query carrying ``carried`` with ``allow`` removed, built once and kept."""
        key = (carried, frozenset(allow))
        cached = self._layouts.get(key)
        if cached is not None:
            return cached
        carried_geom = self._object_geom(carried) if carried is not None else None
        robot: list[int] = [g for g in self.setup.robot_geoms if g in self._shapes]
        env = [g for g in self.setup.env_geoms if g in self._shapes and g != carried_geom]
        carried_row = carried_geom is not None and carried_geom in self._shapes
        if carried_geom is not None and carried_row:
            # The carried object is on the robot side against the scene, and on the scene side
            # against the robot's own geoms (the other hand may come near it; the holding hand's
            # pairs are allowed by the step). Its own pose error is then that pair's sigma.
            robot.append(carried_geom)
            env.append(carried_geom)
        mask = np.ones((len(env), len(robot)), dtype=bool)
        if carried_row:
            mask[-1, -1] = False  # the object against itself
        self._apply_allow(mask, allow, robot, env)
        cutoff = self._cutoffs(env, carried_geom)
        functors = [[self._functor(e, r) for r in robot] for e in env]
        layout = _Layout(
            robot=np.array(robot, dtype=int),
            env=np.array(env, dtype=int),
            mask=mask,
            cutoff=cutoff,
            robot_list=[int(g) for g in robot],
            env_list=[int(g) for g in env],
            env_body=[int(self.model.geom_bodyid[e]) for e in env],
            cutoff_list=[float(c) for c in cutoff],
            functors=functors,
            n_pairs=int(np.count_nonzero(mask)),
        )
        self._layouts[key] = layout
        return layout

    def _apply_allow(self, mask: NDArray[np.bool_], allow: Allow, robot: list[int], env: list[int]) -> None:
        """Clear the (E, R) ``mask``'s pairs that ``allow`` removes; CollisionModelError naming an
        item that is no environment geom or body, or no (robot, environment) pair."""
        for item in allow:
            if isinstance(item, str):
                cols = self._resolve(item, env)
                if not cols:
                    raise CollisionModelError(
                        f"allow: '{item}' is no environment geom or body; environment geoms: "
                        f"{sorted(self._geom_names[g] for g in env)}"
                    )
                for e in cols:
                    mask[env.index(e), :] = False
                continue
            rname, ename = item
            rows, cols = self._resolve(rname, robot), self._resolve(ename, env)
            if not rows or not cols:
                objects = {self._geom_names[g] for g in self.setup.object_geoms.values()}
                if rname in objects or ename in objects:
                    continue  # about an object on the other side than this query has it: no such pair
                raise CollisionModelError(
                    f"allow: ({rname!r}, {ename!r}) is not a (robot, environment) geom or body pair; "
                    f"robot geoms: {sorted(self._geom_names[g] for g in robot)}; environment geoms: "
                    f"{sorted(self._geom_names[g] for g in env)}"
                )
            for e in cols:
                for r in rows:
                    mask[env.index(e), robot.index(r)] = False

    def _cutoffs(self, env: list[int], carried_geom: int | None) -> FloatArray:
        """Broad-phase cutoff (m) per environment geom: ``d_safety + margin + n_sigma * sigma``,
        sigma its body's horizontal 1-sigma combined with a carried object's own."""
        # A carried object's own pose error widens the band in which its pairs are uncertain.
        own = self.carried_sigma.get(carried_geom, 0.0) if carried_geom is not None else 0.0
        cutoff = np.array(
            [
                self.d_safety(int(self.model.geom_bodyid[e]))
                + self.margin
                + self.n_sigma
                * math.hypot(self.setup.env_sigma.get(int(self.model.geom_bodyid[e]), 0.0), own)
                for e in env
            ]
        )
        return cutoff

    def _functor(self, env: int, robot: int) -> coal.ComputeDistance:
        """The cached coal distance functor of a pair (coal docs, ``ComputeDistance``)."""
        functor = self._functors.get((env, robot))
        if functor is None:
            functor = coal.ComputeDistance(self._shapes[env], self._shapes[robot])
            self._functors[(env, robot)] = functor
        return functor

    # --- queries ------------------------------------------------------------------------------

    def knot(
        self,
        qpos: FloatArray,
        *,
        carried: str | None = None,
        allow: Allow = (),
        broad_phase: bool = True,
        near: bool = True,
        shift: Mapping[int, float] | None = None,
    ) -> KnotDistance:
        """Closest approach at configuration ``qpos`` (a full qpos of the model).

        ``near=False``: the closest pair only (``near`` left empty): the pairs are visited
        nearest broad-phase bound first until no bound is below the best distance, instead of
        every pair within the cutoff first (which the collision probability needs). The same
        least distance, for a fraction of the pairs.
        ``shift``: environment body id -> metres added to its pairs' distances when choosing
        the closest pair (a live guard's per-obstacle limit); the distance returned is the
        chosen pair's own.
        """
        data = self._data
        data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, data)
        layout = self._layout(carried, allow)
        added = np.array([shift.get(b, 0.0) for b in layout.env_body]) if shift else None
        return self._knot_from_data(data, layout, broad_phase, near=near, shift=added)

    def profile(
        self, trajectory: TrajectoryLike, *, allow: Allow = (), broad_phase: bool = True
    ) -> CollisionProfile:
        """Closest approach at every knot of ``trajectory`` (its carried object on the robot side)."""
        carried = trajectory.carried[1] if trajectory.carried is not None else None
        layout = self._layout(carried, allow)
        qpos = np.asarray(trajectory.qpos, dtype=float)
        data = self._data
        knots = []
        travel = None
        if broad_phase and len(qpos):
            # First pass: every knot's geom poses, for the bounds of all knots at once.
            geoms = np.concatenate([layout.env, layout.robot])
            xpos, xmat = np.empty((len(qpos), len(geoms), 3)), np.empty((len(qpos), len(geoms), 9))
            for k, row in enumerate(qpos):
                data.qpos[:] = row
                mujoco.mj_kinematics(self.model, data)
                xpos[k], xmat[k] = data.geom_xpos[geoms], data.geom_xmat[geoms]
            travel = _TravelBound(self.model, layout, xpos, xmat)
        for k, row in enumerate(qpos):
            data.qpos[:] = row
            mujoco.mj_kinematics(self.model, data)
            if travel is not None:
                travel.k = k
            knots.append(self._knot_from_data(data, layout, broad_phase, travel))
        return CollisionProfile(np.asarray(trajectory.times, dtype=float), tuple(knots))

    def _lower_bounds(self, data: mujoco.MjData, layout: _Layout) -> FloatArray:
        """(E, R) broad-phase lower bounds: robot bounding sphere vs environment oriented box."""
        return _sphere_box_bounds(
            self.model,
            layout,
            data.geom_xpos[layout.robot],
            data.geom_xpos[layout.env],
            data.geom_xmat[layout.env],
        )

    def _place(self, data: mujoco.MjData, geom: int) -> None:
        """Copy ``geom``'s world pose from ``data`` into its coal transform."""
        tf = self._transforms[geom]
        tf.setRotation(data.geom_xmat[geom].reshape(3, 3))
        tf.setTranslation(data.geom_xpos[geom])

    def _pair_distance(self, layout: _Layout, ei: int, ri: int) -> float:
        """coal signed distance of layout pair (env ei, robot ri) at the placed transforms."""
        # The functor does not reset a reused result: without clear() the witness points and
        # normal can be those of an earlier, closer query (docs/measurements.md).
        self._result.clear()
        return float(
            layout.functors[ei][ri](
                self._transforms[layout.env_list[ei]],
                self._transforms[layout.robot_list[ri]],
                self._request,
                self._result,
            )
        )

    def _knot_from_data(
        self,
        data: mujoco.MjData,
        layout: _Layout,
        broad_phase: bool,
        travel: _TravelBound | None = None,
        *,
        near: bool = True,
        shift: FloatArray | None = None,
    ) -> KnotDistance:
        """:meth:`knot` at the kinematics in ``data``: coal on the broad phase's first pairs, then
        on the pairs beyond them nearest bound first while a bound is below the best distance.
        ``travel``: the profile's bounds at every knot (at its knot ``k``), told every distance;
        ``shift``: metres added per environment geom (layout order) when comparing pairs."""
        n_pairs = layout.n_pairs
        if n_pairs == 0:
            raise CollisionModelError("no robot-environment pair is left to check (all allowed)")
        bounds, first = self._first_pairs(data, layout, broad_phase, travel, near)
        env_ids, robot_ids = layout.env_list, layout.robot_list
        cand_e, cand_r = np.nonzero(first)
        placed_e, placed_r = self._place_first(data, layout, cand_e, cand_r)
        res = self._result
        cutoff = layout.cutoff_list
        best, best_e, best_r = math.inf, -1, -1
        witness = (np.zeros(3), np.zeros(3), np.zeros(3))
        near_pairs: list[NearPair] = []
        checked = 0
        pair_distance, env_body = self._pair_distance, layout.env_body
        record = travel.record if travel is not None else None

        def visit(ei: int, ri: int) -> None:
            nonlocal best, best_e, best_r, witness, checked
            d = pair_distance(layout, ei, ri)
            checked += 1
            if record is not None:
                record(ei, ri, d)
            if near and d <= cutoff[ei]:
                near_pairs.append(NearPair(env_body[ei], env_ids[ei], robot_ids[ri], d, np.array(res.normal)))
            key = d if shift is None else d + shift[ei]
            if key < best:
                best, best_e, best_r = key, ei, ri
                witness = (
                    np.array(res.getNearestPoint2()),
                    np.array(res.getNearestPoint1()),
                    np.array(res.normal),
                )

        for ei, ri in zip(cand_e.tolist(), cand_r.tolist(), strict=True):
            visit(ei, ri)
        if broad_phase:
            # Pairs beyond the cutoff, nearest bound first, until no bound is below the best.
            rest = np.where(first, np.inf, bounds if shift is None else bounds + shift[:, None])
            flat = rest.reshape(-1)
            below = np.flatnonzero(flat < best)  # best only falls: no other pair can beat it
            for idx in below[np.argsort(flat[below], kind="stable")].tolist():
                if flat[idx] >= best:  # the pair is excluded or already visited
                    break
                ei, ri = divmod(idx, rest.shape[1])
                self._place_pair(data, layout, placed_e, placed_r, ei, ri)
                visit(ei, ri)
        if shift is not None and best_e >= 0:
            best -= shift[best_e]
        return self._knot_distance(
            best, env_ids[best_e], robot_ids[best_r], witness, checked, n_pairs, near_pairs
        )

    def _first_pairs(
        self, data: mujoco.MjData, layout: _Layout, broad_phase: bool, travel: _TravelBound | None, near: bool
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """(E, R) broad-phase lower bounds (inf: excluded pair; -inf for all considered pairs
        without the broad phase) and the pairs to visit first: those within the cutoff if
        ``near`` (all of them are wanted), else none; without the broad phase every pair."""
        if not broad_phase:
            return np.where(layout.mask, -np.inf, np.inf), layout.mask
        if travel is not None:
            bounds = travel.bounds()  # excluded pairs already at inf
        else:
            bounds = np.where(layout.mask, self._lower_bounds(data, layout), np.inf)
        return bounds, (bounds <= layout.cutoff[:, None] if near else np.zeros_like(layout.mask))

    def _place_first(
        self, data: mujoco.MjData, layout: _Layout, cand_e: NDArray[np.int_], cand_r: NDArray[np.int_]
    ) -> tuple[list[bool], list[bool]]:
        """Place the coal transforms of the geoms of the first pairs; returns which environment
        and which robot geoms (layout order) are placed."""
        placed_e = [False] * len(layout.env_list)
        placed_r = [False] * len(layout.robot_list)
        for ei in set(cand_e.tolist()):
            self._place(data, layout.env_list[ei])
            placed_e[ei] = True
        for ri in set(cand_r.tolist()):
            self._place(data, layout.robot_list[ri])
            placed_r[ri] = True
        return placed_e, placed_r

    def _place_pair(
        self,
        data: mujoco.MjData,
        layout: _Layout,
        placed_e: list[bool],
        placed_r: list[bool],
        ei: int,
        ri: int,
    ) -> None:
        """Place the coal transforms of layout pair (env ei, robot ri) unless they are placed."""
        if not placed_e[ei]:
            self._place(data, layout.env_list[ei])
            placed_e[ei] = True
        if not placed_r[ri]:
            self._place(data, layout.robot_list[ri])
            placed_r[ri] = True

    def _knot_distance(
        self,
        best: float,
        env: int,
        robot: int,
        witness: tuple[FloatArray, FloatArray, FloatArray],
        checked: int,
        n_pairs: int,
        near_pairs: list[NearPair],
    ) -> KnotDistance:
        """The knot's closest approach: distance ``best`` between geoms ``env`` and ``robot``,
        with its witness points (robot, environment) and normal, and the pairs coal checked."""
        point_robot, point_env, normal = witness
        config = self.risk_config
        risk, scaled = _risk(best, config.d_safety, config.collision.exponent), None
        if self.setup.env_clearance and best < math.inf:
            # Each pair against its body's own d_safety: the knot's risk is the largest.
            ratio = min(
                [
                    best / self.d_safety(int(self.model.geom_bodyid[env])),
                    *(p.distance / self.d_safety(p.env_body) for p in near_pairs),
                ]
            )
            scaled = ratio * config.d_safety
            risk = _risk(ratio, 1.0, config.collision.exponent)
        return KnotDistance(
            distance=best,
            robot_geom=robot,
            env_geom=env,
            robot_geom_name=self._geom_names[robot],
            env_geom_name=self._geom_names[env],
            robot_body_name=self._body_names[int(self.model.geom_bodyid[robot])],
            env_body_name=self._body_names[int(self.model.geom_bodyid[env])],
            point_robot=point_robot,
            point_env=point_env,
            normal=normal,
            risk=risk,
            pairs_checked=checked,
            pairs_skipped=n_pairs - checked,
            near=tuple(near_pairs),
            scaled=scaled,
        )

    def d_safety(self, env_body: int) -> float:
        """The collision metric's ``d_safety`` (m) for an environment body: its own clearance,
        else ``risk.d_safety``."""
        return float(self.setup.env_clearance.get(env_body, self.risk_config.d_safety))

    def body_name(self, body: int) -> str:
        """The MuJoCo name of body ``body``."""
        return self._body_names[body]

    def severity(self, env_body: int) -> float:
        """The loss of touching an environment body (before the body-part factor): its own
        severity, else ``risk.severity.collision``."""
        return float(self.setup.env_severity.get(env_body, self.risk_config.severity.collision))

    @property
    def carried_sigma(self) -> dict[int, float]:
        """Object geom -> its horizontal 1-sigma, which it keeps when carried (see
        :func:`collision_probability`)."""
        return {
            int(g): float(self.setup.env_sigma.get(int(self.model.geom_bodyid[g]), 0.0))
            for g in self.setup.object_geoms.values()
        }

    def body_part(self, geom: int) -> tuple[str, float]:
        """(part name, severity factor) of the robot body of ``geom``; ("other", 1.0) if unlisted."""
        return self.setup.part_factors.get(int(self.model.geom_bodyid[geom]), ("other", 1.0))


# --- trajectory report --------------------------------------------------------------------------


def assess_collision(
    model: CollisionModel,
    trajectory: TrajectoryLike,
    *,
    allow: Allow = (),
    broad_phase: bool = True,
) -> RiskReport:
    """Collision risk of ``trajectory``: seed score, first-order P(collision) and severity."""
    return report_from_profile(model, model.profile(trajectory, allow=allow, broad_phase=broad_phase))


def report_from_profile(model: CollisionModel, prof: CollisionProfile) -> RiskReport:
    """The collision RiskReport of a distance profile (one trajectory, or several steps joined).

    Severity = ``severity.collision`` x the body-part factor of the robot body in the
    closest approach (Long et al. 2018, conclusion: more sensitive parts such as cameras
    weigh more); with obstacles of their own severity, the collision severity is the mean of
    the bodies' severities weighted by their probabilities, so that the expected loss is
    ``P x factor x sum_b P_b s_b / sum_b P_b`` (each body's share linear in its severity).
    Probability: first order, union over all knots (see the module doc). With breach
    obstacles, ``details`` adds the probability of touching any of them and its expected loss.
    """
    config = model.risk_config
    distances = prof.distances
    seed = seed_collision_score(prof.times, prof.scaled_distances, config.d_safety, config.collision)
    prob = collision_probability(
        [k.near for k in prof.knots], model.setup.env_sigma, robot_sigma=model.carried_sigma
    )
    k_min = int(np.argmin(distances))
    closest = prof.knots[k_min]
    part, factor = model.body_part(closest.robot_geom)
    details: dict[str, float | str] = {
        "min_distance": float(closest.distance),
        "min_distance_time": float(prof.times[k_min]),
        "closest_robot_geom": closest.robot_geom_name,
        "closest_env_geom": closest.env_geom_name,
        "closest_robot_body": closest.robot_body_name,
        "closest_env_body": closest.env_body_name,
        "body_part": part,
        "body_part_factor": factor,
        "peak_term": seed.peak,
        "exposure_term": seed.exposure,
        "pairs_checked": float(prof.pairs_checked),
        "pairs_skipped": float(prof.pairs_skipped),
        "probability_method": "first-order union over knots (static Gaussian pose error per body, "
        "a carried object's own error included)",
    }
    severity = _weighted_severity(model, prob.per_body, model.setup.env_severity.keys())
    if model.setup.breach_bodies:
        details.update(_breach_details(model, prob.per_body, factor))
    return RiskReport(
        mode="collision",
        probability=prob.probability,
        probability_bounds=(prob.lower, prob.upper),
        severity=severity * factor,
        seed_score=seed.score,
        times=prof.times,
        traces={
            "distance": distances,
            "instantaneous_risk": prof.risks,
            "probability": prob.per_knot,
        },
        details=details,
    )


def _weighted_severity(
    model: CollisionModel, per_body: Mapping[int, float], bodies: Collection[int]
) -> float:
    """The collision severity: ``risk.severity.collision``, or with ``bodies`` (of their own
    severity) in the scene the bodies' severities weighted by their touch probabilities."""
    base = float(model.risk_config.severity.collision)
    total = sum(per_body.values())
    if not bodies or total <= 0.0:
        return base
    return sum(p * model.severity(b) for b, p in per_body.items()) / total


def _breach_details(
    model: CollisionModel, per_body: Mapping[int, float], factor: float
) -> dict[str, float | str]:
    """P(touching any breach obstacle) (independent bodies, as the union over bodies) and its
    expected loss: that probability x the breach bodies' probability-weighted severity x the
    body-part factor."""
    breach = {b: p for b, p in per_body.items() if b in model.setup.breach_bodies}
    miss = 1.0
    for p in breach.values():
        miss *= 1.0 - p
    total = sum(breach.values())
    mean = sum(p * model.severity(b) for b, p in breach.items()) / total if total > 0.0 else 0.0
    # the breach bodies with a probability above 0, most likely first
    touched = sorted(
        (b for b, p in breach.items() if p > 0.0), key=lambda b: (-breach[b], model.body_name(b))
    )
    names = [model.body_name(b) for b in touched]
    return {
        "breach_probability": 1.0 - miss,
        "breach_expected_loss": (1.0 - miss) * mean * factor,
        "breach_bodies": ", ".join(names),
    }


def breach_summary(report: RiskReport) -> dict[str, float | str] | None:
    """The breach part of a collision report, for tables and logs: ``{"probability",
    "expected_loss", "bodies"}`` (the breach bodies of a probability above 0, most likely
    first, comma-separated; empty if none); None when the scene has no breach obstacle."""
    details = report.details
    if "breach_probability" not in details:
        return None
    return {
        "probability": float(details["breach_probability"]),
        "expected_loss": float(details["breach_expected_loss"]),
        "bodies": str(details["breach_bodies"]),
    }


# --- Monte Carlo validation -----------------------------------------------------------------------


class MonteCarloResult(NamedTuple):
    """Sampled P(collision): over the trajectory and per knot, with standard errors."""

    probability: float
    stderr: float
    per_knot: FloatArray
    samples: int
    coal_calls: int


def monte_carlo_collision_probability(
    model: CollisionModel,
    trajectory: TrajectoryLike,
    rng: np.random.Generator,
    samples: int = 10_000,
    *,
    allow: Allow = (),
) -> MonteCarloResult:
    """P(d < 0 at some knot) with every uncertain environment body shifted by ``N(0, sigma^2 I_2)``.

    One shift per body per sample, held over the whole trajectory (a truth world). Exact
    coal distances; a pair is recomputed only in samples whose shift can close its
    nominal broad-phase lower bound (``|delta| >= bound``), so the answer is unaffected.
    """
    if samples <= 0:
        raise CollisionModelError(f"samples must be > 0, got {samples}")
    carried = trajectory.carried[1] if trajectory.carried is not None else None
    layout = model._layout(carried, allow)
    mdl = model.model
    draws = _draw_shifts(model, layout, carried, rng, samples)
    qpos = np.asarray(trajectory.qpos, dtype=float)
    hit_any = np.zeros(samples, dtype=bool)
    per_knot = np.zeros(len(qpos))
    data = model._data
    calls = 0
    for k, row in enumerate(qpos):
        data.qpos[:] = row
        mujoco.mj_kinematics(mdl, data)
        bounds = model._lower_bounds(data, layout)
        hit = np.zeros(samples, dtype=bool)
        for ei, ri in zip(*np.nonzero(layout.mask), strict=True):
            calls += _sampled_hits(model, data, layout, ei, ri, bounds[ei, ri], draws, hit)
        per_knot[k] = float(np.mean(hit))
        hit_any |= hit
    p = float(np.mean(hit_any))
    return MonteCarloResult(p, math.sqrt(max(p * (1.0 - p), 1e-300) / samples), per_knot, samples, calls)


class _Shifts(NamedTuple):
    """The Monte Carlo samples' pose errors: each environment geom's body (layout order), each
    uncertain body's (samples, 2) shifts and their lengths, the carried object's geom (None)
    with its own sigma, shifts and their lengths, and zero shifts."""

    env_bodies: list[int]
    by_body: dict[int, FloatArray]
    radius: dict[int, FloatArray]
    carried_geom: int | None
    own_sigma: float
    own: FloatArray
    own_radius: FloatArray
    zero: FloatArray


def _draw_shifts(
    model: CollisionModel, layout: _Layout, carried: str | None, rng: np.random.Generator, samples: int
) -> _Shifts:
    """Draw all shifts up front, bodies in sorted id order (same generator state, same answer);
    then the carried object's own shift (it sits in the hand wherever it really was)."""
    env_bodies = [int(model.model.geom_bodyid[e]) for e in layout.env]
    uncertain = sorted({b for b in env_bodies if model.setup.env_sigma.get(b, 0.0) > 0.0})
    shifts = {b: rng.normal(0.0, model.setup.env_sigma[b], size=(samples, 2)) for b in uncertain}
    carried_geom = model._object_geom(carried) if carried is not None else None
    own_sigma = model.carried_sigma.get(carried_geom, 0.0) if carried_geom is not None else 0.0
    zero = np.zeros((samples, 2))
    own = rng.normal(0.0, own_sigma, size=(samples, 2)) if own_sigma > 0.0 else zero
    own_radius = np.hypot(own[:, 0], own[:, 1])
    radius = {b: np.hypot(s[:, 0], s[:, 1]) for b, s in shifts.items()}
    return _Shifts(env_bodies, shifts, radius, carried_geom, own_sigma, own, own_radius, zero)


def _sampled_hits(
    model: CollisionModel,
    data: mujoco.MjData,
    layout: _Layout,
    ei: np.intp,
    ri: np.intp,
    bound: float,
    draws: _Shifts,
    hit: NDArray[np.bool_],
) -> int:
    """Mark in ``hit`` the samples in which layout pair (env ei, robot ri), ``bound`` its nominal
    broad-phase lower bound at the knot in ``data``, penetrates; returns the coal calls made."""
    env, robot, body = layout.env_list[ei], layout.robot_list[ri], draws.env_bodies[ei]
    model._place(data, env)
    model._place(data, robot)
    moves = robot == draws.carried_geom and draws.own_sigma > 0.0
    if body not in draws.by_body and not moves:
        if bound <= 0.0:
            if model._pair_distance(layout, int(ei), int(ri)) < 0.0:
                hit[:] = True
            return 1
        return 0
    calls = 0
    # Only shifts at least as long together as the pair's lower bound can close it.
    env_shift = draws.by_body.get(body, draws.zero)
    reach = draws.radius.get(body, draws.zero[:, 0]) + (draws.own_radius if moves else 0.0)
    env_transform, robot_transform = model._transforms[env], model._transforms[robot]
    env_nominal = np.array(data.geom_xpos[env], dtype=float)
    robot_nominal = np.array(data.geom_xpos[robot], dtype=float)
    for s in np.nonzero(reach >= bound)[0]:
        if hit[s]:
            continue
        dx, dy = env_shift[s]
        env_transform.setTranslation(env_nominal + np.array([dx, dy, 0.0]))
        if moves:
            ox, oy = draws.own[s]
            robot_transform.setTranslation(robot_nominal + np.array([ox, oy, 0.0]))
        calls += 1
        if model._pair_distance(layout, int(ei), int(ri)) < 0.0:
            hit[s] = True
    model._place(data, env)
    model._place(data, robot)
    return calls
