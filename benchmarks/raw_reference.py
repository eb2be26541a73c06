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
    qpos: list[NDArray[np.float64]] = []  # the configurations, in the order of the knots queried
    pairs: list[list[tuple[int, int]]] = []
    knot, poses, knot_at, pair = model.knot, model._poses, model._knot_at, model._pair_distance

    def knot_spy(q: NDArray[np.float64], **kwargs: Any) -> Any:
        qpos.append(np.array(q, dtype=float))
        return knot(q, **kwargs)

    def poses_spy(rows: NDArray[np.float64]) -> Any:
        qpos.extend(np.array(rows, dtype=float))
        return poses(rows)

    def knot_at_spy(*args: Any, **kwargs: Any) -> Any:
        pairs.append([])
        return knot_at(*args, **kwargs)

    def pair_spy(layout: Any, ei: int, ri: int, *rest: Any) -> float:
        pairs[-1].append((layout.env_list[ei], layout.robot_list[ri]))
        return pair(layout, ei, ri, *rest)

    model.knot, model._poses = knot_spy, poses_spy  # type: ignore[method-assign,assignment]
    model._knot_at, model._pair_distance = knot_at_spy, pair_spy  # type: ignore[method-assign,assignment]
    try:
        run()
    finally:
        del model.knot, model._poses, model._knot_at, model._pair_distance
    if len(qpos) != len(pairs):
        raise RuntimeError(f"record_pairs: {len(qpos)} configurations for {len(pairs)} knots")
    return list(zip(qpos, pairs, strict=True))


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
