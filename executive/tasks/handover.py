"""The handover: one hand passes an object to the other in front of the body.

Geometry: the giver grasps one end of the object's local x axis, the receiver the
other (``handover_offset`` either side of the centre), so both hands fit side by
side. At the handover the object lies across the body, the giver's end on the
giver's side, each forearm coming from its own shoulder. Both top-down hands take
and leave the object forearm-forward, so the object turns a half turn in all: only
an object a half turn leaves unchanged (even ``yaw_symmetry``) can be handed over.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import PlanningError
from executive.tasks.hands import UP, HandFrames
from executive.tasks.phases import grasp_height, pick, place
from executive.tasks.placement import Destination, target_placement
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["Exchange", "exchange", "transfer"]

FloatArray = NDArray[np.float64]


def _wrap(angle: float) -> float:
    return float(np.remainder(angle + np.pi, 2 * np.pi) - np.pi)


@dataclass(frozen=True)
class Exchange:
    """Where the handover happens: the hands' sites, the object's yaw, the giver's side direction."""

    giver: str
    receiver: str
    obj: str
    hand_g: FloatArray
    hand_r: FloatArray
    yaw: float
    side_dir: FloatArray
    centre: FloatArray


def check_symmetry(world: World, obj: str, alternative: str) -> None:
    """Raise :class:`PlanningError` for an object whose yaw a half turn would change."""
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    if body.yaw_symmetry % 2:
        raise PlanningError(
            alternative,
            None,
            0.0,
            float(np.pi),
            0,
            reason=(
                f"a top-down handover turns '{obj}' a half turn about the vertical, and its yaw "
                f"matters (yaw_symmetry {body.yaw_symmetry}); declare yaw_symmetry: 2 for an object "
                "a half turn leaves unchanged"
            ),
        )


def exchange_point(
    world: World, giver: str, receiver: str, obj: str, end: float, cfg: CompositionConfig
) -> Exchange:
    """The handover pose: object centre at ``handover_point`` (from the robot's base as it stood at
    the start, moved with it after a walk), lying across the body."""
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    pos, _ = world.object_pose(obj)
    site_above_centre = grasp_height(body, pos[2], cfg) - pos[2]
    h = HandFrames(world)
    hx, hy = h.to_world(cfg.handover_point)
    centre = np.array([hx, hy, world.scenario.scene.table.height + cfg.handover_height + body.half_height()])
    side = 1.0 if giver == "left" else -1.0
    side_dir = np.array([-side * np.sin(h.heading), side * np.cos(h.heading), 0.0])
    # The giver turns it by the shortest way that puts its end on its own side.
    yaw = float(np.arctan2(end * side_dir[1], end * side_dir[0]))
    d = cfg.handover_offset
    return Exchange(
        giver,
        receiver,
        obj,
        centre + d * side_dir + site_above_centre * UP,
        centre - d * side_dir + site_above_centre * UP,
        yaw,
        side_dir,
        centre,
    )


def exchange(h: HandFrames, x: Exchange, grasp_yaw: float, cfg: CompositionConfig) -> list[Step]:
    """The receiver comes over its end from above, closes; the giver opens, leaves up, out, home.

    While one hand holds the object and the other moves, the holding hand is kept where it is
    (an idle arm would move with the torso and carry the object away).
    """
    g, r, obj = x.giver, x.receiver, x.obj
    hold_g = h.target(g, x.hand_g, x.yaw, grasp_yaw)
    hold_r = h.target(r, x.hand_r, x.yaw)
    rise = h.target(r, x.hand_r - cfg.handover_side * x.side_dir + cfg.approach_height * UP, x.yaw)
    up = cfg.approach_height * UP
    clear = h.target(g, x.hand_g + cfg.handover_side * x.side_dir + up, x.yaw, grasp_yaw)
    return [
        Step("move", f"{r}.rise", r, (rise, hold_g), carried=(g, obj)),
        Step("move", f"{r}.pre_handover", r, (h.target(r, x.hand_r + up, x.yaw), hold_g), carried=(g, obj)),
        Step(
            "move",
            f"{r}.handover_approach",
            r,
            (h.target(r, x.hand_r, x.yaw), hold_g),
            carried=(g, obj),
            allow_contact=(obj,),
        ),
        Step("grasp", f"{r}.grasp", r, obj=obj),
        Step("release", f"{g}.release", g, obj=obj),
        # The giver's open jaws leave straight up (a palm moving down and sideways would push
        # the object's end down and turn it in the receiver's grip), out to its side, then home.
        Step(
            "retreat",
            f"{g}.retreat",
            g,
            (h.target(g, x.hand_g + up, x.yaw, grasp_yaw), hold_r),
            carried=(r, obj),
            allow_contact=(obj,),
        ),
        Step("move", f"{g}.clear", g, (clear, hold_r), carried=(r, obj)),
        Step("home", f"{g}.home", g, (h.home[g], hold_r), carried=(r, obj), allow_contact=(obj,)),
    ]


def _giver_to_exchange(
    h: HandFrames, x: Exchange, grasp: FloatArray, yaw: float, end: float, cfg: CompositionConfig
) -> list[Step]:
    """Pick at one end, back out of the table (keeping yaw), then across and turning to the handover."""
    g, obj = x.giver, x.obj
    axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    lift = grasp + cfg.lift_height * UP
    back = np.array([x.centre[0] + end * cfg.handover_offset * axis[0], lift[1], max(lift[2], x.hand_g[2])])
    turn = _wrap(x.yaw - yaw)
    n_turn = max(1, cfg.giver_turn_steps)
    turns = [
        Step(
            "carry",
            f"{g}.turn{k}",
            g,
            (h.target(g, back + (x.hand_g - back) * k / n_turn, yaw + turn * k / n_turn, yaw),),
            carried=(g, obj),
        )
        for k in range(1, n_turn)
    ]
    return [
        *pick(h, g, obj, grasp, yaw, cfg),
        # Back first (the object keeps its yaw), then across and turning: the object's far end
        # then sweeps well clear of the obstacles' front corner.
        Step("carry", f"{g}.back", g, (h.target(g, back, yaw, yaw),), carried=(g, obj)),
        *turns,
        Step("carry", f"{g}.to_handover", g, (h.target(g, x.hand_g, x.yaw, yaw),), carried=(g, obj)),
    ]


def _receiver_turn(
    h: HandFrames, x: Exchange, final_yaw: float, turn_r: FloatArray, back: float, cfg: CompositionConfig
) -> list[Step]:
    """The receiver turns the object to its place yaw in front of the body, in ``receiver_turn_steps``."""
    r, obj = x.receiver, x.obj
    n_back = max(1, cfg.receiver_turn_steps)
    steps = [
        Step(
            "carry",
            f"{r}.turn{k}",
            r,
            (h.target(r, x.hand_r + (turn_r - x.hand_r) * k / n_back, x.yaw + back * k / n_back, x.yaw),),
            carried=(r, obj),
        )
        for k in range(1, n_back)
    ]
    steps.append(Step("carry", f"{r}.turn", r, (h.target(r, turn_r, final_yaw, x.yaw),), carried=(r, obj)))
    return steps


def transfer(
    world: World, task: Destination, giver: str, receiver: str, cfg: CompositionConfig
) -> list[Step]:
    """The steps of a transfer by handover: giver picks and brings it over, exchange, receiver places.

    ``task``: what to put where (a :class:`executive.tasks.transfer.TransferTask`).
    """
    obj = task.object
    check_symmetry(world, obj, f"{giver}_to_{receiver}")
    h = HandFrames(world)
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    pos, quat = world.object_pose(obj)
    yaw = yaw_of(quat)
    # The giver holds the object's +x end (giver_end = 1) or its -x end (-1), the receiver the other.
    end = 1.0 if cfg.giver_end > 0 else -1.0
    axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    grasp_z = grasp_height(body, pos[2], cfg)
    grasp_g = np.array([*(pos[:2] + end * cfg.handover_offset * axis[:2]), grasp_z])
    x = exchange_point(world, giver, receiver, obj, end, cfg)
    target = target_placement(world, body, task.to, task.to_yaw_rad, grasp_z - pos[2])
    # The receiver's wrist turns back the natural way (its closing direction ends nearer its home
    # pose's). With both wrists turning naturally the object ends a half turn from the place yaw:
    # the same pose for an object with an even yaw_symmetry (checked above).
    back = _wrap(h.closing_near_home(receiver, target.yaw) - h.closing_near_home(receiver, x.yaw))
    final_yaw = x.yaw + back
    final_axis = np.array([np.cos(final_yaw), np.sin(final_yaw), 0.0])
    place_r = np.array(
        [
            *(target.centre[:2] - end * cfg.handover_offset * final_axis[:2]),
            target.centre[2] + target.site_above_centre,
        ]
    )
    # After the handover the receiver turns the object over the place's y (far from the
    # obstacles), then carries it straight out over the place and sets it down.
    tx, ty = cfg.turn_point if cfg.turn_point is not None else (x.centre[0], float(task.to[1]))
    turn_r = np.array(
        [
            tx - end * cfg.handover_offset * final_axis[0],
            ty - end * cfg.handover_offset * final_axis[1],
            x.centre[2] + target.site_above_centre,
        ]
    )
    return [
        *_giver_to_exchange(h, x, grasp_g, yaw, end, cfg),
        *exchange(h, x, yaw, cfg),
        *_receiver_turn(h, x, final_yaw, turn_r, back, cfg),
        *place(h, receiver, obj, place_r, final_yaw, x.yaw, cfg),
    ]
