"""An alternative's planned motion on the page: a ghost robot at a chosen time, and what the risk saw.

:class:`PlannedMotion` is one planned alternative seen along one time axis, the one its risk
reports use: its motion steps joined (:func:`executive.decision.assessment.concatenate`), so
the collision report's ``min_distance_time`` and the fall report's CoM traces fall on it. It
knows the closest approach the collision model found (the two geoms and the time; the witness
points are MuJoCo's ``mj_geomDistance`` between those geoms at that time) and the CoM path.

:class:`GhostView` draws one motion at a time: the robot (and the object it moves) as
semi-transparent instances at time ``t``, the CoM path on the floor with the support polygon
under the ghost's feet and the circle of the fall model at the knot of least margin, and the
closest approach as a red segment with its distance.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from executive.console.geoms import FloatArray
from executive.console.scene import InstancedGeoms
from executive.decision.assessment import AlternativeRisk, concatenate
from executive.planning.timing import Trajectory
from executive.risk.fall import support_polygon
from executive.world.model import World

if TYPE_CHECKING:
    import viser

__all__ = ["ClosestApproach", "GhostView", "PlannedMotion"]

GHOST_RGB = (20, 120, 255)
GHOST_OPACITY = 0.4
LIFT = 0.002  # m above the floor for lines drawn on it


@dataclass(frozen=True)
class ClosestApproach:
    """Where the planned motion passes closest to the environment, as the collision model found it."""

    distance: float  # m (the report's, from coal)
    time: float  # s on the motion's time axis
    robot: str  # robot-side body (a carried object counts as the robot's)
    environment: str  # environment body
    segment: FloatArray | None  # (2, 3) witness points env -> robot, None when the geoms are unknown

    def text(self) -> str:
        pair = f"{self.robot} - {self.environment}"
        return f"closest {self.distance * 1000:.1f} mm ({pair}) at t = {self.time:.2f} s"


def _geom_id(model: mujoco.MjModel, name: str) -> int:
    """A geom by the collision model's name for it (its name, or ``geom<id>``); -1 if unknown."""
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
    if g < 0 and name.startswith("geom") and name[4:].isdigit():
        g = int(name[4:]) if int(name[4:]) < model.ngeom else -1
    return int(g)


class PlannedMotion:
    """One feasible alternative's plan on one time axis, with its risk's closest approach and CoM path.

    Args:
        world: the estimate the alternative was planned on (its model; its floor).
        alternative: a feasible :class:`executive.decision.assessment.AlternativeRisk` (plan and risk).
    """

    def __init__(self, world: World, alternative: AlternativeRisk) -> None:
        if alternative.plan is None or alternative.risk is None:
            raise ValueError(f"{alternative.name} has no plan to show (infeasible)")
        self.name = alternative.name
        self.world = world
        self.alternative = alternative
        self.timeline: Trajectory = concatenate(alternative.plan.ordered_trajectories(), alternative.name)
        self.duration = self.timeline.duration
        self.object = alternative.plan.task.object or None
        self._data = mujoco.MjData(world.model)
        fall = alternative.risk.components.get("fall")
        self.com_path: FloatArray | None = None
        self.min_margin: tuple[float, float, float, float] | None = None  # x, y, margin, radius
        if fall is not None and "com_x" in fall.traces:
            self.com_path = np.stack([fall.traces["com_x"], fall.traces["com_y"]], axis=-1)
            k = int(np.argmin(fall.traces["margin"]))
            radius = float(fall.details.get("circle_radius", 0.0))
            self.min_margin = (
                float(self.com_path[k, 0]),
                float(self.com_path[k, 1]),
                float(fall.traces["margin"][k]),
                radius,
            )
        self.closest = self._closest(alternative.risk.components.get("collision"))

    def pose(self, t: float) -> mujoco.MjData:
        """The planned configuration at time ``t`` (clamped), kinematics done (the motion's own data)."""
        self._data.qpos[:] = self.timeline.sample(t)
        mujoco.mj_kinematics(self.world.model, self._data)
        return self._data

    def com(self, t: float) -> FloatArray:
        """The robot's CoM (x, y) as planned at ``t``."""
        times = self.timeline.times
        path = np.asarray(self.timeline.com_path, dtype=float)
        return np.array([np.interp(t, times, path[:, 0]), np.interp(t, times, path[:, 1])])

    def support(self, t: float) -> FloatArray | None:
        """The support polygon (V, 2) under the feet as planned at ``t`` (None: the feet span none)."""
        try:
            return support_polygon(self.world, self.pose(t), from_contacts=False)
        except ValueError:
            return None

    def _closest(self, report: Any) -> ClosestApproach | None:
        if report is None or "min_distance" not in report.details:
            return None
        d = report.details
        t = float(d["min_distance_time"])
        model = self.world.model
        env, robot = (
            _geom_id(model, str(d["closest_env_geom"])),
            _geom_id(model, str(d["closest_robot_geom"])),
        )
        segment = None
        if env >= 0 and robot >= 0:
            data = self.pose(t)
            fromto = np.zeros(6)
            mujoco.mj_geomDistance(model, data, env, robot, 1.0, fromto)
            segment = fromto.reshape(2, 3)
        return ClosestApproach(
            float(d["min_distance"]), t, str(d["closest_robot_body"]), str(d["closest_env_body"]), segment
        )

    def ghost_geoms(self) -> list[int]:
        """The robot's geoms and the moved object's."""
        ids = self.world.ids
        bodies = set(ids.robot_bodies)
        if self.object and self.object in ids.object_bodies:
            bodies.add(ids.object_bodies[self.object])
        model = self.world.model
        return [g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in bodies]


def _loop(points: FloatArray, z: float) -> FloatArray:
    """(N, 2, 3) segments closing the polygon ``points`` (N, 2) at height ``z``."""
    p = np.hstack([points, np.full((len(points), 1), z)])
    return np.stack([p, np.roll(p, -1, axis=0)], axis=1)


def _circle(x: float, y: float, r: float, z: float, n: int = 32) -> FloatArray:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return _loop(np.stack([x + r * np.cos(a), y + r * np.sin(a)], axis=-1), z)


class GhostView:
    """The ghost of one planned motion at a time ``t``, with its closest approach and CoM path.

    Args:
        server: the console's viser server.
        world: the estimate (the model the plans were made on).
        name: scene-tree root of the ghost and its marks.
    """

    def __init__(self, server: viser.ViserServer, world: World, name: str = "/ghost") -> None:
        self.server, self.world, self.name = server, world, name
        self.lock = threading.Lock()
        self.motion: PlannedMotion | None = None
        self.time = 0.0
        self._ghost: InstancedGeoms | None = None
        self._marks: list[Any] = []
        self._polygon: Any = None
        self._com: Any = None
        self._tag: Any = None
        floor = world.ids.floor_geom
        self.floor_z = float(world.data.geom_xpos[floor][2]) if floor >= 0 else 0.0

    def show(self, motion: PlannedMotion, t: float) -> None:
        """Show ``motion`` at time ``t`` (s, clamped to the motion)."""
        with self.lock:
            if motion is not self.motion:
                self._replace(motion)
            self.time = float(np.clip(t, 0.0, motion.duration))
            data = motion.pose(self.time)
            assert self._ghost is not None
            self._ghost.update(data)
            self._feet(motion)

    def hide(self) -> None:
        with self.lock:
            if self._ghost is not None:
                self._ghost.visible = False
            for handle in [*self._marks, self._polygon, self._com, self._tag]:
                if handle is not None:
                    handle.visible = False

    def _replace(self, motion: PlannedMotion) -> None:
        """Swap the ghost's geometry (when the model or the moved object changes) and redraw the marks."""
        old = self.motion
        self.motion = motion
        geoms = motion.ghost_geoms()
        if self._ghost is None or old is None or old.ghost_geoms() != geoms:
            if self._ghost is not None:
                self._ghost.remove()
            data = motion.pose(0.0)
            self._ghost = InstancedGeoms(
                self.server.scene,
                f"{self.name}/robot",
                self.world.model,
                geoms,
                data,
                color=GHOST_RGB,
                opacity=GHOST_OPACITY,
            )
        self._ghost.visible = True
        for handle in self._marks:
            handle.remove()
        self._marks = self._draw_marks(motion)

    def _draw_marks(self, motion: PlannedMotion) -> list[Any]:
        scene, z = self.server.scene, self.floor_z + LIFT
        marks: list[Any] = []
        if motion.com_path is not None and len(motion.com_path) > 1:
            p = np.hstack([motion.com_path, np.full((len(motion.com_path), 1), z)])
            segments = np.stack([p[:-1], p[1:]], axis=1)
            marks.append(
                scene.add_line_segments(f"{self.name}/com_path", segments, (30, 110, 220), thickness=0.004)
            )
        if motion.min_margin is not None and motion.min_margin[3] > 0:
            x, y, margin, r = motion.min_margin
            marks.append(
                scene.add_line_segments(
                    f"{self.name}/com_circle", _circle(x, y, r, z), (220, 60, 40), thickness=0.003
                )
            )
            marks.append(
                scene.add_label(
                    f"{self.name}/com_label",
                    f"least CoM margin {margin * 1000:.0f} mm",
                    position=(x, y, z + 0.02),
                    font_screen_scale=0.8,
                )
            )
        closest = motion.closest
        if closest is not None and closest.segment is not None:
            seg = closest.segment
            marks.append(
                scene.add_line_segments(f"{self.name}/closest", seg[None], (230, 30, 30), thickness=0.004)
            )
            for i, point in enumerate(seg):
                marks.append(
                    scene.add_icosphere(
                        f"{self.name}/closest_{i}", radius=0.008, color=(230, 30, 30), position=tuple(point)
                    )
                )
            marks.append(
                scene.add_label(
                    f"{self.name}/closest_label",
                    closest.text(),
                    position=tuple(seg[1] + [0, 0, 0.04]),
                    font_screen_scale=0.8,
                )
            )
        return marks

    def _feet(self, motion: PlannedMotion) -> None:
        """At the current time: the support polygon under the ghost's feet, its CoM, its name tag."""
        scene, z = self.server.scene, self.floor_z + LIFT
        ids = self.world.ids
        top = motion.pose(self.time).xpos[ids.head_body if ids.head_body is not None else ids.torso_body]
        self._tag = scene.add_label(
            f"{self.name}/tag",
            f"plan: {motion.name} at t = {self.time:.2f} s",
            position=(float(top[0]), float(top[1]), float(top[2]) + 0.25),
            font_screen_scale=0.9,
        )
        polygon = motion.support(self.time)
        if polygon is not None:
            self._polygon = scene.add_line_segments(
                f"{self.name}/support", _loop(polygon, z), (40, 160, 60), thickness=0.004
            )
        com = motion.com(self.time)
        if self._com is None:
            self._com = scene.add_icosphere(
                f"{self.name}/com", radius=0.012, color=(30, 110, 220), position=(com[0], com[1], z)
            )
        else:
            self._com.position = (float(com[0]), float(com[1]), z)
            self._com.visible = True
