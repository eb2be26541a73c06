"""MuJoCo geoms as coal collision geometries (built once per model).

Size conventions differ between the two libraries (verified by running both):

- MuJoCo ``geom_size`` holds half sizes: box half extents, capsule and
  cylinder ``[radius, half_length]``, ellipsoid radii (MuJoCo docs, XML
  reference, "geom/size").
- coal ``Box(x, y, z)`` takes FULL side lengths (``halfSide`` is half of them);
  ``Capsule(radius, lz)`` and ``Cylinder(radius, lz)`` take the FULL length
  along their z axis (``halfLength`` = lz / 2); ``Ellipsoid(rx, ry, rz)``
  takes radii; ``Sphere(r)`` the radius (coal docs, ``coal/shape/geometric_shapes.h``).

Both put the shape's axis on the local z axis and its centre at the origin, so
the geom's world pose (``geom_xpos``, ``geom_xmat``) is the coal transform as is.
A mesh geom becomes the convex hull of its vertices (MuJoCo collides meshes
as their convex hulls too; MuJoCo docs, "Collision detection"); the hull is
computed with scipy (``coal.WITH_QHULL`` is False in the installed wheel) and
handed to ``coal.Convex(points, triangles)``. Planes, height fields and SDF
geoms have no coal counterpart here and give ``None``.
"""

from __future__ import annotations

import coal
import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull

from executive.schema.types import Body

__all__ = ["body_geometry", "coal_geometry", "coal_transform", "mesh_hull", "set_transform"]

FloatArray = NDArray[np.float64]


def coal_geometry(model: mujoco.MjModel, geom: int) -> coal.CollisionGeometry | None:
    """The coal shape of MuJoCo geom ``geom`` in its own frame; None for unsupported types.

    Supported: sphere, capsule, ellipsoid, cylinder, box, mesh (as its convex hull).
    """
    gtype = int(model.geom_type[geom])
    size = np.asarray(model.geom_size[geom], dtype=float)
    if gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
        return coal.Sphere(float(size[0]))
    if gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
        # coal: Capsule(radius, full length); MuJoCo: size = [radius, half length].
        return coal.Capsule(float(size[0]), 2.0 * float(size[1]))
    if gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return coal.Cylinder(float(size[0]), 2.0 * float(size[1]))
    if gtype == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        return coal.Ellipsoid(float(size[0]), float(size[1]), float(size[2]))
    if gtype == mujoco.mjtGeom.mjGEOM_BOX:
        # coal: Box(x, y, z) full side lengths; MuJoCo: half extents.
        return coal.Box(2.0 * float(size[0]), 2.0 * float(size[1]), 2.0 * float(size[2]))
    if gtype == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = int(model.geom_dataid[geom])
        if mesh < 0:
            return None
        start = int(model.mesh_vertadr[mesh])
        count = int(model.mesh_vertnum[mesh])
        return mesh_hull(np.asarray(model.mesh_vert[start : start + count], dtype=float))
    return None  # plane, height field, SDF: not handled


def mesh_hull(vertices: FloatArray) -> coal.Convex:
    """``coal.Convex`` of the convex hull of ``vertices`` (N, 3), in the geom frame.

    MuJoCo stores mesh vertices in the mesh frame, which the compiler aligns with
    the geom frame (MuJoCo docs, "mesh" asset: the mesh is re-centred and the
    geom pose absorbs the offset), so they need no transform here.
    """
    pts = np.asarray(vertices, dtype=float).reshape(-1, 3)
    hull = ConvexHull(pts)
    used = np.unique(hull.simplices)
    index = np.full(len(pts), -1, dtype=int)
    index[used] = np.arange(len(used))
    points = coal.StdVec_Vec3s()
    for p in pts[used]:
        points.append(np.array(p, dtype=float))
    triangles = coal.StdVec_Triangle()
    for a, b, c in index[hull.simplices]:
        triangles.append(coal.Triangle(int(a), int(b), int(c)))
    return coal.Convex(points, triangles)


def coal_transform(position: FloatArray, xmat: FloatArray) -> coal.Transform3s:
    """A ``coal.Transform3s`` from a world position and a row-major 3x3 (or flat 9) rotation."""
    return coal.Transform3s(
        np.asarray(xmat, dtype=float).reshape(3, 3), np.asarray(position, dtype=float).reshape(3)
    )


def set_transform(transform: coal.Transform3s, position: FloatArray, xmat: FloatArray) -> None:
    """Overwrite ``transform`` in place (cheaper than building a new one per knot)."""
    transform.setRotation(np.asarray(xmat, dtype=float).reshape(3, 3))
    transform.setTranslation(np.asarray(position, dtype=float).reshape(3))


def body_geometry(body: Body) -> coal.CollisionGeometry:
    """A scenario body (full sizes: box edges, cylinder radius and length, sphere radius) as coal geometry."""
    if body.shape == "box":
        return coal.Box(*(float(s) for s in body.size))
    if body.shape == "cylinder":
        return coal.Cylinder(float(body.size[0]), float(body.size[1]))
    return coal.Sphere(float(body.size[0]))
