"""The ``transfer`` task kind: move an object to a place on the table (or on something on it).

Alternatives (names stable; Long et al. 2018, section "Total risk"):

* ``left``, ``right``: pick and place with one hand, carried across the body in a lane
  in front of what the carry would pass;
* ``left_to_right``, ``right_to_left``: pick with the first hand, hand over in front of
  the body, place with the second (only for an object a half turn leaves unchanged);
* ``left_regrasp_right``, ``right_regrasp_left``: pick with the first hand, set the object
  down on a free spot of the table near the midline, let go and go clear; the second hand
  picks it up there and places it (the way for an object that cannot be handed over:
  its yaw is never turned; :mod:`executive.tasks.regrasp`). Not in the default list
  (``TransferKind.default_alternatives``): it plans two one-arm legs, so ask for it by name.
* ``left_sidestep``, ``right_sidestep``: pick with that hand, step sideways holding the object,
  place with the same hand from where the robot then stands (:mod:`executive.tasks.sidestep`).
  Planned only where the one-arm alternative of that hand cannot be (``instead_of``): the
  place beyond that hand's reach from where the robot stands.

With a grasp (``grasps``, :mod:`executive.tasks.grasp_candidates`) the one-hand alternatives are
arm x grasp: ``left`` and ``right`` grasp from above across the object's width (``top``, the
default); ``<side>_<grasp>`` (``left_front_75``, ``right_side``) with the other grasps asked for.
Before planning each hand's grasps are pruned, with the reason on their rows: those the hand
cannot make (too wide, too low, out of reach) and all but its :data:`PLANNED_PER_HAND` likeliest.

A one-arm robot offers its one hand; a robot's profile may declare any of them unsupported.
An object already in a hand (a re-plan after a failed handover) is put down by that hand
(``left`` or ``right``: lane carry and place from where it is); the others are then unsupported.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import mujoco
import numpy as np

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import HandTarget, PlanningError
from executive.planning.types import PlannerConfig
from executive.schema.declarations import Block, Choice, ListOf
from executive.schema.scene_keys import OBJECT_NAME, TARGET, TO_YAW
from executive.schema.types import SceneConfig
from executive.schema.yaml_nodes import Node
from executive.tasks import handover as handover_steps
from executive.tasks import regrasp as regrasp_steps
from executive.tasks import sidestep as sidestep_steps
from executive.tasks.base import Alternative, Task, TaskKind, Verdict, alternatives_key
from executive.tasks.grasp_candidates import (
    DEFAULT_GRASPS,
    GRASPS,
    grasp_candidates,
    home_approach,
    rank_grasps,
)
from executive.tasks.grasp_geometry import GraspGeometryError
from executive.tasks.grasp_leg import grasp_leg
from executive.tasks.hands import ONE_HAND, HandFrames
from executive.tasks.phases import one_hand_leg
from executive.tasks.pick_place import PlaceTask, place_steps, site_offset
from executive.tasks.placement import placed_verdict, target_placement
from executive.tasks.variation import VariedPoint
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = [
    "GRASPED",
    "HANDOVERS",
    "PLANNED_PER_HAND",
    "REGRASPS",
    "SIDESTEPS",
    "TransferKind",
    "TransferTask",
    "grasp_alternatives",
    "transfer_steps",
]

HANDOVERS = ("left_to_right", "right_to_left")
REGRASPS = tuple(regrasp_steps.REGRASPS)
SIDESTEPS = tuple(sidestep_steps.SIDESTEPS)
#: One-hand alternatives with a grasp other than ``top``: name -> (side, grasp).
GRASPED = MappingProxyType({f"{side}_{g}": (side, g) for g in GRASPS if g != "top" for side in ONE_HAND})
#: At most this many grasps of each hand are planned; the rest are pruned before planning.
PLANNED_PER_HAND = 3
_GRASPS_KEY = ListOf(
    "the grasps the one-hand alternatives try, each a dimension of them (top: from above across the "
    "object's width, the alternatives left and right; any other g: alternatives left_g and right_g): "
    + "; ".join(f"{k.name}: {k.description}" for k in GRASPS.values()),
    Choice("a grasp", lambda: tuple(GRASPS)),
    min_len=1,
)


@dataclass(frozen=True, kw_only=True)
class TransferTask(Task):
    """Move ``object`` to ``to`` (centre x, y[, z]); z None means resting on the table."""

    kind = "transfer"
    # x, y in [-10, 10], z in [0, 5] (m): over the table, within the robot's reach, the object there
    # clear of obstacles and other objects; with z it must rest on the table or on something on it
    to: tuple[float, float, float | None]
    to_yaw_rad: float | None = None  # None: keep the object's yaw; [-360, 360] deg in YAML
    grasps: tuple[str, ...] = DEFAULT_GRASPS  # the grasps the one-hand alternatives try

    def label(self) -> str:
        to = ", ".join(f"{v:.2f}" for v in self.to if v is not None)
        return f"transfer {self.object} to ({to})"


def grasp_alternatives(alternatives: tuple[str, ...], grasps: tuple[str, ...]) -> tuple[str, ...]:
    """``alternatives`` with each one-hand one (``left``, ``right``) as one per grasp, in order."""
    out: list[str] = []
    for name in alternatives:
        if name not in ONE_HAND:
            out.append(name)
            continue
        out += [
            name if g == "top" else f"{name}_{g}"
            for g in grasps
            if (name if g == "top" else f"{name}_{g}") not in out
        ]
    return tuple(out)


class TransferKind(TaskKind):
    """Move an object to a target pose: one hand, or two with a handover or a regrasp."""

    name = "transfer"
    alternative_names = (*ONE_HAND, *HANDOVERS, *REGRASPS, *SIDESTEPS, *GRASPED)
    default_alternatives = ("left", "right", "left_to_right", *SIDESTEPS)
    instead_of = MappingProxyType(dict(sidestep_steps.SIDESTEPS))
    keys = Block(
        "Move an object to a target: one hand (left, right), a handover (left_to_right, "
        "right_to_left: the object turns a half turn), a regrasp (left_regrasp_right, "
        "right_regrasp_left: set down near the midline and picked up by the other hand) or a "
        "side-step (left_sidestep, right_sidestep: the hand carries it through a walk; planned only "
        "where that hand's one-arm carry cannot be)",
        {
            "object": OBJECT_NAME,
            "to": TARGET,
            "to_yaw": TO_YAW,
            "alternatives": alternatives_key(alternative_names),
            "grasps": _GRASPS_KEY,
        },
        required=("object", "to"),
        defaults={"alternatives": list(default_alternatives), "grasps": list(DEFAULT_GRASPS)},
    )

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``transfer: {object, to: [x, y(, z)], to_yaw (deg), alternatives}``."""
        from executive.schema.readers import read_target

        self.keys.check_keys(node)
        name, to, yaw = read_target(node, scene)
        grasps_node = node.opt("grasps")
        grasps = DEFAULT_GRASPS
        if grasps_node is not None:
            grasps = _GRASPS_KEY.read(grasps_node)
            for i, g in enumerate(grasps):
                if g in grasps[:i]:
                    grasps_node.fail(f"grasp '{g}' is listed twice")
        alternatives = self.read_alternatives(node, self.default_alternatives)
        return TransferTask(
            object=name,
            to=to,
            to_yaw_rad=yaw,
            alternatives=grasp_alternatives(alternatives, grasps),
            grasps=grasps,
        )

    def offered(self, task: Task, world: World) -> list[Alternative]:
        sides = world.profile.sides
        out = [Alternative(s) for s in ONE_HAND if s in sides]
        for name in (*HANDOVERS, *REGRASPS):
            missing = [s for s in HANDOVERS_SIDES.get(name) or regrasp_steps.REGRASPS[name] if s not in sides]
            reason = f"robot '{world.profile.name}' has no {' and no '.join(missing)} arm" if missing else ""
            out.append(Alternative(name, reason))
        for name, side in sidestep_steps.SIDESTEPS.items():
            out.append(Alternative(name, sidestep_steps.cannot_sidestep(world, side)))
        holder = world.held_by(task.object)
        if holder is None:
            return _with_grasps(task, world, out)
        # Already in a hand (a re-plan after a failed handover, say): that hand puts it down.
        held = f"'{task.object}' is in the {holder} hand: only '{holder}' starts there (placing it)"
        return [a if a.name == holder or a.unsupported else Alternative(a.name, held) for a in out]

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        assert isinstance(task, TransferTask)
        if world.held_by(task.object) == alternative:
            # No yaw asked: the yaw it had in the scene (not the one the hand has turned it to).
            body = next(b for b in world.scenario.scene.objects if b.name == task.object)
            yaw = task.to_yaw_rad if task.to_yaw_rad is not None else body.orientation_rad[2]
            place = PlaceTask(object=task.object, to=task.to, to_yaw_rad=yaw)
            clear = others_home(world, task.object, alternative, config)
            return [*clear, *place_steps(world, place, alternative, config)]
        if alternative in ONE_HAND:
            return one_hand_steps(world, task, alternative, config)
        if alternative in GRASPED:
            return grasped_steps(world, task, *GRASPED[alternative], config)
        if alternative in HANDOVERS:
            giver, receiver = HANDOVERS_SIDES[alternative]
            return handover_steps.transfer(world, task, giver, receiver, config)
        if alternative in REGRASPS:
            first, second = regrasp_steps.REGRASPS[alternative]
            return regrasp_steps.transfer(world, task, first, second, config)
        if alternative in SIDESTEPS:
            return sidestep_steps.transfer(world, task, sidestep_steps.SIDESTEPS[alternative], config)
        raise PlanningError(
            alternative, None, 0.0, 0.0, 0, reason=f"transfer has no alternative '{alternative}'"
        )

    def verify(self, task: Task, world: World, detector: object) -> Verdict | None:
        assert isinstance(task, TransferTask)
        return placed_verdict(world, detector, task.object, task.to, task.to_yaw_rad)

    def varied_points(self, task: Task) -> tuple[VariedPoint, ...]:
        """The target ``to``, where the task leaves its object."""
        assert isinstance(task, TransferTask)
        return (VariedPoint("to", task.to, places=task.object, yaw_rad=task.to_yaw_rad),)


HANDOVERS_SIDES = {"left_to_right": ("left", "right"), "right_to_left": ("right", "left")}


def _with_grasps(task: Task, world: World, offered: list[Alternative]) -> list[Alternative]:
    """``offered`` and the grasped one-hand alternatives, each hand's grasps pruned before planning.

    A task that asks for no grasp but ``top`` (in ``grasps`` or by an alternative's name) is left as
    it was: ``left`` and ``right`` unpruned.
    """
    assert isinstance(task, TransferTask)
    named = tuple(GRASPED[a][1] for a in task.alternatives if a in GRASPED)  # asked for by name
    grasps = tuple(dict.fromkeys((*task.grasps, *named)))
    if grasps == DEFAULT_GRASPS:
        return offered
    reasons: dict[str, str] = {}
    sigma = world.scenario.uncertainty.object_position
    for side in world.profile.sides:
        candidates = grasp_candidates(
            world,
            side,
            task.object,
            grasps,
            CompositionConfig(),
            table_clearance=PlannerConfig().table_distance,
        )
        for c in rank_grasps(candidates, sigma, PLANNED_PER_HAND, home_approach(world, side)):
            reasons[side if c.grasp == "top" else f"{side}_{c.grasp}"] = c.reason
    out = [Alternative(a.name, a.unsupported or reasons.get(a.name, "")) for a in offered]
    missing = f"robot '{world.profile.name}' has no such arm"
    return out + [Alternative(name, reasons.get(name, missing)) for name in GRASPED]


def grasped_steps(
    world: World, task: TransferTask, side: str, grasp: str, cfg: CompositionConfig
) -> list[Step]:
    """One hand moves the object with ``grasp`` (:func:`executive.tasks.grasp_leg.grasp_leg`).

    Raises:
        GraspGeometryError: the hand cannot make that grasp (the candidate's reason).
    """
    body = next(b for b in world.scenario.scene.objects if b.name == task.object)
    pos, quat = world.object_pose(task.object)
    candidate = grasp_candidates(
        world, side, task.object, (grasp,), cfg, table_clearance=PlannerConfig().table_distance
    )[0]
    if candidate.reason:
        raise GraspGeometryError(f"{side}.approach", side, candidate.reason)
    target = target_placement(world, body, task.to, task.to_yaw_rad, 0.0)
    return grasp_leg(
        HandFrames(world), side, body, (pos, yaw_of(quat)), (target.centre, target.yaw), candidate, cfg
    )


def one_hand_steps(world: World, task: TransferTask, side: str, cfg: CompositionConfig) -> list[Step]:
    """Pick, carry across the body in the lane in front of what is in the way, place, home.

    The carried object skirts the obstacles' front at ``obstacle_clearance`` (the one-arm
    alternatives' risk); see :func:`executive.tasks.phases.one_hand_leg`.
    """
    body = next(b for b in world.scenario.scene.objects if b.name == task.object)
    pos, quat = world.object_pose(task.object)
    target = target_placement(world, body, task.to, task.to_yaw_rad, 0.0)
    return one_hand_leg(HandFrames(world), side, body, (pos, yaw_of(quat)), (target.centre, target.yaw), cfg)


def others_home(world: World, obj: str, holder: str, cfg: CompositionConfig) -> list[Step]:
    """The other hands home first, ``holder`` keeping ``obj`` where it is (they may brush it leaving).

    After a failed handover the receiver's open hand is still at the object.
    """
    h = HandFrames(world)
    pos, quat = world.object_pose(obj)
    grip = world.grips.get(obj)
    site_q = np.zeros(4)
    if grip is not None and grip.looks:  # object = site * grip, so site = object * grip^-1
        inverse = np.zeros(4)
        mujoco.mju_negQuat(inverse, np.asarray(grip.quat, dtype=float))
        mujoco.mju_mulQuat(site_q, quat, inverse)
    else:
        site_q = h.target(holder, pos, yaw_of(quat)).quat
    hold = HandTarget(holder, pos + site_offset(world, obj, cfg), site_q)
    return [
        Step("home", f"{side}.clear", side, (h.home[side], hold), carried=(holder, obj), allow_contact=(obj,))
        for side in world.profile.sides
        if side != holder
    ]


def transfer_steps(
    world: World, task: Task, alternative: str, config: CompositionConfig | None = None
) -> list[Step]:
    """The steps of one alternative of a transfer task, with targets from the estimate world."""
    return TransferKind().steps(task, world, alternative, config or CompositionConfig())
