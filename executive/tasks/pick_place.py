"""The ``pick`` and ``place`` task kinds: take an object into a hand, and put it down later.

A ``pick`` ends with the object held at a hold pose in front of the body on the picking
hand's side (no release, no way home): a later task uses it. A ``place`` puts a held object
down from the hand that holds it, as the estimate knows it (``World.held_by``).

Alternatives (names stable): ``left``, ``right``. A pick offers both hands (a one-arm robot
its one); a place supports only the hand that holds the object, and says which one does.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import PlanningError
from executive.schema.declarations import Block
from executive.schema.scene_keys import OBJECT_NAME, TARGET, TO_YAW
from executive.schema.types import Body, SceneConfig
from executive.schema.yaml_nodes import Node
from executive.tasks.base import Alternative, Task, TaskKind, Verdict, alternatives_key
from executive.tasks.hands import ONE_HAND, UP, HandFrames
from executive.tasks.phases import carry_lane_front, grasp_height, lane_carry, pick, place
from executive.tasks.placement import placed_verdict, target_placement
from executive.tasks.variation import VariedPoint
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["PickKind", "PickTask", "PlaceKind", "PlaceTask", "held_verdict", "holder_of"]

FloatArray = NDArray[np.float64]
#: A hand "holds" an object with at least this many of its geoms on it, pressing this hard in
#: total (N): the grasp behaviour's own test (behaviours.gripper.Grasp).
MIN_CONTACTS, MIN_FORCE = 2, 10.0
#: A lane point closer than this (m) to where the hand already is is no motion: it is left out.
SAME_POINT = 0.01
#: A held object further than this (rad) from its place yaw is turned before the lane carry.
TURN_FIRST = np.radians(45.0)


@dataclass(frozen=True, kw_only=True)
class PickTask(Task):
    """Take ``object`` from the table into a hand and hold it in front of the body."""

    kind = "pick"


@dataclass(frozen=True, kw_only=True)
class PlaceTask(Task):
    """Put the held ``object`` at ``to`` (centre x, y[, z]); z None means resting on the table."""

    kind = "place"
    # x, y in [-10, 10], z in [0, 5] (m), as a transfer's target
    to: tuple[float, float, float | None]
    to_yaw_rad: float | None = None  # None: keep the object's yaw; [-360, 360] deg in YAML

    def label(self) -> str:
        to = ", ".join(f"{v:.2f}" for v in self.to if v is not None)
        return f"place {self.object} at ({to})"


def holder_of(world: World, obj: str) -> str | None:
    """The side of the hand that holds ``obj`` in the estimate ``world`` (None: no hand)."""
    return world.held_by(obj)


def _body(world: World, obj: str) -> Body:
    return next(b for b in world.scenario.scene.objects if b.name == obj)


def _length(body: Body) -> float:
    """The object's extent along its x axis (a box's length, else its diameter)."""
    return body.size[0] if body.shape == "box" else 2 * body.size[0]


class PickKind(TaskKind):
    """Pick an object up with one hand and keep holding it."""

    name = "pick"
    alternative_names = ONE_HAND
    leaves_held = True
    keys = Block(
        "Pick an object up with one hand and keep holding it (a place puts it down)",
        {"object": OBJECT_NAME, "alternatives": alternatives_key(ONE_HAND)},
        required=("object",),
        defaults={"alternatives": list(ONE_HAND)},
    )

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``pick: {object, alternatives: [left, right]}``."""
        from executive.schema.readers import read_object

        self.keys.check_keys(node)
        return PickTask(object=read_object(node, scene), alternatives=self.read_alternatives(node, ONE_HAND))

    def offered(self, task: Task, world: World) -> list[Alternative]:
        holder = holder_of(world, task.object)
        out = []
        for side in ONE_HAND:
            reason = "" if side in world.profile.sides else f"robot '{world.profile.name}' has no {side} arm"
            if not reason and holder is not None:
                reason = f"'{task.object}' is held by the {holder} hand already"
            out.append(Alternative(side, reason))
        return out

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        if alternative not in ONE_HAND:
            raise PlanningError(
                alternative, None, 0.0, 0.0, 0, reason=f"pick has no alternative '{alternative}'"
            )
        return pick_steps(world, task.object, alternative, config)

    def verify(self, task: Task, world: World, detector: object) -> Verdict | None:
        return held_verdict(detector, task.object)


def hold_point(
    world: World, h: HandFrames, side: str, obj: str, lift: FloatArray, cfg: CompositionConfig
) -> FloatArray:
    """Where the hand site holds a picked object: in front of the body on ``side``'s side.

    At the lift's height (the object clear of the table by ``lift_height``), level with the
    hand's home pose across the body, and as far forward as the lift but no farther than the
    lane in front of the obstacles the object passes on its way there (``obstacle_clearance``).
    """
    body = _body(world, obj)
    half = _length(body) / 2
    home_y = float(h.home[side].position[1])
    front = carry_lane_front(
        world.scenario.scene,
        (float(lift[1]), home_y),
        half + cfg.obstacle_clearance,
        float(h.base[0]),
        float(lift[0]),
        beyond=float(lift[0]) - half,
        ceiling=float(lift[2]) + cfg.approach_height,
    )
    return np.array([min(front - cfg.obstacle_clearance - half, float(lift[0])), home_y, float(lift[2])])


def pick_steps(world: World, obj: str, side: str, cfg: CompositionConfig) -> list[Step]:
    """Over the object, down, close, lift, then carry it to the hold pose (:func:`hold_point`)."""
    h = HandFrames(world)
    pos, quat = world.object_pose(obj)
    yaw = yaw_of(quat)
    grasp = np.array([pos[0], pos[1], grasp_height(_body(world, obj), pos[2], cfg)])
    hold = hold_point(world, h, side, obj, grasp + cfg.lift_height * UP, cfg)
    carry = Step("carry", f"{side}.hold", side, (h.target(side, hold, yaw, yaw),), carried=(side, obj))
    return [*pick(h, side, obj, grasp, yaw, cfg), carry]


def held_verdict(detector: object, obj: str) -> Verdict | None:
    """Does a hand hold ``obj`` now? The grasp behaviour's test, on the robot the detector watches.

    A robot with its own touch sensing (``hand_contacts(side, obj)``) answers itself; otherwise
    the contacts of the detector's MuJoCo world are counted. None: a detector that sees neither.
    """
    from behaviours.gripper import object_contacts

    sense = getattr(detector, "hand_contacts", None)
    world = getattr(detector, "world", None)
    if not callable(sense) and world is None:
        return None
    found: dict[str, tuple[int, float]] = {}
    for side in world.profile.sides if world is not None else ONE_HAND:
        n, force = sense(side, obj) if callable(sense) else object_contacts(detector, side, obj)
        found[side] = (n, force)
        if n >= MIN_CONTACTS and force >= MIN_FORCE:
            return Verdict(True, "held", {"object": obj, "side": side, "contacts": n, "force_n": force})
    from executive.monitoring.detectors import Failure

    touch = ", ".join(f"{s} {n} geoms {f:.1f} N" for s, (n, f) in found.items())
    detail = f"drop: no hand holds {obj} ({touch}; need {MIN_CONTACTS} geoms and {MIN_FORCE:.0f} N)"
    t = float(world.data.time) if world is not None else float(getattr(detector, "time", 0.0))
    fields = {"mode": "drop", "detail": detail, "behaviour": "hold", "time": t}
    return Verdict(False, "failure", fields, Failure("drop", detail, t, (obj,)))


class PlaceKind(TaskKind):
    """Put a held object down with the hand that holds it."""

    name = "place"
    alternative_names = ONE_HAND
    needs_held = True
    keys = Block(
        "Put a held object down with the hand that holds it (an earlier pick left it there)",
        {
            "object": OBJECT_NAME,
            "to": TARGET,
            "to_yaw": TO_YAW,
            "alternatives": alternatives_key(ONE_HAND),
        },
        required=("object", "to"),
        defaults={"alternatives": list(ONE_HAND)},
    )

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``place: {object, to: [x, y(, z)], to_yaw (deg), alternatives}``."""
        from executive.schema.readers import read_target

        self.keys.check_keys(node)
        name, to, yaw = read_target(node, scene)
        return PlaceTask(
            object=name, to=to, to_yaw_rad=yaw, alternatives=self.read_alternatives(node, ONE_HAND)
        )

    def offered(self, task: Task, world: World) -> list[Alternative]:
        holder = holder_of(world, task.object)
        out = []
        for side in ONE_HAND:
            if side not in world.profile.sides:
                reason = f"robot '{world.profile.name}' has no {side} arm"
            elif holder is None:
                reason = f"'{task.object}' is held by no hand (pick it first)"
            elif holder != side:
                reason = f"'{task.object}' is held by the {holder} hand"
            else:
                reason = ""
            out.append(Alternative(side, reason))
        return out

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        assert isinstance(task, PlaceTask)
        holder = holder_of(world, task.object)
        if alternative != holder:
            by = f"the {holder} hand" if holder else "no hand (a place starts where a pick left it in hand)"
            reason = f"place {alternative}: '{task.object}' is held by {by}"
            raise PlanningError(alternative, None, 0.0, 0.0, 0, reason=reason)
        return place_steps(world, task, alternative, config)

    def verify(self, task: Task, world: World, detector: object) -> Verdict | None:
        assert isinstance(task, PlaceTask)
        return placed_verdict(world, detector, task.object, task.to, task.to_yaw_rad)

    def varied_points(self, task: Task) -> tuple[VariedPoint, ...]:
        """The target ``to``, where the task puts its object down."""
        assert isinstance(task, PlaceTask)
        return (VariedPoint("to", task.to, places=task.object, yaw_rad=task.to_yaw_rad),)


def site_offset(world: World, obj: str, cfg: CompositionConfig) -> FloatArray:
    """From the held object's centre to the hand site (world frame, m), as the estimate has it.

    The grip the observations measured (``World.grips``: the object's pose in the site frame)
    when there is one; else where a top-down grasp puts the site, :func:`grasp_height` above
    the centre.
    """
    pos, quat = world.object_pose(obj)
    grip = world.grips.get(obj)
    if grip is None or not grip.looks:
        return (grasp_height(_body(world, obj), float(pos[2]), cfg) - float(pos[2])) * UP
    to_object, rel = np.zeros(9), np.zeros(9)
    mujoco.mju_quat2Mat(to_object, quat)
    mujoco.mju_quat2Mat(rel, np.asarray(grip.quat, dtype=float))
    # object = site * grip: the site is at -R_object R_grip^T p from the object's centre
    return np.asarray(-to_object.reshape(3, 3) @ rel.reshape(3, 3).T @ grip.position, dtype=float)


def natural_place_yaw(h: HandFrames, side: str, held_yaw: float, place_yaw: float, symmetry: int) -> float:
    """Of the yaws equivalent to ``place_yaw`` (``symmetry`` turns), the one the wrist turns to naturally.

    A hand turns a held object with itself. Among the equivalent place yaws, take the one whose
    closing direction is nearest the hand's preferred one for an object at that yaw (its
    profile's ``closing_yaw``, else its home pose's): a wrist turned half a turn from that
    cannot reach as far (a handover leaves the giver's wrist a quarter turn from natural).
    """
    grasp_closing = h.closing_near_home(side, held_yaw)

    def strain(yaw: float) -> float:
        closing = grasp_closing + (yaw - held_yaw)
        return abs(float(np.remainder(closing - h.closing_near_home(side, yaw) + np.pi, 2 * np.pi) - np.pi))

    n = max(1, symmetry)
    return min((place_yaw + 2 * np.pi * k / n for k in range(n)), key=strain)


def place_steps(world: World, task: PlaceTask, side: str, cfg: CompositionConfig) -> list[Step]:
    """From the hold: to the lane in front of what is in the way, across, then put it down, home.

    The hand site sits where a top-down grasp put it (:func:`grasp_height` above the object's
    centre); the object is where the estimate has it in the hand. Lane points the hand is
    already at are left out.
    """
    h = HandFrames(world)
    body = _body(world, task.object)
    pos, quat = world.object_pose(task.object)
    yaw = yaw_of(quat)
    offset = site_offset(world, task.object, cfg)
    site = pos + offset
    target = target_placement(world, body, task.to, task.to_yaw_rad, float(offset[2]))
    target = dataclasses.replace(target, yaw=natural_place_yaw(h, side, yaw, target.yaw, body.yaw_symmetry))
    turn = target.yaw - yaw
    c, s = np.cos(turn), np.sin(turn)
    place_at = target.centre + np.array(
        [c * offset[0] - s * offset[1], s * offset[0] + c * offset[1], offset[2]]
    )
    # Carried at the height a one-hand transfer carries (lift height over the place), or lower
    # if it is held lower: a hand held high (at a handover) reaches less far across the body.
    carry_z = max(min(site[2], place_at[2] + cfg.lift_height), place_at[2] + cfg.approach_height)
    half = _length(body) / 2
    near = min(float(pos[0]), float(target.centre[0])) - half
    front = carry_lane_front(
        world.scenario.scene,
        (pos[1], target.centre[1]),
        half + cfg.obstacle_clearance,
        h.base[0],
        pos[0],
        near,
    )
    lane_x = min(front - cfg.obstacle_clearance - half, place_at[0])
    lane = (np.array([lane_x, site[1], carry_z]), np.array([lane_x, place_at[1], carry_z]))
    carry, at = [], site
    # Far from its place yaw (as a handover leaves it, across the body), it turns on the way to
    # the lane; else half way there.
    far = abs(float(np.remainder(target.yaw - yaw + np.pi, 2 * np.pi) - np.pi)) > TURN_FIRST
    carry_yaw = (yaw + target.yaw) / 2
    for step, point in zip(
        lane_carry(h, side, task.object, lane, carry_yaw, yaw, target.yaw if far else None),
        lane,
        strict=True,
    ):
        if np.linalg.norm(point - at) > SAME_POINT:
            carry.append(step)
            at = point
    back: tuple[Step, ...] = ()
    if world.profile.return_along_lane and h.side_of_body(place_at) != h.side_of_body(h.home[side].position):
        back_point = np.array([lane_x, h.home[side].position[1], carry_z])
        back = (Step("move", f"{side}.back", side, (h.target(side, back_point, target.yaw, yaw),)),)
    return [*carry, *place(h, side, task.object, place_at, target.yaw, yaw, cfg, back)]
