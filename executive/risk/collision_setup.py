"""What the collision model pairs: the world's geom groups, and the geom pairs of one query.

:class:`CollisionSetup` says which geoms form the robot and the environment and what is
uncertain (built from a world with :meth:`CollisionSetup.from_world`, or given for any MuJoCo
model); :class:`PairLayout` is one query's (carried object, ``allow`` set) pairs as index arrays
with their coal functors, which :class:`executive.risk.collision_pairs.CollisionPairs` builds.
Re-exported by :mod:`executive.risk.collision` (``Allow``, ``CollisionSetup``).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import coal
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World, is_descendant

__all__ = ["Allow", "CollisionSetup", "PairLayout"]

FloatArray = NDArray[np.float64]
#: Pairs excluded from a query: an environment geom/body name (all robot geoms), or a
#: (robot geom or body name, environment geom or body name) pair.
Allow = Collection[str | tuple[str, str]]


@dataclass(frozen=True)
class CollisionSetup:
    """Which geoms form the robot and the environment, and what is uncertain.

    robot_geoms: the robot's collision geoms (feet included; the floor is never a pair).
    env_geoms: table, obstacles and objects (the carried object moves to the robot side).
    object_geoms: object name -> geom, the objects a trajectory may carry.
    env_sigma: environment body id -> horizontal 1-sigma (m); missing means exact.
    part_factors: robot body id -> (body part, severity factor) (``Severity.body_parts``).
    hand_geoms: side -> robot geoms of the hand subtree.
    support_geoms: the geoms objects rest on (the table's), for
        :meth:`executive.risk.collision_pairs.CollisionPairs.support_allow`.
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


class PairLayout(NamedTuple):
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
