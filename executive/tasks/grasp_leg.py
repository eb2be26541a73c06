"""One hand moves an object with a chosen grasp (:mod:`executive.tasks.grasp_candidates`).

A grasp from above is the one-hand leg every transfer had (:func:`executive.tasks.phases.one_hand_leg`),
its jaws across the object's local y (``top``) or x (``top_across``: the same leg with the
object's axes turned a quarter turn). A level grasp (``front``, ``side``) comes in along its
approach at the height the candidate chose, closes, lifts, carries the object in the same lane
in front of what is in the way (the hand's frame turned about the vertical with the object's
yaw), puts it down and backs out along the approach before it goes home.

Usage::

    steps = grasp_leg(HandFrames(world), "left", body, (pos, yaw), (centre, end_yaw), candidate, cfg)
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import HandTarget
from executive.schema.types import Body
from executive.tasks.grasp_candidates import GRASPS, GraspCandidate
from executive.tasks.hands import UP, HandFrames
from executive.tasks.phases import one_hand_layout, one_hand_leg

__all__ = ["grasp_leg", "turned"]

FloatArray = NDArray[np.float64]


def turned(quat: FloatArray, angle: float) -> FloatArray:
    """``quat`` (w x y z) turned by ``angle`` (rad) about the world's vertical."""
    out = np.zeros(4)
    turn = np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])
    mujoco.mju_mulQuat(out, turn, np.asarray(quat, dtype=float))
    return out


def _about_z(vector: FloatArray, angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    x, y, z = (float(v) for v in vector)
    return np.array([c * x - s * y, s * x + c * y, z])


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
        pre-grasp, approach, grasp, lift, the lane carry, pre-place, place, release, retreat, home.
    """
    kind = GRASPS[candidate.grasp]
    (pos, yaw), (centre, end_yaw) = start, end
    if not kind.level:
        quarter = 0.0 if kind.closing == "object_y" else math.pi / 2
        return one_hand_leg(h, side, body, (pos, yaw + quarter), (centre, end_yaw + quarter), cfg)
    layout = one_hand_layout(h, side, body, start, end, cfg, grasp_z=float(candidate.site[2]))
    offset = np.asarray(candidate.site, dtype=float) - np.asarray(pos, dtype=float)
    offset[2] = 0.0  # the site's level offset from the centre; the layout has its height
    turn = end_yaw - yaw

    def at(point: FloatArray, angle: float) -> HandTarget:
        return HandTarget(side, point + _about_z(offset, angle), turned(candidate.quat, angle))

    grasp, place_at = layout.grasp, layout.place_at
    approach = np.asarray(candidate.approach, dtype=float)
    back_out = _about_z(approach, turn)
    obj, carried = body.name, (side, body.name)
    lane_in, lane_out = layout.lane
    return [
        Step("move", f"{side}.pre_grasp", side, (at(grasp - cfg.approach_height * approach, 0.0),)),
        Step("move", f"{side}.approach", side, (at(grasp, 0.0),), allow_contact=(obj,)),
        Step("grasp", f"{side}.grasp", side, obj=obj),
        Step("lift", f"{side}.lift", side, (at(grasp + cfg.lift_height * UP, 0.0),), carried=carried),
        Step("carry", f"{side}.to_lane", side, (at(lane_in, turn / 2),), carried=carried),
        Step("carry", f"{side}.transfer", side, (at(lane_out, turn / 2),), carried=carried),
        Step(
            "carry",
            f"{side}.pre_place",
            side,
            (at(place_at + cfg.approach_height * UP, turn),),
            carried=carried,
        ),
        Step(
            "place",
            f"{side}.place",
            side,
            (at(place_at, turn),),
            carried=carried,
            allow_contact=("table_top",),
        ),
        Step("release", f"{side}.release", side, obj=obj),
        Step(
            "retreat",
            f"{side}.retreat",
            side,
            (at(place_at - cfg.approach_height * back_out, turn),),
            allow_contact=(obj,),
        ),
        Step("home", f"{side}.home", side, (h.home[side],), obj=obj),
    ]
