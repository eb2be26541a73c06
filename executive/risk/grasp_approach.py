"""The jaws' approach: where a hand's geoms pass beside an object on their way down to grasp it.

:func:`approach_envelope` collects the hand's geom points beside the object along a planned
descent; :func:`approach_miss_probability` the chance that a Gaussian object pose error puts
the object's side in their way.

Usage::

    env = approach_envelope(world, "left", "book", qpos_path)
    p, p_a, p_b = approach_miss_probability(env, position_sigma=0.01, yaw_sigma=0.05)
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from executive.risk.gaussian import gauss_hermite_normal, normal_cdf
from executive.risk.hand_span import hand_collision_geoms
from executive.risk.model_geometry import geom_corners, half_extent
from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = ["ApproachEnvelope", "approach_envelope", "approach_miss_probability"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ApproachEnvelope:
    """Where a hand's collision geoms pass beside an object on their way down to grasp it.

    Coordinates are in the object's planned (estimated) horizontal frame, m: x along its
    lateral axis (across the jaws' closing direction), y along its closing axis. Only the
    corners of geoms that are below the object's top face at a knot are kept.

    Attributes:
        side_a: (n, 2) corners (x, y) with y > 0 (beside the object's +y face).
        side_b: (m, 2) corners with y <= 0 (beside its -y face).
        half_width: the object's half extent b along its closing axis.
    """

    side_a: FloatArray
    side_b: FloatArray
    half_width: float

    def clearances(self, yaw: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Largest u = c - l tan t that keeps off each face, for object yaw errors t (rad).

        A box of half-width b turned by t about its centre (c along the jaws, l across them)
        has its face at y = c + b / cos t + tan t (x - l), so a pad corner (x, y) outside it
        is hit iff u > y - x tan t - b / cos t (plane geometry; Ericson, "Real-Time Collision
        Detection", 2005, 4.4: a convex polygon meets a half-plane iff one of its vertices does).

        Returns (hi, lo): the approach misses the object iff lo < u < hi; hi is +inf (lo -inf)
        when no geom goes below the top on that side.
        """
        t = np.atleast_1d(np.asarray(yaw, dtype=float))
        tan, sec = np.tan(t), 1.0 / np.cos(t)
        hi = np.full(t.shape, np.inf)
        lo = np.full(t.shape, -np.inf)
        if len(self.side_a):
            hi = np.min(self.side_a[:, 1][None, :] - np.outer(tan, self.side_a[:, 0]), axis=1)
        if len(self.side_b):
            lo = np.max(self.side_b[:, 1][None, :] - np.outer(tan, self.side_b[:, 0]), axis=1)
        return hi - self.half_width * sec, lo + self.half_width * sec


def _below(
    model: mujoco.MjModel, data: mujoco.MjData, geom: int, top: float, local: FloatArray | None
) -> FloatArray:
    """The points of a hand geom below ``top`` that can meet the object's side on the way down.

    A mesh (a dexterous hand's finger) gives its vertices below the top (``local``: its vertices
    in its frame, :func:`_mesh_vertices`); a primitive gives all its bounding box's corners when
    its lowest corner is below the top (none otherwise).
    """
    if local is not None:  # as geom_points, with the vertices read once per envelope
        verts = np.asarray(data.geom_xpos[geom] + local @ data.geom_xmat[geom].reshape(3, 3).T, dtype=float)
        return verts[verts[:, 2] < top]
    pts = geom_corners(model, data, geom)
    return pts if float(pts[:, 2].min()) < top else np.zeros((0, 3))


def _mesh_vertices(model: mujoco.MjModel, geom: int) -> FloatArray | None:
    """A mesh geom's vertices in its frame (float64; None for a primitive)."""
    if model.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH:
        return None
    mesh = int(model.geom_dataid[geom])
    start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    return np.asarray(model.mesh_vert[start : start + count], dtype=float)


def _bound(model: mujoco.MjModel, geom: int) -> float:
    """A radius about the geom's origin that holds its local bounding box (so its vertices and
    corners): the box's centre's distance plus its half diagonal."""
    aabb = model.geom_aabb[geom]
    return float(np.linalg.norm(aabb[:3]) + np.linalg.norm(aabb[3:])) + 1e-9


def _extreme_points(points: FloatArray) -> FloatArray:
    """The vertices of the 2-D convex hull of ``points`` (all of them when there are few or they are
    degenerate): a linear function's minimum over the points is attained at one of them."""
    if len(points) <= 64:
        return points
    try:
        return np.asarray(points[ConvexHull(points).vertices], dtype=float)
    except QhullError:
        return points


def approach_envelope(
    world: World,
    side: str,
    obj: str,
    qpos_path: ArrayLike,
    *,
    closing_axis_object: ArrayLike = (0.0, 1.0, 0.0),
) -> ApproachEnvelope:
    """The corners of the ``side`` hand's geoms beside ``obj`` over a path of robot poses.

    Args:
        world: the estimate; the object's pose is taken from ``world.data``.
        side: the grasping arm.
        obj: the object to be grasped (a box; other shapes use their extent along the axes).
        qpos_path: (k, nq) full-model poses the hand passes through on its way to the grasp
            (e.g. the knots of the pre-grasp and approach trajectories).
        closing_axis_object: the object-frame axis the jaws close along.

    Returns:
        The envelope; its corners are those of geoms whose lowest corner is below the
        object's top face at that pose.
    """
    model = world.model
    geom = world.ids.object_geoms[obj]
    rot = world.data.geom_xmat[geom].reshape(3, 3)
    c_axis = np.asarray(closing_axis_object, dtype=float).reshape(3)
    c_axis = c_axis / np.linalg.norm(c_axis)
    y_world = rot @ c_axis
    y_world[2] = 0.0
    y_world /= np.linalg.norm(y_world)
    x_world = np.array([y_world[1], -y_world[0], 0.0])
    centre = world.data.geom_xpos[geom].copy()
    top = float(centre[2] + half_extent(model, geom, rot.T @ np.array([0.0, 0.0, 1.0])))
    width = half_extent(model, geom, c_axis)
    # Beyond the object's circumradius along its lateral axis a point passes its end at any yaw
    # (e.g. a hand starting at the robot's hip, below the table top, far to one side).
    reach = float(np.hypot(width, half_extent(model, geom, np.cross(c_axis, [0.0, 0.0, 1.0]))))
    geoms = [(g, _mesh_vertices(model, g), _bound(model, g)) for g in hand_collision_geoms(world, side)]
    corners: list[FloatArray] = []
    with scratch_data(model) as data:
        for q in np.asarray(qpos_path, dtype=float).reshape(-1, model.nq):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            for g, local, bound in geoms:
                at = data.geom_xpos[g]  # a geom wholly above the top, or beyond the reach: no point
                if at[2] - bound >= top or abs(float((at - centre) @ x_world)) - bound > reach:
                    continue
                pts = _below(model, data, g, top, local)
                if len(pts):
                    rel = pts - centre
                    corners.append(np.column_stack([rel @ x_world, rel @ y_world]))
    flat = np.concatenate(corners) if corners else np.zeros((0, 2))
    flat = flat[np.abs(flat[:, 0]) <= reach]
    side_a, side_b = flat[flat[:, 1] > 0.0], flat[flat[:, 1] <= 0.0]
    return ApproachEnvelope(_extreme_points(side_a), _extreme_points(side_b), float(width))


def approach_miss_probability(
    envelope: ApproachEnvelope,
    position_sigma: float,
    yaw_sigma: float,
    order: int = 32,
    *,
    hand: tuple[float, float] = (0.0, 0.0),
    hand_sigma: float = 0.0,
) -> tuple[float, float, float]:
    """P(a hand geom meets the object's side on the way down) for a Gaussian object pose error.

    The object's horizontal position error is N(0, position_sigma^2) per axis and its yaw
    error N(0, yaw_sigma^2), independent. Given the yaw t, u = c - l tan t is
    N(0, position_sigma^2 / cos^2 t) and the approach misses the object iff lo(t) < u < hi(t)
    (:meth:`ApproachEnvelope.clearances`); the yaw is integrated by Gauss-Hermite quadrature
    of ``order`` nodes. Valid while the pads pass beside the object's long faces (the yaw
    does not bring a face's end under them).

    ``hand``: the hand's mean execution error (m) along the envelope's closing (y) and lateral
    (x) axes, ``hand_sigma`` its spread per axis (the tracking model's,
    :mod:`executive.risk.tracking`): the hand's geoms move with it, so what counts is the
    object's offset from the hand, ``u' = (c - h_c) - (l - h_l) tan t``, of mean
    ``-h_c + h_l tan t`` and variance ``(position_sigma^2 + hand_sigma^2) / cos^2 t``.

    Returns:
        (probability, p_a, p_b): the total and the parts from the +y and -y faces.
    """
    if position_sigma < 0.0 or yaw_sigma < 0.0 or hand_sigma < 0.0:
        raise ValueError(
            f"approach_miss_probability: sigmas must be >= 0, got {position_sigma}, {yaw_sigma}, {hand_sigma}"
        )
    z, w = gauss_hermite_normal(order) if yaw_sigma > 0.0 else (np.zeros(1), np.ones(1))
    t = np.clip(yaw_sigma * z, -1.5, 1.5)
    hi, lo = envelope.clearances(t)
    mean = -hand[0] + hand[1] * np.tan(t)
    sigma = float(np.hypot(position_sigma, hand_sigma)) if hand_sigma > 0.0 else position_sigma
    if sigma > 0.0:
        s = sigma / np.cos(t)
        p_a, p_b = normal_cdf((mean - hi) / s), normal_cdf((lo - mean) / s)
    else:
        p_a, p_b = (hi <= mean).astype(float), (lo >= mean).astype(float)
    p = np.where(lo >= hi, 1.0, np.minimum(1.0, p_a + p_b))
    return float(w @ p), float(w @ p_a), float(w @ p_b)
