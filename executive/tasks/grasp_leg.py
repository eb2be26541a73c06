"""One hand moves an object with a chosen grasp (:mod:`executive.tasks.grasp_candidates`).

Every grasp takes the one-hand leg (:func:`executive.tasks.phases.one_hand_leg`). From above,
the jaws close across the object's local y (``top``) or x (``top_across``: the hand turned a
quarter turn). A grasp from a side (``front``, ``side``; a
:class:`LevelGrip`) comes in along its approach at the height the candidate chose, carries the
object in the same lane (the hand's frame turned about the vertical with the object's yaw), puts
it down and backs out along the approach before it goes home.

Usage::

    steps = grasp_leg(HandFrames(world), "left", body, (pos, yaw), (centre, end_yaw), candidate, cfg)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import HandTarget
from executive.schema.types import Body
from executive.tasks.grasp_candidates import GRASPS, GraspCandidate
from executive.tasks.hands import HandFrames
from executive.tasks.phases import TopDown, one_hand_leg, turned_about_z

__all__ = ["LevelGrip", "grasp_leg", "turned"]

FloatArray = NDArray[np.float64]


def turned(quat: FloatArray, angle: float) -> FloatArray:
    """``quat`` (w x y z) turned by ``angle`` (rad) about the world's vertical."""
    out = np.zeros(4)
    turn = np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])
    mujoco.mju_mulQuat(out, turn, np.asarray(quat, dtype=float))
    return out


@dataclass(frozen=True)
class LevelGrip:
    """A grasp from a side (:class:`executive.tasks.phases.Grip`): the candidate's hand frame, its
    site offset from the object's centre, both turned about the vertical with the object."""

    side: str
    offset: FloatArray  # the site's level offset from the object's centre at the pick
    quat: FloatArray  # the candidate's site frame at the pick (w x y z)
    approach: FloatArray

    def at(self, point: FloatArray, hand_yaw: float, grasp_yaw: float | None = None) -> HandTarget:
        """See :class:`executive.tasks.phases.Grip`."""
        angle = 0.0 if grasp_yaw is None else hand_yaw - grasp_yaw
        return HandTarget(self.side, point + turned_about_z(self.offset, angle), turned(self.quat, angle))


def grasp_leg(
    h: HandFrames,
    side: str,
    body: Body,
    start: tuple[FloatArray, float],
    end: tuple[FloatArray, float],
    candidate: GraspCandidate,
    cfg: CompositionConfig,
) -> list[Step]:
    """The ``side`` hand moves ``body`` from ``start`` to ``end`` (centre, yaw) with ``candidate``.

    Args:
        h: the hand frames of the estimate.
        side: the hand.
        body: the object.
        start: its centre and yaw where it rests now.
        end: its centre and yaw where it is to rest.
        candidate: the grasp (:func:`executive.tasks.grasp_candidates.grasp_candidates`).
        cfg: the composition's geometry.

    Returns:
        the steps of :func:`executive.tasks.phases.one_hand_leg` with the candidate's grip.
    """
    kind = GRASPS[candidate.grasp]
    if not kind.level:
        quarter = 0.0 if kind.closing == "object_y" else math.pi / 2
        return one_hand_leg(h, side, body, start, end, cfg, TopDown(h, side, quarter))
    offset = np.asarray(candidate.site, dtype=float) - np.asarray(start[0], dtype=float)
    offset[2] = 0.0  # the site's level offset from the centre; the layout has its height
    grip = LevelGrip(
        side, offset, np.asarray(candidate.quat, dtype=float), np.asarray(candidate.approach, dtype=float)
    )
    return one_hand_leg(h, side, body, start, end, cfg, grip, grasp_z=float(candidate.site[2]))
