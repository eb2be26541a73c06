"""The side-step: one hand picks, the robot steps sideways holding the object, the same hand places.

For a transfer whose place is beyond the reach of the hand that picks, stepping sideways
competes with the handover and with the other arm. The composition comes from the robot
and the scene, not from the scenario: the robot steps along its own lateral axis just far
enough that the place lies where the hand reaches from its own side of the body (in
the band between the body's midline and the hand's home line or its pick, whichever is
farther: it does not reach across the body), with the foot on the side it moves to leading.

The object travels in the one-arm carry's lane (:func:`executive.tasks.phases.one_hand_layout`):
the hand takes it there from the pick, the walk carries it along the lane, the hand finishes
the lane and places it from where the robot then stands; the robot stays there.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NoReturn

import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import PlanningError
from executive.tasks.hands import HandFrames
from executive.tasks.phases import back_along_lane, lane_carry, one_hand_layout, pick, place
from executive.tasks.placement import Destination, target_placement
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["SIDESTEPS", "cannot_sidestep", "sidestep_stance", "transfer"]

FloatArray = NDArray[np.float64]

#: The side-step alternatives of a transfer, by name: the hand that picks, carries and places.
SIDESTEPS = {"left_sidestep": "left", "right_sidestep": "right"}


def sidestep_stance(
    h: HandFrames, side: str, pick_at: FloatArray, place_at: FloatArray
) -> tuple[float, float, float]:
    """Where the base should stand so that ``side``'s hand places without reaching across the body.

    The hand is taken to reach what lies between the body's midline and the farther of its home
    line and the pick (both it reaches from the start), measured along the base's lateral axis;
    the base steps along that axis (heading kept) the least that brings the place into that band.
    Returns the base's (x, y, heading): where it stands when the place lies in the band already.
    """
    heading = h.heading
    left = np.array([-np.sin(heading), np.cos(heading)])
    base = np.asarray(h.base[:2], dtype=float)
    own = h.side_of_body(h.home[side].position)  # +1: the hand's side is the body's left

    def lateral(point: FloatArray) -> float:  # towards the hand's own side, from the midline
        return own * float((np.asarray(point[:2], dtype=float) - base) @ left)

    far = max(lateral(h.home[side].position), lateral(pick_at))
    across = lateral(place_at)
    d = min(across, 0.0) + max(across - far, 0.0)  # the place past the midline, or past the band
    x, y, _ = h.stance()
    return x + own * d * float(left[0]), y + own * d * float(left[1]), heading


def cannot_sidestep(world: World, side: str) -> str:
    """Why ``side`` cannot pick, step sideways and place on this robot ("" if it can)."""
    if side not in world.profile.sides:
        return f"robot '{world.profile.name}' has no {side} arm"
    feet = len(world.profile.feet)
    return "" if feet == 2 else f"robot '{world.profile.name}' has {feet} feet; a side-step needs two"


def transfer(world: World, task: Destination, side: str, cfg: CompositionConfig) -> list[Step]:
    """The steps of a side-step transfer by ``side``: pick, into the lane, walk, along the lane, place.

    Raises:
        PlanningError: the robot cannot step (it has not two feet), the hand works behind a wall
            it reaches past (a glove port: the arm cannot walk through it), or the place is
            within the hand's reach from where the robot stands (nothing to step for).
    """
    name = f"{side}_sidestep"
    if why := cannot_sidestep(world, side):
        _refuse(name, why)
    h = HandFrames(world)
    body = next(b for b in world.scenario.scene.objects if b.name == task.object)
    pos, quat = world.object_pose(task.object)
    yaw = yaw_of(quat)
    target = target_placement(world, body, task.to, task.to_yaw_rad, 0.0)
    layout = one_hand_layout(h, side, body, (pos, yaw), (target.centre, target.yaw), cfg)
    if layout.through:
        _refuse(name, f"the {side} hand reaches past a wall to '{task.object}'; it cannot walk with it")
    stance = sidestep_stance(h, side, layout.grasp, layout.place_at)
    moved = np.array([stance[0] - h.base[0], stance[1] - h.base[1], 0.0])
    if not moved.any():
        _refuse(name, f"the place is within the {side} hand's side of the body already: nothing to step for")
    there = HandFrames(world, stance)
    lead = _leading_foot(h, moved, tuple(world.profile.feet))
    carried = (side, task.object)
    # The walk carries the object in the lane straight ahead of the hand's home pose, the arm
    # tucked in front of its shoulder; the hand finishes the lane from where the robot stands then.
    lane_x, carry_z = float(layout.lane[0][0]), float(layout.lane[0][2])
    tucked = np.array([lane_x, h.home[side].position[1], carry_z])
    walked = np.array([lane_x, there.home[side].position[1], carry_z])
    into_lane = lane_carry(h, side, task.object, (layout.lane[0], tucked), yaw, yaw)
    tuck = replace(into_lane[1], name=f"{side}.tuck")
    along = lane_carry(there, side, task.object, (walked, layout.lane[1]), yaw, yaw, target.yaw)[1]
    walk = Step("step", f"{side}.sidestep", lead, carried=carried, stance=stance)
    back = back_along_lane(there, side, layout, target.yaw, yaw)
    return [
        *pick(h, side, task.object, layout.grasp, yaw, cfg),
        into_lane[0],
        tuck,
        walk,
        along,
        *place(there, side, task.object, layout.place_at, target.yaw, yaw, cfg, back),
    ]


def _leading_foot(h: HandFrames, moved: FloatArray, feet: tuple[str, ...]) -> str:
    """The foot on the side the base moves to by ``moved`` (it opens the stance; the other closes it)."""
    toward = h.side_of_body(h.base + moved)
    return "left" if toward > 0 and "left" in feet else "right" if "right" in feet else feet[0]


def _refuse(name: str, reason: str) -> NoReturn:
    raise PlanningError(name, None, 0.0, 0.0, 0, reason=reason)
