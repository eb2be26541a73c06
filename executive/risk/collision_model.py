"""The closest robot-environment approach at a configuration and along a trajectory.

:class:`CollisionModel` (``CollisionModel(world)``, or :meth:`CollisionModel.from_setup` for any
MuJoCo model) answers :meth:`CollisionModel.knot` (one configuration) and
:meth:`CollisionModel.profile` (every knot of a trajectory) with :class:`KnotDistance` records:
the signed minimum distance, its witness points and normal, the seed's instantaneous risk and
every pair near enough for the collision probability. Re-exported by
:mod:`executive.risk.collision`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision_bounds import TravelBound
from executive.risk.collision_pairs import CollisionPairs
from executive.risk.collision_probability import CollisionModelError, NearPair
from executive.risk.collision_seed import scalar_risk
from executive.risk.collision_setup import Allow, CollisionSetup, PairLayout
from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World

__all__ = ["CollisionModel", "CollisionProfile", "KnotDistance", "TrajectoryLike"]

FloatArray = NDArray[np.float64]


class TrajectoryLike(Protocol):
    """What the collision model reads of a trajectory (``executive.planning.planner.Trajectory``)."""

    @property
    def times(self) -> FloatArray: ...

    @property
    def qpos(self) -> FloatArray: ...

    @property
    def carried(self) -> tuple[str, str] | None: ...


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


class CollisionModel(CollisionPairs):
    """Distance queries per configuration and trajectory over the pairs of :class:`CollisionPairs`.

    ``CollisionModel(world, risk_config)`` uses the scenario's uncertainty; see
    :meth:`from_setup` for any MuJoCo model. Not thread-safe (it owns one ``MjData``).
    The pairs, ``allow`` and the allow sets: :class:`CollisionPairs`.

    A broad phase bounds each pair from below by the distance of the robot geom's bounding
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
        super().__init__(
            world.model,
            CollisionSetup.from_world(world, config, uncertainty),
            config,
            margin=margin,
            n_sigma=n_sigma,
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
        CollisionPairs.__init__(self, model, setup, risk_config, margin=margin, n_sigma=n_sigma)
        return self

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
        return self._knot_at(data.geom_xpos, data.geom_xmat, layout, broad_phase, near=near, shift=added)

    def profile(
        self, trajectory: TrajectoryLike, *, allow: Allow = (), broad_phase: bool = True
    ) -> CollisionProfile:
        """Closest approach at every knot of ``trajectory`` (its carried object on the robot side)."""
        carried = trajectory.carried[1] if trajectory.carried is not None else None
        layout = self._layout(carried, allow)
        xpos, xmat = self._poses(np.asarray(trajectory.qpos, dtype=float))
        travel = None
        if broad_phase and len(xpos):
            geoms = np.concatenate([layout.env, layout.robot])
            travel = TravelBound(self.model, layout, xpos[:, geoms], xmat[:, geoms])
        knots = []
        for k in range(len(xpos)):
            if travel is not None:
                travel.k = k
            knots.append(self._knot_at(xpos[k], xmat[k], layout, broad_phase, travel))
        return CollisionProfile(np.asarray(trajectory.times, dtype=float), tuple(knots))

    def _poses(self, qpos: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Every geom's world pose at every knot of ``qpos`` (K, nq): (K, ngeom, 3) positions and
        (K, ngeom, 9) rotation matrices, one ``mj_kinematics`` per knot."""
        data, model = self._data, self.model
        xpos, xmat = np.empty((len(qpos), model.ngeom, 3)), np.empty((len(qpos), model.ngeom, 9))
        for k, row in enumerate(qpos):
            data.qpos[:] = row
            mujoco.mj_kinematics(model, data)
            xpos[k], xmat[k] = data.geom_xpos, data.geom_xmat
        return xpos, xmat

    def _knot_at(
        self,
        xpos: FloatArray,
        xmat: FloatArray,
        layout: PairLayout,
        broad_phase: bool,
        travel: TravelBound | None = None,
        *,
        near: bool = True,
        shift: FloatArray | None = None,
    ) -> KnotDistance:
        """:meth:`knot` at the geom poses ``xpos`` (ngeom, 3), ``xmat`` (ngeom, 9): coal on the
        broad phase's first pairs, then on the pairs beyond them nearest bound first while a bound
        is below the best distance. ``travel``: the profile's bounds at every knot (at its knot
        ``k``), told every distance; ``shift``: metres added per environment geom (layout order)
        when comparing pairs."""
        n_pairs = layout.n_pairs
        if n_pairs == 0:
            raise CollisionModelError("no robot-environment pair is left to check (all allowed)")
        bounds, first = self._first_pairs(xpos, xmat, layout, broad_phase, travel, near)
        env_ids, robot_ids = layout.env_list, layout.robot_list
        cand_e, cand_r = np.nonzero(first)
        cand_e_list, cand_r_list = cand_e.tolist(), cand_r.tolist()
        placed_e, placed_r = self._place_first(xpos, xmat, layout, cand_e_list, cand_r_list)
        # Two coal results: the best pair's is kept (its witness) while the next pair is queried.
        results = [self._result, self._spare]
        cutoff, env_body, pair_distance = layout.cutoff_list, layout.env_body, self._pair_distance
        best, best_e, best_r, kept = math.inf, -1, -1, 1
        near_pairs: list[NearPair] = []
        checked = 0
        record = travel.record if travel is not None else None

        def visit(ei: int, ri: int) -> None:
            nonlocal best, best_e, best_r, kept, checked
            res = results[1 - kept]
            d = pair_distance(layout, ei, ri, res)
            checked += 1
            if record is not None:
                record(ei, ri, d)
            if near and d <= cutoff[ei]:
                near_pairs.append(NearPair(env_body[ei], env_ids[ei], robot_ids[ri], d, np.array(res.normal)))
            key = d if shift is None else d + shift[ei]
            if key < best:
                best, best_e, best_r, kept = key, ei, ri, 1 - kept

        for ei, ri in zip(cand_e_list, cand_r_list, strict=True):
            visit(ei, ri)
        # A pair beyond the first has its bound above its cutoff: none can beat a best below them all.
        if broad_phase and (shift is not None or best > min(cutoff)):
            # Pairs beyond the cutoff, nearest bound first, until no bound is below the best.
            rest = np.where(first, np.inf, bounds if shift is None else bounds + shift[:, None])
            flat = rest.reshape(-1)
            below = np.flatnonzero(flat < best)  # best only falls: no other pair can beat it
            for idx in below[np.argsort(flat[below], kind="stable")].tolist():
                if flat[idx] >= best:  # the pair is excluded or already visited
                    break
                ei, ri = divmod(idx, rest.shape[1])
                self._place_pair(xpos, xmat, layout, placed_e, placed_r, ei, ri)
                visit(ei, ri)
        witness = (np.zeros(3), np.zeros(3), np.zeros(3))
        if best_e >= 0:
            res = results[kept]
            point_robot, point_env = np.array(res.getNearestPoint2()), np.array(res.getNearestPoint1())
            witness = (point_robot, point_env, np.array(res.normal))
        if shift is not None and best_e >= 0:
            best -= shift[best_e]
        return self._knot_distance(
            best, env_ids[best_e], robot_ids[best_r], witness, checked, n_pairs, near_pairs
        )

    def _first_pairs(
        self,
        xpos: FloatArray,
        xmat: FloatArray,
        layout: PairLayout,
        broad_phase: bool,
        travel: TravelBound | None,
        near: bool,
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """(E, R) broad-phase lower bounds (inf: excluded pair; -inf for all considered pairs
        without the broad phase) and the pairs to visit first: those within the cutoff if
        ``near`` (all of them are wanted), else none; without the broad phase every pair."""
        if not broad_phase:
            return np.where(layout.mask, -np.inf, np.inf), layout.mask
        if travel is not None:
            bounds = travel.bounds()  # excluded pairs already at inf
        else:
            bounds = np.where(layout.mask, self._lower_bounds(xpos, xmat, layout), np.inf)
        return bounds, (bounds <= layout.cutoff[:, None] if near else np.zeros_like(layout.mask))

    def _place_first(
        self, xpos: FloatArray, xmat: FloatArray, layout: PairLayout, cand_e: list[int], cand_r: list[int]
    ) -> tuple[list[bool], list[bool]]:
        """Place the coal transforms of the geoms of the first pairs (layout indices ``cand_e``,
        ``cand_r``); returns which environment and which robot geoms (layout order) are placed."""
        placed_e = [False] * len(layout.env_list)
        placed_r = [False] * len(layout.robot_list)
        for ei in set(cand_e):
            self._place_pose(xpos, xmat, layout.env_list[ei])
            placed_e[ei] = True
        for ri in set(cand_r):
            self._place_pose(xpos, xmat, layout.robot_list[ri])
            placed_r[ri] = True
        return placed_e, placed_r

    def _place_pair(
        self,
        xpos: FloatArray,
        xmat: FloatArray,
        layout: PairLayout,
        placed_e: list[bool],
        placed_r: list[bool],
        ei: int,
        ri: int,
    ) -> None:
        """Place the coal transforms of layout pair (env ei, robot ri) unless they are placed."""
        if not placed_e[ei]:
            self._place_pose(xpos, xmat, layout.env_list[ei])
            placed_e[ei] = True
        if not placed_r[ri]:
            self._place_pose(xpos, xmat, layout.robot_list[ri])
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
        risk, scaled = scalar_risk(best, config.d_safety, config.collision.exponent), None
        if self.setup.env_clearance and best < math.inf:
            # Each pair against its body's own d_safety: the knot's risk is the largest.
            ratio = min(
                [
                    best / self.d_safety(self._geom_body[env]),
                    *(p.distance / self.d_safety(p.env_body) for p in near_pairs),
                ]
            )
            scaled = ratio * config.d_safety
            risk = scalar_risk(ratio, 1.0, config.collision.exponent)
        return KnotDistance(
            distance=best,
            robot_geom=robot,
            env_geom=env,
            robot_geom_name=self._geom_names[robot],
            env_geom_name=self._geom_names[env],
            robot_body_name=self._body_names[self._geom_body[robot]],
            env_body_name=self._body_names[self._geom_body[env]],
            point_robot=point_robot,
            point_env=point_env,
            normal=normal,
            risk=risk,
            pairs_checked=checked,
            pairs_skipped=n_pairs - checked,
            near=tuple(near_pairs),
            scaled=scaled,
        )
