"""The geom pairs of the collision model and their coal signed distances.

:class:`CollisionPairs` holds the coal shape of every robot and environment geom of a
:class:`executive.risk.collision_setup.CollisionSetup`, builds the pairs of a query (carried
object, ``allow`` set) once and keeps them, and computes one pair's coal distance at the poses
placed from an ``MjData``. It is the base of :class:`executive.risk.collision_model.CollisionModel`,
which adds the per-knot and per-trajectory queries; the allow sets and the per-body losses and
sigmas (``d_safety``, ``severity``, ``body_part``, ``carried_sigma``) are read from here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import coal
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision_bounds import sphere_box_bounds
from executive.risk.collision_probability import CollisionModelError
from executive.risk.collision_setup import Allow, CollisionSetup, PairLayout
from executive.risk.shapes import coal_geometry
from executive.schema.types import RiskConfig

__all__ = ["CollisionPairs"]

FloatArray = NDArray[np.float64]


class CollisionPairs:
    """coal shapes of a setup's geoms, built once; the geom pairs of a query and their distances.

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
    via GJK/EPA; coal docs, "DistanceRequest.enable_signed_distance"). Not thread-safe (it
    owns one ``MjData`` and one coal result).

    Args:
        model: the MuJoCo model the setup's geom ids index.
        setup: the robot and environment geom groups and their sigmas.
        risk_config: the scenario's ``risk`` (``d_safety``, the severities).
        margin: metres added to ``d_safety`` in the broad phase's cutoff.
        n_sigma: sigmas of a body's pose error added to the cutoff.

    Raises:
        CollisionModelError: ``risk_config.d_safety`` is not above 0.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        setup: CollisionSetup,
        risk_config: RiskConfig,
        *,
        margin: float = 0.02,
        n_sigma: float = 6.0,
    ) -> None:
        if risk_config.d_safety <= 0.0:
            raise CollisionModelError(f"risk.d_safety must be > 0, got {risk_config.d_safety}")
        self.model = model
        self.setup = setup
        self.risk_config = risk_config
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
        self._spare = coal.DistanceResult()  # a knot's best pair keeps its result while others are queried
        self._geom_body = [int(b) for b in model.geom_bodyid]
        self._layouts: dict[tuple[str | None, frozenset[str | tuple[str, str]]], PairLayout] = {}
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

    # --- the pairs of a query ---------------------------------------------------------------

    def warm(self, carried: str | None = None, allow: Allow = ()) -> None:
        """Build now the geom pairs of queries carrying ``carried`` with ``allow`` removed (the
        first such query would; built once and kept)."""
        self._layout(carried, allow)

    def _layout(self, carried: str | None, allow: Allow) -> PairLayout:
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
        layout = PairLayout(
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

    # --- coal distances ---------------------------------------------------------------------

    def _lower_bounds(self, xpos: FloatArray, xmat: FloatArray, layout: PairLayout) -> FloatArray:
        """(E, R) broad-phase lower bounds at the geom poses ``xpos`` (ngeom, 3), ``xmat`` (ngeom, 9):
        robot bounding sphere vs environment oriented box."""
        return sphere_box_bounds(self.model, layout, xpos[layout.robot], xpos[layout.env], xmat[layout.env])

    def _place(self, data: mujoco.MjData, geom: int) -> None:
        """Copy ``geom``'s world pose from ``data`` into its coal transform."""
        self._place_pose(data.geom_xpos, data.geom_xmat, geom)

    def _place_pose(self, xpos: FloatArray, xmat: FloatArray, geom: int) -> None:
        """Copy ``geom``'s world pose from poses of every geom (``xpos`` (ngeom, 3), ``xmat``
        (ngeom, 9), as ``MjData.geom_xpos`` and ``geom_xmat``) into its coal transform."""
        tf = self._transforms[geom]
        tf.setRotation(xmat[geom].reshape(3, 3))
        tf.setTranslation(xpos[geom])

    def _pair_distance(
        self, layout: PairLayout, ei: int, ri: int, result: coal.DistanceResult | None = None
    ) -> float:
        """coal signed distance of layout pair (env ei, robot ri) at the placed transforms, its
        witness points and normal left in ``result`` (default: the model's own result)."""
        res = self._result if result is None else result
        # The functor does not reset a reused result: without clear() the witness points and
        # normal can be those of an earlier, closer query (docs/measurements.md).
        res.clear()
        return float(
            layout.functors[ei][ri](
                self._transforms[layout.env_list[ei]],
                self._transforms[layout.robot_list[ri]],
                self._request,
                res,
            )
        )

    # --- per-body losses and sigmas --------------------------------------------------------

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
        :func:`executive.risk.collision_probability.collision_probability`)."""
        return {
            int(g): float(self.setup.env_sigma.get(int(self.model.geom_bodyid[g]), 0.0))
            for g in self.setup.object_geoms.values()
        }

    def body_part(self, geom: int) -> tuple[str, float]:
        """(part name, severity factor) of the robot body of ``geom``; ("other", 1.0) if unlisted."""
        return self.setup.part_factors.get(int(self.model.geom_bodyid[geom]), ("other", 1.0))
