"""The phases alternatives are composed of: pick up, carry along a lane, put down.

Each returns the :class:`Step` list of one hand for one phase; a kind strings phases
together (``transfer`` = pick + lane carry + place; ``pick`` = pick + hold;
``place`` = place from the holding hand). A :class:`Grip` says where the hand goes for a point
and yaw and which way it comes in: :class:`TopDown` (the default) from above, the jaws closing
across the object's local y extent (:class:`executive.tasks.hands.HandFrames`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import HandTarget
from executive.schema.types import Body, SceneConfig
from executive.tasks.hands import UP, HandFrames

__all__ = [
    "Grip",
    "OneHandLayout",
    "TopDown",
    "back_along_lane",
    "carry_lane_front",
    "footprint_half_y",
    "grasp_height",
    "lane_carry",
    "one_hand_layout",
    "one_hand_leg",
    "pick",
    "place",
    "reached_through",
    "turned_about_z",
]

FloatArray = NDArray[np.float64]


def turned_about_z(vector: FloatArray, angle: float) -> FloatArray:
    """``vector`` turned by ``angle`` (rad) about the world's vertical."""
    c, s = math.cos(angle), math.sin(angle)
    x, y, z = (float(v) for v in vector)
    return np.array([c * x - s * y, s * x + c * y, z])


class Grip(Protocol):
    """How one hand holds an object along a leg: its target for a point and yaw, its way in
    (``approach``; it backs out along it, turned with the object, after the place)."""

    @property
    def approach(self) -> FloatArray:
        """The unit direction of the hand's travel onto the object at the pick."""
        ...

    def at(self, point: FloatArray, hand_yaw: float, grasp_yaw: float | None = None) -> HandTarget:
        """The hand's target at ``point`` (the layout's hand site) with the object at ``hand_yaw``.

        ``grasp_yaw``: the object's yaw when the hand grasped it (None: not grasped yet).
        """
        ...


@dataclass(frozen=True)
class TopDown:
    """The grasp from above (:meth:`executive.tasks.hands.HandFrames.target`), the jaws across the
    object's local y, or turned by ``turn`` (rad) from it (``pi / 2``: across its local x)."""

    h: HandFrames
    side: str
    turn: float = 0.0
    approach: FloatArray = field(default_factory=lambda: -UP)

    def at(self, point: FloatArray, hand_yaw: float, grasp_yaw: float | None = None) -> HandTarget:
        """See :class:`Grip`."""
        grasped = None if grasp_yaw is None else grasp_yaw + self.turn
        return self.h.target(self.side, point, hand_yaw + self.turn, grasped)


def footprint_half_y(body: Body, yaws: tuple[float, ...]) -> float:
    """Half the extent along the world's y of ``body``'s footprint, the most over the yaws (rad)
    between the least and the largest of ``yaws`` (a box: ``L |sin| + W |cos|`` of its half sizes)."""
    if body.shape != "box":
        return float(body.size[0])  # a cylinder's or a sphere's radius
    half_l, half_w = body.size[0] / 2, body.size[1] / 2
    low, high = min(yaws), max(yaws)
    peak = math.atan2(half_l, half_w)  # where L |sin| + W |cos| is largest, every half turn
    turns = range(math.floor((low - peak) / math.pi) - 1, math.ceil((high + peak) / math.pi) + 2)
    inside = [a + k * math.pi for a in (peak, -peak) for k in turns if low <= a + k * math.pi <= high]
    return max(half_l * abs(math.sin(a)) + half_w * abs(math.cos(a)) for a in (low, high, *inside))


def grasp_height(body: Body, centre_z: float, cfg: CompositionConfig) -> float:
    """Height of the hand site for a top-down grasp of ``body`` with its centre at ``centre_z``."""
    return max(centre_z, centre_z + body.half_height() - cfg.grip_depth)


def pick(
    h: HandFrames,
    side: str,
    obj: str,
    grasp: FloatArray,
    yaw: float,
    cfg: CompositionConfig,
    grip: Grip | None = None,
) -> list[Step]:
    """In along the grip's approach onto the object (the open jaws may touch it), close, lift it.

    ``grip``: the grasp (default :class:`TopDown`: over the object, then down).
    """
    g = TopDown(h, side) if grip is None else grip
    return [
        Step("move", f"{side}.pre_grasp", side, (g.at(grasp - cfg.approach_height * g.approach, yaw),)),
        Step("move", f"{side}.approach", side, (g.at(grasp, yaw),), allow_contact=(obj,)),
        Step("grasp", f"{side}.grasp", side, obj=obj),
        Step(
            "lift", f"{side}.lift", side, (g.at(grasp + cfg.lift_height * UP, yaw, yaw),), carried=(side, obj)
        ),
    ]


def place(
    h: HandFrames,
    side: str,
    obj: str,
    point: FloatArray,
    place_yaw: float,
    grasp_yaw: float,
    cfg: CompositionConfig,
    back: tuple[Step, ...] = (),
    grip: Grip | None = None,
) -> list[Step]:
    """Over the place, down, open, back out along the grip's approach, (``back``: moves before
    turning home), home clear of the object. ``grip``: the grasp (default :class:`TopDown`)."""
    g = TopDown(h, side) if grip is None else grip
    above = point + cfg.approach_height * UP
    out = point - cfg.approach_height * turned_about_z(g.approach, place_yaw - grasp_yaw)
    carried = (side, obj)
    return [
        Step("carry", f"{side}.pre_place", side, (g.at(above, place_yaw, grasp_yaw),), carried=carried),
        Step(
            "place",
            f"{side}.place",
            side,
            (g.at(point, place_yaw, grasp_yaw),),
            carried=carried,
            allow_contact=("table_top",),
        ),
        Step("release", f"{side}.release", side, obj=obj),
        Step("retreat", f"{side}.retreat", side, (g.at(out, place_yaw, grasp_yaw),), allow_contact=(obj,)),
        *back,
        # The way home keeps clear of the object just placed (a hand that rotates back to its
        # home pose can sweep its fingers into it); brushing it is tolerated (obj).
        Step("home", f"{side}.home", side, (h.home[side],), obj=obj),
    ]


def _band(
    scene: SceneConfig, y_span: tuple[float, float], reach: float, base_x: float, ceiling: float
) -> list[tuple[float, float]]:
    """(near x, far x) of the obstacles ahead of the base that overlap the band ``y_span`` +- ``reach``.

    Obstacles wholly above ``ceiling`` (a roof the hand passes under) are left out.
    """
    low, high = min(y_span) - reach, max(y_span) + reach
    out = []
    for o in scene.obstacles:
        half_x = o.size[0] / 2 if o.shape == "box" else o.size[0]
        half_y = o.size[1] / 2 if o.shape == "box" else o.size[0]
        x, y = o.position[0], o.position[1]
        half_z = o.size[2] / 2 if o.shape == "box" else o.size[1] / 2 if o.shape == "cylinder" else o.size[0]
        if y + half_y < low or y - half_y > high or x + half_x <= base_x or o.position[2] - half_z >= ceiling:
            continue
        out.append((x - half_x, x + half_x))
    return out


def carry_lane_front(
    scene: SceneConfig,
    y_span: tuple[float, float],
    reach: float,
    base_x: float,
    default: float,
    beyond: float = -np.inf,
    ceiling: float = np.inf,
) -> float:
    """The x of the nearest front face among the obstacles a carry across ``y_span`` would pass.

    An obstacle counts when its footprint overlaps the band swept by the carried object
    (``y_span`` widened by ``reach`` either side) and lies ahead of the robot's base; side walls
    of an enclosure beside the work area do not. Nor does one wholly nearer the robot than
    ``beyond`` (the object's near edge at its start and at its target): the arm reaches past it
    (the front wall of a glovebox, reached through its ports), so the lane stays behind it;
    nor one wholly above ``ceiling`` (a roof the hand passes under). ``default`` when none is
    in the way.
    """
    fronts = [near for near, far in _band(scene, y_span, reach, base_x, ceiling) if far > beyond]
    return min(fronts, default=default)


def reached_through(
    scene: SceneConfig,
    y_span: tuple[float, float],
    reach: float,
    base_x: float,
    beyond: float,
    ceiling: float,
) -> bool:
    """Whether the arm reaches past an obstacle (a front wall with ports) to work across ``y_span``.

    True when an obstacle ahead of the base, overlapping the band ``y_span`` +- ``reach`` and not
    wholly above ``ceiling``, lies wholly nearer the robot than ``beyond``: the obstacles
    :func:`carry_lane_front` leaves out because the arm passes them.
    """
    return any(far <= beyond for _, far in _band(scene, y_span, reach, base_x, ceiling))


def lane_carry(
    h: HandFrames,
    side: str,
    obj: str,
    points: tuple[FloatArray, FloatArray],
    carry_yaw: float,
    grasp_yaw: float,
    exit_yaw: float | None = None,
    grip: Grip | None = None,
) -> list[Step]:
    """Back to the lane, then across the body in it (the object skirting what is in the way).

    The object is at ``carry_yaw`` on reaching the lane and at ``exit_yaw`` (default the same) at
    its end: a large turn is shared between the two moves. ``grip``: the grasp (default
    :class:`TopDown`).
    """
    g = TopDown(h, side) if grip is None else grip
    lane_in, lane_out = points
    out_yaw = carry_yaw if exit_yaw is None else exit_yaw
    carried = (side, obj)
    return [
        Step("carry", f"{side}.to_lane", side, (g.at(lane_in, carry_yaw, grasp_yaw),), carried=carried),
        Step("carry", f"{side}.transfer", side, (g.at(lane_out, out_yaw, grasp_yaw),), carried=carried),
    ]


@dataclass(frozen=True)
class OneHandLayout:
    """Where one hand's pick, lane carry and place go (:func:`one_hand_layout`).

    ``grasp``, ``place_at``: the hand site at the pick and at the place; ``lane``: the carry lane's
    two ends (at the pick's y and at the place's y); ``through``: the hand works behind a wall it
    reaches past (its ``own_line``, straight ahead of its home pose, is the way in and out).
    """

    grasp: FloatArray
    place_at: FloatArray
    lane: tuple[FloatArray, FloatArray]
    own_line: FloatArray
    through: bool


def one_hand_layout(
    h: HandFrames,
    side: str,
    body: Body,
    start: tuple[FloatArray, float],
    end: tuple[FloatArray, float],
    cfg: CompositionConfig,
    grasp_z: float | None = None,
) -> OneHandLayout:
    """The pick, lane and place of one hand moving ``body`` from ``start`` to ``end`` (centre, yaw).

    The lane runs in front of what the carry would pass (what overlaps the y the object's
    footprint sweeps from ``start``'s yaw to ``end``'s, :func:`footprint_half_y`), the carried
    object skirting the obstacles' front at ``obstacle_clearance`` (:func:`carry_lane_front`).
    ``grasp_z``: the hand site's height at the grasp (None: a top-down grasp's, :func:`grasp_height`).
    """
    (pos, yaw), (centre, end_yaw) = start, end
    z = grasp_height(body, float(pos[2]), cfg) if grasp_z is None else grasp_z
    grasp = np.array([pos[0], pos[1], z])
    place_at = centre + (grasp[2] - pos[2]) * UP
    carry_z = max(grasp[2] + cfg.lift_height, place_at[2] + cfg.approach_height)
    length = body.size[0] if body.shape == "box" else 2 * body.size[0]
    scene = h.world.scenario.scene
    reach = footprint_half_y(body, (yaw, end_yaw)) + cfg.obstacle_clearance
    near = min(pos[0], centre[0]) - length / 2
    above = carry_z + cfg.approach_height  # the hand and wrist over the carried object
    front_x = carry_lane_front(scene, (pos[1], centre[1]), reach, h.base[0], pos[0], near, above)
    lane_x = min(front_x - cfg.obstacle_clearance - length / 2, grasp[0], place_at[0])
    lane = (np.array([lane_x, grasp[1], carry_z]), np.array([lane_x, place_at[1], carry_z]))
    own_line = np.array([lane_x, h.home[side].position[1], carry_z])
    span = (float(own_line[1]), float(pos[1]), float(centre[1]))
    through = reached_through(scene, (min(span), max(span)), reach, h.base[0], near, above)
    return OneHandLayout(grasp, place_at, lane, own_line, through)


def back_along_lane(
    h: HandFrames, side: str, layout: OneHandLayout, end_yaw: float, yaw: float, grip: Grip | None = None
) -> tuple[Step, ...]:
    """The move back to the hand's own side along the lane after placing across the body, for a
    robot whose profile asks for it (``return_along_lane``); none otherwise. ``grip``: the grasp
    (default :class:`TopDown`)."""
    g = TopDown(h, side) if grip is None else grip
    place_at, lane_x = layout.place_at, float(layout.lane[0][0])
    if not h.world.profile.return_along_lane or h.side_of_body(place_at) == h.side_of_body(
        h.home[side].position
    ):
        return ()
    back_point = np.array([lane_x, h.home[side].position[1], float(layout.lane[0][2])])
    back = replace(g.at(back_point, end_yaw, yaw), frame="base")  # ahead of the hand's home
    return (Step("move", f"{side}.back", side, (back,)),)


def one_hand_leg(
    h: HandFrames,
    side: str,
    body: Body,
    start: tuple[FloatArray, float],
    end: tuple[FloatArray, float],
    cfg: CompositionConfig,
    grip: Grip | None = None,
    grasp_z: float | None = None,
) -> list[Step]:
    """One hand moves ``body`` from ``start`` to ``end`` (centre, yaw), both resting: pick, carry, place.

    Straight, simple hand paths: in along the grip's approach (default :class:`TopDown`: from
    above), up, back to the lane, across the body in that lane (the carried object skirting the
    front of the obstacles it passes at ``obstacle_clearance``, :func:`one_hand_layout`), over the
    place, down, open, back out, home. A robot whose profile asks for it (``return_along_lane``)
    first goes back along the lane to its own side after placing across the body, as it is, and
    only then turns home: the straight way home from across the body swings the arm across the
    body's front while the hand turns. A hand that works behind a wall it reaches past
    (:func:`reached_through`: a glove port) goes in and out along its own line, straight ahead of
    its home pose, and moves sideways only behind the wall. ``grasp_z``: the hand site's height
    at the grasp (None: a top-down grasp's).
    """
    g = TopDown(h, side) if grip is None else grip
    (_, yaw), (_, end_yaw) = start, end
    layout = one_hand_layout(h, side, body, start, end, cfg, grasp_z)
    entry: tuple[Step, ...] = ()
    back: tuple[Step, ...] = ()
    if layout.through:
        entry = (Step("move", f"{side}.reach_in", side, (g.at(layout.own_line, yaw),)),)
        back = (Step("move", f"{side}.back", side, (g.at(layout.own_line, end_yaw, yaw),)),)
    else:
        back = back_along_lane(h, side, layout, end_yaw, yaw, g)
    return [
        *entry,
        *pick(h, side, body.name, layout.grasp, yaw, cfg, g),
        *lane_carry(h, side, body.name, layout.lane, (yaw + end_yaw) / 2, yaw, grip=g),
        *place(h, side, body.name, layout.place_at, end_yaw, yaw, cfg, back, g),
    ]
