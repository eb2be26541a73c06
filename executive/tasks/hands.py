"""Hand targets for top-down grasps: the frames a task kind lays its steps out in.

:class:`HandFrames` knows the robot's home hand poses, its base and heading, and
which of the two ways to close across an object each hand prefers (its profile's
``closing_yaw``, e.g. a hand with a thumb on one side such as the G1's Dex3, else
the one nearer its home pose's), and makes :class:`HandTarget` values from a
point and the yaw of the object the jaws close across.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.planner import HandTarget
from executive.planning.types import site_quat
from executive.world.heading import yaw_of
from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = ["ONE_HAND", "UP", "HandFrames", "top_down_quat"]

FloatArray = NDArray[np.float64]
UP = np.array([0.0, 0.0, 1.0])
#: The hands, by side: the names of the alternatives that use one of them.
ONE_HAND = ("left", "right")


def top_down_quat(yaw: float) -> FloatArray:
    """Hand site frame with +z down and +y (closing) along the horizontal direction at ``yaw``."""
    y_axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    x_axis = np.cross(y_axis, z_axis)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x_axis, y_axis, z_axis]).ravel())
    return quat


class HandFrames:
    """Hand targets in one world: home poses, the body's midline, preferred closing directions.

    The home hand poses are the home keyframe's; once the robot has walked (the estimate
    ``follows_base``) they, the base and the heading move with the base where it stands now.

    Args:
        world: the estimate world (its home keyframe gives the home hand poses and the base).
        stance: where the base stands instead (pelvis x, y on the floor, heading rad): the frames
            of a robot that will have walked there (a side-step inside a composition).
    """

    def __init__(self, world: World, stance: tuple[float, float, float] | None = None) -> None:
        self.world = world
        with scratch_data(world.model) as data:
            mujoco.mj_resetDataKeyframe(world.model, data, world.ids.keyframe)
            mujoco.mj_kinematics(world.model, data)
            mat = data.xmat[world.ids.base_body]
            start, start_heading = data.xpos[world.ids.base_body].copy(), float(np.arctan2(mat[3], mat[0]))
            if stance is None:
                self._moved = _walked(world, start, start_heading)
            else:
                shift = np.array(stance[:2], dtype=float) - start[:2]
                self._moved = _Walked(start, stance[2] - start_heading, shift)
            self.home = {  # poses of the body: they move with the base (frame "base")
                side: self._moved.target(
                    HandTarget(side, data.site_xpos[site].copy(), site_quat(data, site), frame="base")
                )
                for side, site in world.ids.hand_sites.items()
            }
            self.base = self._moved.point(start)
            self.heading = start_heading + self._moved.turn  # yaw of the base's forward (x) axis
            self.shoulder = {  # each arm's first joint
                side: self._moved.point(data.xanchor[world.model.joint(arm.joints[0]).id].copy())
                for side, arm in world.profile.arms.items()
            }

    def stance(self) -> tuple[float, float, float]:
        """Where the base stands in these frames: pelvis x, y on the floor and heading (rad)."""
        return float(self.base[0]), float(self.base[1]), self.heading

    def to_world(self, xy: tuple[float, float]) -> tuple[float, float]:
        """A point of the floor given as if the robot stood at its start (x, y): where it is now."""
        p = self._moved.point(np.array([xy[0], xy[1], 0.0]))
        return float(p[0]), float(p[1])

    def side_of_body(self, point: FloatArray) -> float:
        """+1 left of the robot's midline, -1 right of it."""
        left_of_base = np.array([-np.sin(self.heading), np.cos(self.heading), 0.0])
        return 1.0 if float(np.dot(np.asarray(point) - self.base, left_of_base)) >= 0.0 else -1.0

    def closing_near_home(self, side: str, hand_yaw: float) -> float:
        """Of the two closing directions across an object at ``hand_yaw``, the one ``side`` prefers."""
        preferred = self.world.profile.arms[side].hand.closing_yaw_deg
        if preferred is None:
            mat = np.zeros(9)
            mujoco.mju_quat2Mat(mat, self.home[side].quat)
            want = float(np.arctan2(mat[4], mat[1]))  # yaw of the home frame's y (closing) axis
        else:
            want = self.heading + float(np.radians(preferred))
        closing = hand_yaw + np.pi / 2
        return closing + np.pi if np.cos(closing - want) < 0 else closing

    def target(
        self, side: str, point: FloatArray, hand_yaw: float, grasp_yaw: float | None = None
    ) -> HandTarget:
        """Top-down hand target whose jaws close across an object at ``hand_yaw``.

        ``grasp_yaw``: the object's yaw when this hand grasped it. A hand that holds (or has just
        released) an object turns it with itself, so its closing direction is the grasp's
        turned by the object's change of yaw, not whichever of the two is nearer home.
        """
        if grasp_yaw is None:
            closing = self.closing_near_home(side, hand_yaw)
        else:
            closing = self.closing_near_home(side, grasp_yaw) + (hand_yaw - grasp_yaw)
        return HandTarget(side, np.asarray(point, dtype=float), top_down_quat(closing))


class _Walked:
    """The planar motion of the base from its start: a turn ``turn`` (rad) about the start base,
    then a shift ``shift`` (m, x y)."""

    def __init__(self, start: FloatArray, turn: float, shift: FloatArray) -> None:
        self.start, self.turn, self.shift = np.asarray(start, dtype=float), float(turn), shift
        c, s = np.cos(self.turn), np.sin(self.turn)
        self.rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        self.quat = np.array([np.cos(self.turn / 2), 0.0, 0.0, np.sin(self.turn / 2)])

    def point(self, p: FloatArray) -> FloatArray:
        """``p`` moved with the base."""
        out = self.rotation @ (np.asarray(p, dtype=float) - self.start) + self.start
        out[:2] += self.shift
        return out

    def target(self, t: HandTarget) -> HandTarget:
        """A hand target moved with the base."""
        if self.turn == 0.0 and not np.any(self.shift):
            return t
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, self.quat, np.asarray(t.quat, dtype=float))
        return HandTarget(t.side, self.point(t.position), quat, t.frame)


def _walked(world: World, start: FloatArray, start_heading: float) -> _Walked:
    """How far the base has walked from its start in ``world`` (none unless it ``follows_base``)."""
    if not world.follows_base:
        return _Walked(start, 0.0, np.zeros(2))
    base = world.data.qpos[world.base_qpos]
    return _Walked(start, yaw_of(base[3:]) - start_heading, np.asarray(base[:2], dtype=float) - start[:2])
