"""The regrasp: one hand puts the object down midway on the table, the other picks it up there.

For an object that cannot be handed over (its yaw matters, odd ``yaw_symmetry``: see
:mod:`executive.tasks.handover`) and that neither hand should carry across the whole
body. The first hand picks the object and sets it down, at its own yaw, on the free spot
of the table nearest the midline in front of the body (:func:`midway_spot`), lets go and
goes home; the second picks it up there and places it. Each leg is a pick, a lane carry
and a place (:func:`executive.tasks.phases.one_hand_leg`); the object keeps its yaw on the table, so
every grasp is the same top-down grasp and the object's yaw is never turned by a half turn.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import PlanningError
from executive.risk.shapes import body_geometry
from executive.schema.readers import over_table
from executive.schema.types import Body
from executive.tasks.hands import HandFrames
from executive.tasks.phases import one_hand_leg
from executive.tasks.placement import Destination, target_placement
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["REGRASPS", "Spot", "midway_spot", "transfer"]

FloatArray = NDArray[np.float64]

#: The regrasp alternatives: (first hand, second hand).
REGRASPS = {"left_regrasp_right": ("left", "right"), "right_regrasp_left": ("right", "left")}

_GRID_STEP = 0.01  # m between candidate spots on the table top


@dataclass(frozen=True)
class Spot:
    """Where the object is set down midway: its centre (resting on the table) and its yaw."""

    centre: FloatArray
    yaw: float


def _rotation(quat: FloatArray) -> FloatArray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=float))
    return mat.reshape(3, 3)


def _footprint(body: Body, centre: FloatArray, yaw: float) -> FloatArray:
    """Points of the object's horizontal outline at ``centre`` and ``yaw`` (corners, or a circle's)."""
    if body.shape == "box":
        hx, hy = body.size[0] / 2, body.size[1] / 2
        local = np.array([[hx, hy], [hx, -hy], [-hx, hy], [-hx, -hy]])
    else:
        angles = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
        local = body.size[0] * np.column_stack([np.cos(angles), np.sin(angles)])
    c, s = np.cos(yaw), np.sin(yaw)
    return np.asarray(centre[:2] + local @ np.array([[c, s], [-s, c]]), dtype=float)


def _others(world: World, obj: str) -> list[tuple[str, coal.CollisionGeometry, coal.Transform3s]]:
    """The obstacles (scene poses) and the other objects (the estimate's poses) as coal shapes."""
    scene = world.scenario.scene
    out = []
    for o in scene.obstacles:
        quat = np.zeros(4)
        mujoco.mju_euler2Quat(quat, np.asarray(o.orientation_rad, dtype=float), "xyz")
        out.append(
            (o.name, body_geometry(o), coal.Transform3s(_rotation(quat), np.asarray(o.position, dtype=float)))
        )
    for b in scene.objects:
        if b.name != obj:
            pos, quat = world.object_pose(b.name)
            out.append(
                (b.name, body_geometry(b), coal.Transform3s(_rotation(quat), np.asarray(pos, dtype=float)))
            )
    return out


def midway_spot(world: World, obj: str, start: FloatArray, target: FloatArray, clearance: float) -> Spot:
    """The free spot on the table nearest the midline, in front of the body, midway in depth.

    Candidates lie on a grid over the table top; the object keeps its current yaw and rests on
    the table. A spot is free when the object's outline lies over the table and the object is at
    least ``clearance`` from every obstacle and every other object (coal distances). The spot
    nearest the point on the midline at the mean depth of ``start`` and ``target`` wins; of two
    as near, the one nearer ``start``.

    Raises:
        PlanningError: no free spot on the table, with what rules each candidate out.
    """
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    table = world.scenario.scene.table
    h = HandFrames(world)
    forward = np.array([np.cos(h.heading), np.sin(h.heading), 0.0])
    depth = 0.5 * float(np.dot(start - h.base, forward) + np.dot(target - h.base, forward))
    aim = h.base[:2] + depth * forward[:2]
    _, quat = world.object_pose(obj)
    yaw = yaw_of(quat)
    z = table.height + body.half_height()
    candidates = _grid(table.position, table.size, table.yaw_rad)
    order = np.lexsort((np.linalg.norm(candidates - start[:2], axis=1), _rounded(candidates - aim)))
    shape, rot = body_geometry(body), _rotation(quat)
    others = _others(world, obj)
    blocked: dict[str, int] = {}
    for i in order:
        centre = np.array([*candidates[i], z])
        if float(np.dot(centre - h.base, forward)) <= 0.0:
            continue
        if not all(over_table(table, float(x), float(y)) for x, y in _footprint(body, centre, yaw)):
            continue
        near = _nearest(shape, coal.Transform3s(rot, centre), others, clearance)
        if near is None:
            return Spot(centre, yaw)
        blocked[near] = blocked.get(near, 0) + 1
    why = ", ".join(f"{n} candidates too near '{name}'" for name, n in blocked.items()) or "none fits"
    raise PlanningError(
        "regrasp",
        None,
        0.0,
        0.0,
        0,
        reason=(
            f"no free spot on the table to set '{obj}' down for a regrasp (its outline over the table, "
            f"{clearance * 1000:.0f} mm clear of obstacles and other objects): {why}"
        ),
    )


def _grid(position: tuple[float, ...], size: tuple[float, ...], yaw: float) -> FloatArray:
    """Points ``_GRID_STEP`` apart over the table top (world x, y)."""
    u = np.arange(-size[0] / 2, size[0] / 2 + 1e-9, _GRID_STEP)
    v = np.arange(-size[1] / 2, size[1] / 2 + 1e-9, _GRID_STEP)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    c, s = np.cos(yaw), np.sin(yaw)
    x = position[0] + c * uu - s * vv
    y = position[1] + s * uu + c * vv
    return np.column_stack([x.ravel(), y.ravel()])


def _rounded(offsets: FloatArray) -> FloatArray:
    """Distances to the aim point, to a tenth of the grid step (so that mirror images tie)."""
    return np.asarray(np.round(np.linalg.norm(offsets, axis=1) / (_GRID_STEP / 10)), dtype=float)


def _nearest(
    shape: coal.CollisionGeometry,
    pose: coal.Transform3s,
    others: list[tuple[str, coal.CollisionGeometry, coal.Transform3s]],
    clearance: float,
) -> str | None:
    """The first of ``others`` closer than ``clearance`` to ``shape`` at ``pose`` (None: all clear)."""
    for name, other, other_pose in others:
        d = coal.distance(shape, pose, other, other_pose, coal.DistanceRequest(), coal.DistanceResult())
        if d < clearance:
            return name
    return None


def transfer(world: World, task: Destination, first: str, second: str, cfg: CompositionConfig) -> list[Step]:
    """The steps of a transfer by regrasp: ``first`` sets the object down midway, ``second`` places it.

    ``task``: what to put where (a :class:`executive.tasks.transfer.TransferTask`).

    Raises:
        PlanningError: no free spot to set the object down (the reason says what is in the way).
    """
    body = next(b for b in world.scenario.scene.objects if b.name == task.object)
    pos, quat = world.object_pose(task.object)
    target = target_placement(world, body, task.to, task.to_yaw_rad, 0.0)
    spot = midway_spot(world, task.object, pos, target.centre, cfg.obstacle_clearance)
    h = HandFrames(world)
    return [
        *one_hand_leg(h, first, body, (pos, yaw_of(quat)), (spot.centre, spot.yaw), cfg),
        *one_hand_leg(h, second, body, (spot.centre, spot.yaw), (target.centre, target.yaw), cfg),
    ]
