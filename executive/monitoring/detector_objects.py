"""The object checks, verdict ``drop``: a carried object slipping out, a placed one off its target.

:class:`HoldCheck` runs after every physics step while a hand carries (the distance from
the hand's site to the object's surface); :func:`check_placement` runs once at the end of
a task that puts an object down. An object on the floor is a drop too; the contact check
sees it.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.monitoring.detector_base import DetectorThresholds, Failure, Phase
from executive.world.model import World

__all__ = ["HoldCheck", "check_placement"]

_BOX, _SPHERE, _CYLINDER = (
    int(mujoco.mjtGeom.mjGEOM_BOX),
    int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CYLINDER),
)


class HoldCheck:
    """Verdict ``drop`` when the carried object is farther than ``hold_distance`` from the hand's site.

    The distance is to the object's surface: 0 while the site is inside it, as between closed
    jaws. Nothing is checked while no hand carries (``set_phase`` with ``carried`` None).
    """

    def __init__(self, world: World, thresholds: DetectorThresholds) -> None:
        m, d, ids = world.model, world.data, world.ids
        self._m = m
        self._site_xpos = d.site_xpos
        self._geom_xpos, self._geom_xmat = d.geom_xpos, d.geom_xmat
        self._geom_type: list[int] = m.geom_type.tolist()
        self._hand_sites = ids.hand_sites
        self._object_geom = dict(ids.object_geoms)
        self._hold_distance = thresholds.hold_distance
        self._carried: tuple[str, str] | None = None

    def set_phase(self, phase: Phase) -> None:
        """Watch the hand and object ``phase.carried`` names (None: nothing)."""
        self._carried = phase.carried

    def check(self, t: float) -> Failure | None:
        """A ``drop`` failure naming the object and the hand site, or None."""
        if self._carried is None:
            return None
        side, name = self._carried
        site = self._hand_sites[side]
        dist = self._surface_distance(self._object_geom[name], self._site_xpos[site])
        if dist <= self._hold_distance:
            return None
        return Failure(
            "drop",
            f"drop: {name} is {dist:.3f} m from the {side} hand site {self._m.site(site).name} "
            f"(limit {self._hold_distance:.3f} m) at t={t:.3f} s",
            t,
            (name, self._m.body(self._m.site_bodyid[site]).name),
        )

    def _surface_distance(self, geom: int, point: NDArray[np.float64]) -> float:
        """Distance from ``point`` to the geom's surface; 0 inside (box, sphere, cylinder, else centre).

        Plain float arithmetic on three-vectors (it runs after every physics step while a hand
        carries): ``local = R^T (point - centre)`` in the geom's frame.
        """
        px, py, pz = point.tolist()
        cx, cy, cz = self._geom_xpos[geom].tolist()
        r = self._geom_xmat[geom].tolist()  # row-major R: world = R @ local
        dx, dy, dz = px - cx, py - cy, pz - cz
        lx = r[0] * dx + r[3] * dy + r[6] * dz
        ly = r[1] * dx + r[4] * dy + r[7] * dz
        lz = r[2] * dx + r[5] * dy + r[8] * dz
        sx, sy, sz = self._m.geom_size[geom].tolist()
        kind = self._geom_type[geom]
        if kind == _BOX:
            ox, oy, oz = max(abs(lx) - sx, 0.0), max(abs(ly) - sy, 0.0), max(abs(lz) - sz, 0.0)
            return math.sqrt(ox * ox + oy * oy + oz * oz)
        if kind == _SPHERE:
            return max(0.0, math.sqrt(lx * lx + ly * ly + lz * lz) - sx)
        if kind == _CYLINDER:
            radial = max(0.0, math.hypot(lx, ly) - sx)
            axial = max(0.0, abs(lz) - sy)
            return math.hypot(radial, axial)
        return math.sqrt(lx * lx + ly * ly + lz * lz)


def check_placement(
    world: World,
    thresholds: DetectorThresholds,
    obj: str,
    target_xy: tuple[float, float],
    target_yaw: float | None = None,
    yaw_symmetry: int = 1,
) -> Failure | None:
    """Is ``obj`` resting on the table at ``target_xy`` (and ``target_yaw``, rad)?

    Args:
        world: the truth world, in the state to judge.
        thresholds: ``place_position_tol``, ``place_yaw_tol_deg``, ``place_tilt_deg``, ``rest_speed``.
        obj: an object of the scene (the caller checks the name).
        target_xy: where its centre should rest in the table plane (m).
        target_yaw: its yaw there (rad), or None not to check the yaw.
        yaw_symmetry: the yaw error counts modulo ``2*pi / yaw_symmetry`` (``Body.yaw_symmetry``).

    Returns:
        None when it is within the tolerances, upright, at rest and touching the table;
        otherwise a ``drop`` failure naming what is off.
    """
    m, d, th, ids = world.model, world.data, thresholds, world.ids
    t = float(d.time)
    body = ids.object_bodies[obj]
    pos = d.xpos[body]
    rot = d.xmat[body].reshape(3, 3)
    problems: list[str] = []
    err = math.hypot(float(pos[0]) - target_xy[0], float(pos[1]) - target_xy[1])
    if not err <= th.place_position_tol:
        problems.append(
            f"rests {err:.3f} m from its target ({target_xy[0]:.3f}, {target_xy[1]:.3f}) "
            f"(tolerance {th.place_position_tol:.3f} m) at ({pos[0]:.3f}, {pos[1]:.3f})"
        )
    if target_yaw is not None:
        yaw = math.atan2(float(rot[1, 0]), float(rot[0, 0]))
        dyaw = math.degrees(abs(math.remainder(yaw - target_yaw, 2 * math.pi / max(1, yaw_symmetry))))
        if not dyaw <= th.place_yaw_tol_deg:
            problems.append(f"yaw off by {dyaw:.1f} deg (tolerance {th.place_yaw_tol_deg:.1f} deg)")
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(rot[2, 2])))))
    if not tilt <= th.place_tilt_deg:
        problems.append(f"tipped {tilt:.1f} deg (limit {th.place_tilt_deg:.1f} deg)")
    vel = np.zeros(6)
    mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, vel, 0)
    lin, ang = float(np.linalg.norm(vel[3:])), float(np.linalg.norm(vel[:3]))
    if not (lin <= th.rest_speed and ang <= 10.0 * th.rest_speed):
        problems.append(f"still moving ({lin:.3f} m/s, {ang:.3f} rad/s)")
    g = ids.object_geoms[obj]
    table_top = ids.table_geoms[0] if ids.table_geoms else -1
    on_table = any(g in pair and table_top in pair for pair in (d.contact.geom.tolist() if d.ncon else []))
    if not on_table:
        problems.append(f"not on the table (centre at z={pos[2]:.3f} m)")
    if not problems:
        return None
    return Failure("drop", f"drop: {obj} " + "; ".join(problems) + f" at t={t:.3f} s", t, (obj,))
