"""The robot's support in the ground plane: foot contact points and the support polygon.

:func:`support_polygon` is the convex hull (Andrew's monotone chain, A. M. Andrew, Inf.
Process. Lett. 9(5):216-219, 1979) of the feet's ground contacts at one state, from physics
contacts or from the foot geometry; :func:`fall_knots` gives, for every knot of a trajectory,
the robot's CoM, its support polygon (:mod:`executive.risk.fall_batch`), pelvis height and
torso uprightness, which the fall model scores. ``support_polygon`` is re-exported by
:mod:`executive.risk.fall`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.loaded_com import LoadedCoM
from executive.planning.timing import Trajectory
from executive.risk.fall_batch import KnotPolygons, hulls
from executive.world.model import World
from executive.world.polygon import convex_hull
from executive.world.scratch import scratch_data

__all__ = ["FallKnots", "fall_knots", "support_polygon"]

FloatArray = NDArray[np.float64]


def _ground_height(world: World, data: mujoco.MjData) -> float:
    """Height (m) of the floor geom in ``data``; 0 without a floor."""
    floor = world.ids.floor_geom
    return float(data.geom_xpos[floor][2]) if floor >= 0 else 0.0


def _foot_points(world: World, data: mujoco.MjData) -> FloatArray:
    """Candidate ground-contact points (3D) of the foot geoms: box soles' bottom-face corners."""
    model = world.model
    points: list[FloatArray] = []
    for geoms in world.ids.foot_geoms.values():
        for g in geoms:
            centre = data.geom_xpos[g]
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
                rot = data.geom_xmat[g].reshape(3, 3)
                size = model.geom_size[g]
                k = int(np.argmax(np.abs(rot[2])))  # local axis closest to the vertical
                sign = -np.sign(rot[2, k]) if rot[2, k] != 0.0 else -1.0
                others = [i for i in range(3) if i != k]
                for s1 in (-1.0, 1.0):
                    for s2 in (-1.0, 1.0):
                        local = np.zeros(3)
                        local[k] = sign * size[k]
                        local[others[0]] = s1 * size[others[0]]
                        local[others[1]] = s2 * size[others[1]]
                        points.append(centre + rot @ local)
            else:
                points.append(centre.copy())
    return np.array(points, dtype=float).reshape(-1, 3)


def support_polygon(
    world: World, data: mujoco.MjData, from_contacts: bool, *, ground_tolerance: float = 0.01
) -> FloatArray:
    """Support polygon (V, 2), counter-clockwise: convex hull of the feet's ground contacts.

    from_contacts: the positions of the physics contacts between foot geoms and the floor
    (any non-robot geom when the world has no floor) in ``data.contact``.
    Otherwise (planning): the foot geometry in ``data`` (needs its kinematics): box soles'
    bottom-face corners, other foot geoms' centres; points higher than ``ground_tolerance``
    above the floor (a lifted foot) are left out.
    Raises ValueError when fewer than 3 non-collinear points remain.
    """
    feet = {g for geoms in world.ids.foot_geoms.values() for g in geoms}
    if from_contacts:
        floor = world.ids.floor_geom
        robot = set(world.ids.robot_geoms)
        pts = []
        for i in range(data.ncon):
            g1, g2 = int(data.contact.geom[i][0]), int(data.contact.geom[i][1])
            other = g2 if g1 in feet else g1 if g2 in feet else None
            if other is None or (other != floor if floor >= 0 else other in robot):
                continue
            pts.append(data.contact.pos[i][:2].copy())
        xy = np.array(pts, dtype=float).reshape(-1, 2)
        what = "physics contacts between the feet and the floor"
    else:
        p3 = _foot_points(world, data)
        p3 = p3[p3[:, 2] <= _ground_height(world, data) + ground_tolerance]
        xy = p3[:, :2]
        what = "foot geometry points on the ground"
    hull = convex_hull(xy)
    if len(hull) < 3:
        raise ValueError(f"support_polygon: {len(xy)} {what} do not span a polygon")
    return hull


def _foot_points_batch(world: World, xpos: FloatArray, xmat: FloatArray) -> FloatArray:
    """:func:`_foot_points` for K knots at once: xpos (K, G, 3), xmat (K, G, 3, 3) of the foot geoms
    (in ``world.ids.foot_geoms`` order); returns (K, P, 3) in the same point order."""
    model = world.model
    geoms = [g for gs in world.ids.foot_geoms.values() for g in gs]
    parts = []
    signs = np.array([[-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]])  # (s1, s2) as in the loop
    for i, g in enumerate(geoms):
        centre, rot = xpos[:, i], xmat[:, i]
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX:
            parts.append(centre[:, None, :])
            continue
        size = model.geom_size[g]
        up = rot[:, 2, :]  # (K, 3): the world z row
        k = np.argmax(np.abs(up), axis=1)  # local axis closest to the vertical
        vert = up[np.arange(len(k)), k]
        sign = np.where(vert != 0.0, -np.sign(vert), -1.0)
        others = np.array([[1, 2], [0, 2], [0, 1]])[k]  # (K, 2), increasing
        local = np.zeros((len(k), 4, 3))
        rows = np.arange(len(k))
        local[rows, :, k] = (sign * size[k])[:, None]
        local[rows[:, None], np.arange(4)[None, :], others[:, 0:1]] = (
            signs[None, :, 0] * size[others[:, 0]][:, None]
        )
        local[rows[:, None], np.arange(4)[None, :], others[:, 1:2]] = (
            signs[None, :, 1] * size[others[:, 1]][:, None]
        )
        parts.append(centre[:, None, :] + np.einsum("kij,kcj->kci", rot, local))
    return np.concatenate(parts, axis=1)


@dataclass(frozen=True)
class FallKnots:
    """Per knot of a trajectory: CoM, the feet's support polygons, pelvis height, torso uprightness,
    which feet are on the ground."""

    times: FloatArray
    coms: FloatArray  # (K, 3)
    polygons: KnotPolygons
    pelvis: FloatArray
    upright: FloatArray  # the torso z axis' vertical component
    ground: float
    gravity: float
    mass: float  # the robot's
    feet_down: dict[str, NDArray[np.bool_]] = field(default_factory=dict)  # side -> (K,) on the ground


def fall_knots(
    world: World, trajectory: Trajectory, carried: Sequence[tuple[str, str] | None] | None = None
) -> FallKnots:
    """The robot's CoM, support polygon and posture at every knot (MuJoCo kinematics, robot bodies only).

    ``carried``: per knot, (hand side, object) of an object whose mass counts in the CoM there
    (a walk that carries it: :class:`executive.planning.loaded_com.LoadedCoM`), or None.

    Raises:
        ValueError: qpos that do not fit the model, or a knot whose foot points span no polygon.
    """
    model = world.model
    times = np.asarray(trajectory.times, dtype=float)
    qpos = np.asarray(trajectory.qpos, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(times) != len(qpos) or len(times) == 0:
        raise ValueError(
            f"assess_fall: trajectory '{trajectory.name}' has qpos {qpos.shape} and {len(times)} "
            f"times; the world's model needs (K, {model.nq}) with K = len(times) >= 1"
        )
    base, torso = world.ids.base_body, world.ids.torso_body
    count = len(times)
    feet = [g for gs in world.ids.foot_geoms.values() for g in gs]
    coms = np.zeros((count, 3))
    xpos = np.zeros((count, len(feet), 3))
    xmat = np.zeros((count, len(feet), 9))
    pelvis, upright = np.zeros(count), np.zeros(count)
    loads = {load: LoadedCoM(world, load) for load in set(carried or ()) if load is not None}
    with scratch_data(model) as data:
        for k in range(count):
            data.qpos[:] = qpos[k]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            load = carried[k] if carried is not None else None
            coms[k] = data.subtree_com[base] if load is None else loads[load].position(data)
            xpos[k] = data.geom_xpos[feet]
            xmat[k] = data.geom_xmat[feet]
            pelvis[k] = data.xpos[base][2]
            upright[k] = data.xmat[torso][8]
        ground = _ground_height(world, data)
    points = _foot_points_batch(world, xpos, xmat.reshape(count, len(feet), 3, 3))
    down = points[..., 2] <= ground + 0.01
    polygons = hulls(points[..., :2], down)
    gravity = float(np.linalg.norm(model.opt.gravity))
    mass = float(model.body_subtreemass[base])
    return FallKnots(times, coms, polygons, pelvis, upright, ground, gravity, mass, _feet_down(world, down))


def _feet_down(world: World, down: NDArray[np.bool_]) -> dict[str, NDArray[np.bool_]]:
    """Per foot: is any of its ground-contact points (``_foot_points`` order) down, per knot."""
    model, out, start = world.model, {}, 0
    for side, geoms in world.ids.foot_geoms.items():
        count = sum(4 if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX else 1 for g in geoms)
        out[side] = np.any(down[:, start : start + count], axis=1)
        start += count
    return out
