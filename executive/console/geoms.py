"""A MuJoCo model's geoms as instanced shapes: what the console draws, and where, in one array per shape.

A browser draws many copies of one mesh at the cost of one (instancing), and moving them all
is one message. So the geoms are grouped by shape: every box is an instance of one unit cube
scaled by its half-sizes, every sphere and ellipsoid of one unit sphere, every cylinder of one
unit cylinder, a capsule a cylinder and two spheres; a mesh geom is an instance of its own
mesh (MuJoCo's vertices, in the geom's frame). Planes are left to the caller (a grid);
height fields and SDFs are not drawn.

Use :func:`shape_batches` once per model and set of geoms, then :meth:`ShapeBatch.poses` on
any ``MjData`` of that model (after its kinematics) for the instances' positions and
orientations. Nothing here needs a browser or viser.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["ShapeBatch", "drawn_geoms", "quat_multiply", "shape_batches", "unit_cylinder", "unit_sphere"]

FloatArray = NDArray[np.float64]
GT = mujoco.mjtGeom
#: MuJoCo's viewer shows geom groups 0-2 by default; group 3 and up hold collision-only geoms.
VISIBLE_GROUPS = 3


def unit_sphere(rings: int = 10, segments: int = 16) -> tuple[FloatArray, NDArray[np.uint32]]:
    """A UV sphere of radius 1 about the origin: (vertices (V, 3), faces (F, 3), counter-clockwise)."""
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack(
        [
            np.outer(np.sin(theta), np.cos(phi)),
            np.outer(np.sin(theta), np.sin(phi)),
            np.repeat(np.cos(theta)[:, None], segments, 1),
        ],
        axis=-1,
    ).reshape(-1, 3)
    vertices = np.vstack([[0.0, 0.0, 1.0], ring, [0.0, 0.0, -1.0]])
    bottom = len(vertices) - 1
    faces: list[tuple[int, int, int]] = []
    for j in range(segments):
        k = (j + 1) % segments
        faces.append((0, 1 + j, 1 + k))
        faces.append((bottom, 1 + (rings - 2) * segments + k, 1 + (rings - 2) * segments + j))
    for i in range(rings - 2):
        for j in range(segments):
            k = (j + 1) % segments
            a, b = 1 + i * segments + j, 1 + i * segments + k
            c, d = a + segments, b + segments
            faces += [(a, c, b), (b, c, d)]
    return vertices, np.array(faces, dtype=np.uint32)


def unit_cylinder(segments: int = 20) -> tuple[FloatArray, NDArray[np.uint32]]:
    """A closed cylinder of radius 1 from z = -1 to z = 1 (MuJoCo's size convention: half-length)."""
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    circle = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    top = np.hstack([circle, np.ones((segments, 1))])
    bottom = np.hstack([circle, -np.ones((segments, 1))])
    vertices = np.vstack([top, bottom, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
    ct, cb = 2 * segments, 2 * segments + 1
    faces: list[tuple[int, int, int]] = []
    for j in range(segments):
        k = (j + 1) % segments
        faces += [(j, segments + j, k), (k, segments + j, segments + k)]  # side
        faces += [(ct, j, k), (cb, segments + k, segments + j)]  # caps
    return vertices, np.array(faces, dtype=np.uint32)


def _unit_box() -> tuple[FloatArray, NDArray[np.uint32]]:
    """The cube [-1, 1]^3 (scaled by a box geom's half-sizes), 12 outward triangles."""
    v = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(faces, dtype=np.uint32)


def quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton products ``a * b`` of (N, 4) quaternions (w, x, y, z), row by row."""
    aw, ax, ay, az = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bw, bx, by, bz = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


@dataclass(frozen=True)
class ShapeBatch:
    """Instances of one shape: which geom each is, where along the geom's z it sits, its scale.

    ``key`` names the shape (``box``, ``sphere``, ``cylinder`` or ``mesh:<name>``); ``vertices``
    and ``faces`` are the unit shape (or the mesh); per instance ``geoms`` (geom ids),
    ``offsets`` (m along the geom's z axis: a capsule's end spheres), ``scales`` (N, 3),
    ``colors`` (N, 3) uint8 and ``opacities`` (N,) from the geoms' rgba (or their material's).
    """

    key: str
    vertices: FloatArray
    faces: NDArray[np.uint32]
    geoms: NDArray[np.int_]
    offsets: FloatArray
    scales: FloatArray
    colors: NDArray[np.uint8]
    opacities: FloatArray

    def poses(self, model: mujoco.MjModel, data: mujoco.MjData) -> tuple[FloatArray, FloatArray]:
        """(positions (N, 3), wxyz quaternions (N, 4)) of the instances in ``data`` (kinematics done)."""
        g = self.geoms
        xmat = data.geom_xmat[g].reshape(-1, 3, 3)
        positions = data.geom_xpos[g] + xmat[:, :, 2] * self.offsets[:, None]
        wxyz = quat_multiply(data.xquat[model.geom_bodyid[g]], model.geom_quat[g])
        return positions, wxyz


def drawn_geoms(model: mujoco.MjModel, geoms: Iterable[int] | None = None) -> list[int]:
    """The geoms a viewer shows: groups 0-2, not fully transparent, of a drawable type."""
    drawable = {int(GT.mjGEOM_BOX), int(GT.mjGEOM_SPHERE), int(GT.mjGEOM_ELLIPSOID)}
    drawable |= {int(GT.mjGEOM_CYLINDER), int(GT.mjGEOM_CAPSULE), int(GT.mjGEOM_MESH)}
    ids = range(model.ngeom) if geoms is None else geoms
    return [
        int(g)
        for g in ids
        if model.geom_group[g] < VISIBLE_GROUPS
        and _rgba(model, int(g))[3] > 0
        and model.geom_type[g] in drawable
    ]


def _rgba(model: mujoco.MjModel, geom: int) -> FloatArray:
    """The colour a geom is drawn in: its material's when it has one, else its own rgba."""
    mat = int(model.geom_matid[geom])
    return np.asarray(model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[geom], dtype=float)


def _instances(model: mujoco.MjModel, geom: int) -> list[tuple[str, float, FloatArray]]:
    """(shape key, offset along z, scale) of each instance that draws ``geom``."""
    kind, size = int(model.geom_type[geom]), np.asarray(model.geom_size[geom], dtype=float)
    if kind == GT.mjGEOM_BOX:
        return [("box", 0.0, size.copy())]
    if kind == GT.mjGEOM_SPHERE:
        return [("sphere", 0.0, np.full(3, size[0]))]
    if kind == GT.mjGEOM_ELLIPSOID:
        return [("sphere", 0.0, size.copy())]
    if kind == GT.mjGEOM_CYLINDER:
        return [("cylinder", 0.0, np.array([size[0], size[0], size[1]]))]
    if kind == GT.mjGEOM_CAPSULE:
        r, h = size[0], size[1]
        ball = np.full(3, r)
        return [("cylinder", 0.0, np.array([r, r, h])), ("sphere", h, ball), ("sphere", -h, ball)]
    mesh = int(model.geom_dataid[geom])
    return [(f"mesh:{model.mesh(mesh).name or mesh}", 0.0, np.ones(3))]


def _shape(model: mujoco.MjModel, key: str, geom: int) -> tuple[FloatArray, NDArray[np.uint32]]:
    if key == "box":
        return _unit_box()
    if key == "sphere":
        return unit_sphere()
    if key == "cylinder":
        return unit_cylinder()
    mesh = int(model.geom_dataid[geom])
    v0, nv = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    f0, nf = int(model.mesh_faceadr[mesh]), int(model.mesh_facenum[mesh])
    vertices = np.asarray(model.mesh_vert[v0 : v0 + nv], dtype=float)
    return vertices, np.asarray(model.mesh_face[f0 : f0 + nf], dtype=np.uint32)


def shape_batches(model: mujoco.MjModel, geoms: Iterable[int]) -> list[ShapeBatch]:
    """Group ``geoms`` (see :func:`drawn_geoms`) into one :class:`ShapeBatch` per shape.

    Args:
        model: the compiled model.
        geoms: geom ids to draw; types that cannot be drawn this way are skipped.

    Returns:
        The batches, in the order their shapes first appear.
    """
    rows: dict[str, list[tuple[int, float, FloatArray]]] = {}
    for g in drawn_geoms(model, geoms):
        for key, offset, scale in _instances(model, g):
            rows.setdefault(key, []).append((g, offset, scale))
    batches = []
    for key, items in rows.items():
        ids = np.array([g for g, _, _ in items], dtype=int)
        rgba = np.array([_rgba(model, int(g)) for g in ids])
        vertices, faces = _shape(model, key, int(ids[0]))
        batches.append(
            ShapeBatch(
                key=key,
                vertices=vertices,
                faces=faces,
                geoms=ids,
                offsets=np.array([o for _, o, _ in items]),
                scales=np.array([s for _, _, s in items]),
                colors=np.clip(np.round(rgba[:, :3] * 255), 0, 255).astype(np.uint8),
                opacities=rgba[:, 3].copy(),
            )
        )
    return batches
