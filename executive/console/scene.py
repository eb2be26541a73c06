"""The 3D scene of a MuJoCo world on the console's page: instanced shapes that follow an ``MjData``.

:class:`InstancedGeoms` draws a set of geoms (see :mod:`executive.console.geoms`) as one
viser batched mesh per shape and moves them all from an ``MjData`` in one message per
shape. :class:`WorldView` draws a whole world: the geoms welded to the world once (table,
fixed obstacles), the floor as a grid, the moving ones (robot, objects) as instances that
:meth:`WorldView.update` moves.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from executive.console.geoms import FloatArray, ShapeBatch, shape_batches

if TYPE_CHECKING:
    import viser

__all__ = ["STILL", "InstancedGeoms", "WorldView", "light", "moving_geoms", "static_geoms"]

#: A shape whose instances all moved less than this (m, and in each quaternion component) since
#: they were last sent is not sent again (0.1 mm; 1e-4 in a unit quaternion is 0.01 degree).
STILL = 1e-4


def moving_geoms(model: mujoco.MjModel) -> list[int]:
    """Geoms of bodies that are not welded to the world (the robot, free objects)."""
    return [g for g in range(model.ngeom) if model.body_weldid[model.geom_bodyid[g]] != 0]


def static_geoms(model: mujoco.MjModel) -> list[int]:
    """Geoms welded to the world (table, fixed obstacles, floor)."""
    return [g for g in range(model.ngeom) if model.body_weldid[model.geom_bodyid[g]] == 0]


def light(server: viser.ViserServer) -> None:
    """Plain light for the scene: viser's lights without shadows and a sky/ground hemisphere.

    viser's default image-based lighting keeps the browser drawing frames while nothing moves
    (0.65 of a core in headless Chromium, measured; 0.06 without it), so it is switched off.
    """
    server.scene.configure_environment_map(None)
    server.scene.configure_default_lights(enabled=True, cast_shadow=False)
    server.scene.add_light_hemisphere("/light/sky", sky_color=(255, 255, 255), ground_color=(120, 110, 100))


class InstancedGeoms:
    """Geoms of one model drawn as instanced batches under ``name`` in a viser scene.

    Args:
        scene: the server's scene API (``server.scene``).
        name: the scene-tree path of the group (``/world/moving``).
        model: the compiled model the geoms belong to.
        geoms: geom ids to draw.
        color: one RGB colour for every instance (a ghost), or None for the geoms' own.
        opacity: one opacity for every instance, or None for the geoms' own alpha.
        data: where the instances start (kinematics done).
    """

    def __init__(
        self,
        scene: viser.SceneApi,
        name: str,
        model: mujoco.MjModel,
        geoms: Iterable[int],
        data: mujoco.MjData,
        *,
        color: tuple[int, int, int] | None = None,
        opacity: float | None = None,
    ) -> None:
        self.model = model
        self.batches: list[ShapeBatch] = shape_batches(model, geoms)
        self.handles = []
        for batch in self.batches:
            positions, wxyz = batch.poses(model, data)
            alpha = batch.opacities
            transparent = opacity is not None or bool(np.any(alpha < 1.0))
            self.handles.append(
                scene.add_batched_meshes_simple(
                    f"{name}/{batch.key.replace(':', '_')}",
                    vertices=batch.vertices.astype(np.float32),
                    faces=batch.faces,
                    batched_wxyzs=wxyz.astype(np.float32),
                    batched_positions=positions.astype(np.float32),
                    batched_scales=batch.scales.astype(np.float32),
                    batched_colors=np.tile(np.array(color, dtype=np.uint8), (len(alpha), 1))
                    if color is not None
                    else batch.colors,
                    batched_opacities=None
                    if opacity is not None or not transparent
                    else alpha.astype(np.float32),
                    opacity=opacity if opacity is not None else (1.0 if transparent else None),
                    lod="off",
                    cast_shadow=opacity is None,
                    receive_shadow=opacity is None,
                    flat_shading=batch.key.startswith("box"),
                )
            )

    @property
    def instances(self) -> int:
        return sum(len(b.geoms) for b in self.batches)

    def poses(self, data: mujoco.MjData) -> list[tuple[FloatArray, FloatArray]]:
        """Per batch the (positions, wxyz) of its instances in ``data`` (kinematics done)."""
        return [batch.poses(self.model, data) for batch in self.batches]

    def update(self, data: mujoco.MjData) -> int:
        """Move every instance to its geom's pose in ``data`` (kinematics done): one message per shape
        whose instances moved (by more than :data:`STILL`); returns the shapes sent."""
        sent = 0
        for handle, (positions, wxyz) in zip(self.handles, self.poses(data), strict=True):
            p, q = positions.astype(np.float32), wxyz.astype(np.float32)
            if np.abs(p - handle.batched_positions).max(initial=0.0) <= STILL and (
                np.abs(q - handle.batched_wxyzs).max(initial=0.0) <= STILL
            ):
                continue
            handle.batched_positions = p
            handle.batched_wxyzs = q
            sent += 1
        return sent

    @property
    def visible(self) -> bool:
        return all(h.visible for h in self.handles)

    @visible.setter
    def visible(self, value: bool) -> None:
        for handle in self.handles:
            handle.visible = value

    def remove(self) -> None:
        for handle in self.handles:
            handle.remove()
        self.handles = []


class WorldView:
    """A whole world on the page: floor grid and fixed geoms drawn once, moving geoms updated.

    Args:
        server: the console's viser server.
        model: the world's model; ``data``: its state to start from (kinematics are run here
            on a private copy).
        name: scene-tree root.
    """

    def __init__(
        self, server: viser.ViserServer, model: mujoco.MjModel, data: mujoco.MjData, name: str = "/world"
    ) -> None:
        self.model = model
        self.data = mujoco.MjData(model)  # the view's own: kinematics off the caller's data
        self.data.qpos[:] = data.qpos
        mujoco.mj_kinematics(model, self.data)
        self._floor(server, name)
        fixed = [g for g in static_geoms(model) if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_PLANE]
        self.fixed = InstancedGeoms(server.scene, f"{name}/fixed", model, fixed, self.data)
        self.moving = InstancedGeoms(server.scene, f"{name}/moving", model, moving_geoms(model), self.data)
        self.qpos = self.data.qpos.copy()

    def _floor(self, server: viser.ViserServer, name: str) -> None:
        planes = [
            g for g in static_geoms(self.model) if self.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE
        ]
        for i, g in enumerate(planes):
            half = self.model.geom_size[g][:2]
            width, height = (2 * half) if np.all(half > 0) else (4.0, 4.0)
            server.scene.add_grid(
                f"{name}/floor{i}",
                width=float(min(width, 6.0)),
                height=float(min(height, 6.0)),
                cell_size=0.1,
                section_size=1.0,
                position=np.array(self.data.geom_xpos[g], dtype=float),
            )

    def update(self, qpos: FloatArray) -> bool:
        """Show the world at ``qpos`` (a full qpos of the model); False when nothing moved."""
        if np.array_equal(qpos, self.qpos):
            return False
        self.qpos = np.array(qpos, dtype=float)
        self.data.qpos[:] = self.qpos
        mujoco.mj_kinematics(self.model, self.data)
        self.moving.update(self.data)
        return True
