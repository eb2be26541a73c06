"""The raw reference of the collision risk benchmarks: what any caller must do for the same distances.

``record_pairs`` runs the collision model once and records, per knot it visits, the
configuration and the (environment, robot) geom pairs its broad phase sent to coal;
``raw_distances`` then does only ``mujoco.mj_kinematics`` plus ``coal.distance`` (a fresh
``coal.Transform3s`` per geom) on exactly those knots and pairs. ``bench_collision.py`` and
``bench_planning.py`` divide their per-knot costs by this one definition.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import coal
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision import CollisionModel
from executive.risk.shapes import coal_geometry, coal_transform

__all__ = ["Knot", "raw_distances", "record_pairs"]

Knot = tuple[NDArray[np.float64], list[tuple[int, int]]]  # qpos, (env geom, robot geom) pairs


def record_pairs(model: CollisionModel, run: Callable[[], object]) -> list[Knot]:
    """The knots ``run()`` makes ``model`` visit, each with the pairs it sent to coal."""
    record: list[Knot] = []
    knot, pair = model._knot_from_data, model._pair_distance

    def knot_spy(data: mujoco.MjData, *args: Any) -> Any:
        record.append((data.qpos.copy(), []))
        return knot(data, *args)

    def pair_spy(layout: Any, ei: int, ri: int) -> float:
        record[-1][1].append((layout.env_list[ei], layout.robot_list[ri]))
        return pair(layout, ei, ri)

    model._knot_from_data = knot_spy  # type: ignore[method-assign,assignment]
    model._pair_distance = pair_spy  # type: ignore[method-assign]
    try:
        run()
    finally:
        del model._knot_from_data, model._pair_distance
    return record


def raw_distances(model: mujoco.MjModel, knots: Sequence[Knot]) -> Callable[[], None]:
    """A function doing one pass of mj_kinematics + coal.distance over ``knots`` (shapes built here)."""
    d = mujoco.MjData(model)
    shapes = {g: coal_geometry(model, g) for g in range(model.ngeom)}
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def run() -> None:
        for qpos, pairs in knots:
            d.qpos[:] = qpos
            mujoco.mj_kinematics(model, d)
            for e, r in pairs:
                coal.distance(
                    shapes[e],
                    coal_transform(d.geom_xpos[e], d.geom_xmat[e]),
                    shapes[r],
                    coal_transform(d.geom_xpos[r], d.geom_xmat[r]),
                    req,
                    res,
                )

    return run
