"""The geom pairs the whole-body planner keeps apart, their clearance, and the collision limit.

:class:`CollisionPairs` is built once per world (by
:class:`~executive.planning.problem.PlanningProblem`): it sorts the geoms into each arm's, the
rest of the body's and the environment's, pairs the groups for a move (a carried object with
its hand's arm), gives each pair its required clearance and builds the
:class:`~executive.planning.limits.GeomPairCollisionLimit` of a request, kept for the next move.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.limits import GeomPairCollisionLimit, geom_pairs
from executive.planning.types import PlannerConfig, PlanningInputError
from executive.world.model import World, is_descendant

__all__ = ["CollisionPairs"]

FloatArray = NDArray[np.float64]

#: A move's request as far as the collision pairs go: (carried, allow_contact).
_Key = tuple[tuple[str, str] | None, tuple[str, ...]]


class CollisionPairs:
    """The planner's collision pairs on one world: each arm (and a carried object) against the
    table, obstacles and other objects, the arms against each other and the rest of the body.

    The pairs and the collision limit of each (carried, allow_contact) are built on first use and
    kept: they depend on the model and the request only.

    Args:
        world: the (estimate) world whose model the planner plans on.
        config: the planner's tuning (clearances, the collision limit's gains).
    """

    def __init__(self, world: World, config: PlannerConfig) -> None:
        self.world = world
        self.config = config
        self.model = world.model
        self.sides: tuple[str, ...] = tuple(sorted(world.ids.hand_sites))
        self._pairs: dict[_Key, list[tuple[int, int]]] = {}
        self._limits: dict[_Key, tuple[GeomPairCollisionLimit, FloatArray]] = {}
        self._collision_groups()

    def _collision_groups(self) -> None:
        """Geom groups: each arm's subtree, the rest of the body, and the environment."""
        model, ids = self.model, self.world.ids
        self.arm_geoms: dict[str, list[int]] = {}
        for side in self.sides:
            root = int(model.jnt_bodyid[ids.arm_joints[side][0]])
            subtree = {b for b in ids.robot_bodies if is_descendant(model, b, root)}
            self.arm_geoms[side] = [g for g in ids.robot_geoms if int(model.geom_bodyid[g]) in subtree]
        in_arms = {g for gs in self.arm_geoms.values() for g in gs}
        self.body_geoms = [g for g in ids.robot_geoms if g not in in_arms]
        self.static_env = [g for g in ids.table_geoms] + list(ids.obstacle_geoms.values())
        self.geom_names = {
            str(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)): g
            for g in range(model.ngeom)
            if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
        }

    def pairs(
        self, carried: tuple[str, str] | None = None, allow_contact: Sequence[str] = ()
    ) -> list[tuple[int, int]]:
        """Geom pairs the planner keeps apart for a move (after ``allow_contact`` is removed).

        Args:
            carried: (hand side, object name) of a carried object.
            allow_contact: names of geoms the robot may touch.

        Returns:
            The geom pairs (a copy of the kept list).

        Raises:
            PlanningInputError: when ``allow_contact`` names no geom of the model.
        """
        key = (carried, tuple(allow_contact))
        cached = self._pairs.get(key)
        if cached is None:
            cached = self._pairs[key] = self._collision_pairs(carried, allow_contact)
        return list(cached)

    def _collision_pairs(
        self, carried: tuple[str, str] | None, allow_contact: Sequence[str]
    ) -> list[tuple[int, int]]:
        ids = self.world.ids
        allowed = self.allowed_geoms(allow_contact)
        carried_geom = ids.object_geoms[carried[1]] if carried else None
        objects = [g for g in ids.object_geoms.values() if g != carried_geom]
        env = self.static_env + objects
        groups: list[tuple[Sequence[int], Sequence[int]]] = []
        for side in self.sides:
            groups += [(self.arm_geoms[side], env), (self.arm_geoms[side], self.body_geoms)]
        for i, a in enumerate(self.sides):
            for b in self.sides[i + 1 :]:
                groups.append((self.arm_geoms[a], self.arm_geoms[b]))
        if carried is not None and carried_geom is not None:
            others = [g for s in self.sides if s != carried[0] for g in self.arm_geoms[s]]
            groups.append(([carried_geom], env + self.body_geoms + others))
        return [p for p in geom_pairs(self.model, groups) if not allowed & set(p)]

    def required_clearance(self, pairs: Sequence[tuple[int, int]]) -> FloatArray:
        """Clearance (m) each pair must keep: an obstacle's own ``clearance`` against that
        obstacle, ``table_distance`` against the table, else ``min_distance``.

        Args:
            pairs: geom pairs.

        Returns:
            The clearance of each pair (m).
        """
        table = set(self.world.ids.table_geoms)
        geoms = self.world.ids.obstacle_geoms
        own = {
            geoms[b.name]: b.clearance
            for b in self.world.scenario.scene.obstacles
            if b.clearance is not None and geoms.get(b.name, -1) >= 0
        }
        cfg = self.config

        def required(a: int, b: int) -> float:
            for g in (a, b):
                if g in own:
                    return float(own[g])
            return cfg.table_distance if table & {a, b} else cfg.min_distance

        return np.array([required(a, b) for a, b in pairs], dtype=float)

    def allowed_geoms(self, allow_contact: Sequence[str]) -> set[int]:
        """The geoms named in ``allow_contact``.

        Args:
            allow_contact: geom names.

        Returns:
            Their geom ids.

        Raises:
            PlanningInputError: when a name is no geom of the model.
        """
        return {self._geom(n) for n in allow_contact}

    def _geom(self, name: str) -> int:
        if name not in self.geom_names:
            valid = ", ".join(sorted(self.geom_names))
            raise PlanningInputError(f"allow_contact names no geom '{name}'; geoms are: {valid}")
        return self.geom_names[name]

    def limit(
        self, carried: tuple[str, str] | None, allow_contact: Sequence[str], attach: dict[int, int]
    ) -> tuple[GeomPairCollisionLimit, FloatArray]:
        """The collision limit of (carried, allow_contact) and its pairs' required clearance (m),
        built on first use and kept (both depend on the model and the request only).

        Args:
            carried: (hand side, object name) of a carried object.
            allow_contact: names of geoms the robot may touch.
            attach: a carried object's geom -> its hand's body (used when the limit is built).

        Returns:
            The collision limit and its pairs' required clearance (m).
        """
        key = (carried, tuple(allow_contact))
        if key not in self._limits:
            cfg = self.config
            pairs = self.pairs(carried, allow_contact)
            required = self.required_clearance(pairs)
            self._limits[key] = (
                GeomPairCollisionLimit(
                    self.model,
                    pairs,
                    # As for the balance: a little extra in the QP keeps the interpolated knots clear.
                    required + cfg.clearance_tolerance,
                    _detection_distance(cfg, required),
                    cfg.collision_gain,
                    attach,
                    cfg.collision_recovery,
                ),
                required,
            )
        return self._limits[key]


def _detection_distance(cfg: PlannerConfig, required: FloatArray) -> float:
    """The collision limit's detection distance: the configured one, widened for an obstacle's
    own clearance above ``min_distance`` so that its pairs enter the QP as far beyond their
    clearance as the others do."""
    widest = float(np.max(required, initial=0.0))
    if widest <= cfg.min_distance:
        return cfg.detection_distance
    return max(cfg.detection_distance, widest + cfg.detection_distance - cfg.min_distance)
