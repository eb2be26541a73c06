"""The ``press`` task kind: push a point on an obstacle (a button, a glovebox panel) with a force for a while.

YAML: ``press: {target, point: [x, y, z], force, duration, tolerance, alternatives: [left, right]}``.
``target`` names an obstacle, ``point`` lies on its surface (within :data:`SURFACE_TOLERANCE`), not
on a face that looks down; ``force`` (N, (0, 100]) is pushed into the surface along its normal for
``duration`` (s, (0, 60]) within ``tolerance`` (N, (0, force]; default 10 % of the force, at least
:data:`MIN_TOLERANCE`).

Alternatives (names stable): ``left``, ``right``, the pressing hand. Each lays out: over the point
along the face's normal (``approach_height`` off), in to :attr:`PressKind.standoff` off the surface,
the press (a step of kind ``press`` whose target is beyond the surface by the depth at which the
arm's position servos push with ``force``, :func:`executive.planning.press_geometry.press_compliance`;
its ``force`` is the force the hand exerts on the panel, its ``hold_s`` the duration), back out
over the point, home. The press's behaviour (:class:`behaviours.press.Press`) measures the contact
force and closes the loop on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import py_trees

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import HandTarget, PlanningError
from executive.planning.press_geometry import hand_lead, press_compliance, press_quat, surface_at
from executive.schema import ranges as R
from executive.schema.declarations import Block, Number, Text, Vector
from executive.schema.types import SceneConfig
from executive.schema.yaml_nodes import Node
from executive.tasks.base import Alternative, Task, TaskKind, Verdict, alternatives_key
from executive.tasks.hands import HandFrames
from executive.tasks.subtree import build_subtree
from executive.tasks.variation import VariedPoint
from executive.world.model import World

if TYPE_CHECKING:
    from executive.planning.plan import AlternativePlan

__all__ = [
    "FORCE_MAX",
    "MIN_TOLERANCE",
    "PRESS_RECORD_KEY",
    "SURFACE_TOLERANCE",
    "PressKind",
    "PressTask",
    "press_steps",
]

#: m: how far ``point`` may be off the target's surface.
SURFACE_TOLERANCE = 0.005
#: N: the largest force a press may ask for; s: its longest duration.
FORCE_MAX = 100.0
DURATION_MAX = 60.0
#: N: the least force tolerance (the failure detectors' contact threshold, 1 N, is the force
#: they tell a touch from solver noise by; half of it is still well above the contact's ripple).
MIN_TOLERANCE = 0.5
#: Blackboard key (namespace ``/executive``) where the press behaviour leaves its measurement.
PRESS_RECORD_KEY = "press_record"
SIDES = ("left", "right")


@dataclass(frozen=True, kw_only=True)
class PressTask(Task):
    """Push ``point`` on obstacle ``target`` with ``force`` (N) along ``-normal`` for ``duration`` (s)."""

    kind = "press"
    object: str = ""  # a press moves no object
    target: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]  # the target's outward unit normal at the point
    force: float  # N, (0, 100]
    duration: float  # s, (0, 60]
    tolerance: float  # N, (0, force]

    def label(self) -> str:
        at = ", ".join(f"{v:.2f}" for v in self.point)
        return f"press {self.target} at ({at}) with {self.force:g} N for {self.duration:g} s"


class PressKind(TaskKind):
    """Press a point on an obstacle with one hand, with a force, for a time."""

    name = "press"
    alternative_names = SIDES
    keys = Block(
        "Press a point on an obstacle (a button, a glovebox panel) with one hand, with a force, for a time",
        {
            "target": Text("the name of the obstacle pressed"),
            "point": Vector(
                "the point pressed, x y z: on the target's surface (within 5 mm), not on a face that "
                "looks down",
                (Number("coordinate", "m", -R.POSITION_MAX, R.POSITION_MAX),),
                (3,),
                ("x", "y", "z"),
                unit="m",
            ),
            "force": Number("pushed into the surface along its normal", "N", 0.0, FORCE_MAX, open_low=True),
            "duration": Number("how long the force is held", "s", 0.0, DURATION_MAX, open_low=True),
            "tolerance": Number(
                f"how far the force may stray while held; at most the force; absent: 10 % of the "
                f"force, at least {MIN_TOLERANCE:g} N",
                "N",
                0.0,
                FORCE_MAX,
                open_low=True,
            ),
            "alternatives": alternatives_key(SIDES),
        },
        required=("target", "point", "force", "duration"),
        defaults={"alternatives": list(SIDES)},
    )
    #: m off the surface where the approach ends: the servo's tracking error on the way in
    #: (the move's 3 cm arrival tolerance is far looser) must not bump the hand into the panel
    #: before the press declares the contact.
    standoff = 0.01

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``press: {target, point: [x, y, z], force, duration, tolerance, alternatives}``.

        Raises:
            ScenarioError: naming the key path: an unknown target (the obstacles listed), a point off
                its surface or on a face that looks down, a force, duration or tolerance out of range.
        """
        keys = self.keys
        keys.check_keys(node)
        target_node = node.get("target")
        name = keys.keys["target"].read(target_node)
        bodies = {b.name: b for b in scene.obstacles}
        if name not in bodies:
            valid = ", ".join(bodies) or "(none)"
            hint = (
                " (an object; a press pushes an obstacle)"
                if any(b.name == name for b in scene.objects)
                else ""
            )
            target_node.fail(f"unknown obstacle '{name}'{hint}; the scene's obstacles are: {valid}")
        point_node = node.get("point")
        point = keys.keys["point"].read(point_node)
        surface = surface_at(bodies[name], np.array(point))
        if abs(surface.distance) > SURFACE_TOLERANCE:
            where = "outside" if surface.distance > 0 else "inside"
            point_node.fail(
                f"the point is {abs(surface.distance) * 1000:.1f} mm {where} the surface of '{name}' "
                f"(tolerance {SURFACE_TOLERANCE * 1000:.0f} mm); a press pushes a point on it"
            )
        if surface.normal[2] < -0.5:
            point_node.fail(f"the point is on the underside of '{name}' (its face looks down there)")
        force = keys.read_key(node, "force")
        duration = keys.read_key(node, "duration")
        tol_node = node.opt("tolerance")
        # at most the force: the declared range's upper end is the largest force
        tolerance = (
            tol_node.number(gt=0.0, le=force) if tol_node is not None else max(0.1 * force, MIN_TOLERANCE)
        )
        return PressTask(
            target=name,
            point=(point[0], point[1], point[2]),
            normal=(float(surface.normal[0]), float(surface.normal[1]), float(surface.normal[2])),
            force=force,
            duration=duration,
            tolerance=tolerance,
            alternatives=self.read_alternatives(node, SIDES),
        )

    def offered(self, task: Task, world: World) -> list[Alternative]:
        sides = world.profile.sides
        return [
            Alternative(s, "" if s in sides else f"robot '{world.profile.name}' has no {s} arm")
            for s in SIDES
        ]

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        assert isinstance(task, PressTask)
        if alternative not in SIDES:
            reason = f"press has no alternative '{alternative}'"
            raise PlanningError(alternative, None, 0.0, 0.0, 0, reason=reason)
        return press_steps(world, task, alternative, config, self.standoff)

    def subtree(self, plan: AlternativePlan, *, guard: bool = False) -> py_trees.behaviour.Behaviour:
        """The steps' behaviours in order; the press step is a :class:`behaviours.press.Press`.

        The hand closes (a fist) as the first motion starts and opens again as it goes home.
        """
        from behaviours.press import Press, SetGripper

        task = plan.task
        assert isinstance(task, PressTask)
        side = plan.steps[0].side

        def press(step: Step) -> py_trees.behaviour.Behaviour:
            return Press(
                step.name,
                plan.trajectories[step.name],
                side=step.side,
                target=task.target,
                standoff=self.standoff,
                force=task.force,
                hold_s=step.hold_s,
                tolerance=task.tolerance,
            )

        built = build_subtree(plan, guard=guard, make={"press": press})
        children = list(built.children)  # one per step: a press has no grasp, so no handover
        built.remove_all_children()
        home = [s.kind for s in plan.steps].index("home")
        children.insert(home, SetGripper(f"{side}.open", side, closed=False))
        children.insert(0, SetGripper(f"{side}.fist", side, closed=True))
        return py_trees.composites.Sequence(name=plan.name, memory=True, children=children)

    def verify(self, task: Task, world: World, detector: object) -> Verdict | None:
        """The press behaviour's measurement: event ``pressed`` with the force held and for how long."""
        assert isinstance(task, PressTask)
        record = _press_record()
        if record is None or record.get("target") != task.target:
            return None
        return Verdict(True, "pressed", record)

    def moved_objects(self, task: Task) -> tuple[str, ...]:
        return ()

    def varied_points(self, task: Task) -> tuple[VariedPoint, ...]:
        """The ``point`` on the target's surface: it moves as the target does."""
        assert isinstance(task, PressTask)
        return (VariedPoint("point", task.point, follows=task.target),)


def _press_record() -> dict[str, Any] | None:
    """The last press's measurement on the blackboard (None before any press)."""
    from behaviours.robot_access import NAMESPACE

    try:
        record = py_trees.blackboard.Blackboard.get(f"{NAMESPACE}/{PRESS_RECORD_KEY}")
    except KeyError:
        return None
    return dict(record) if isinstance(record, dict) else None


def press_steps(
    world: World, task: PressTask, side: str, cfg: CompositionConfig, standoff: float
) -> list[Step]:
    """Over the point, in to ``standoff``, press to the servo depth of ``task.force``, back out, home.

    The hand's site frame points its +z into the face (:func:`press_quat`); the site stops where the
    hand's leading geom (:func:`hand_lead`) touches the point. The press target is beyond that by the
    hand's compliance along the push (at the home configuration) times the force.
    """
    h = HandFrames(world)
    normal = np.asarray(task.normal, dtype=float)
    into = -normal
    closing_yaw = h.closing_near_home(side, h.heading)
    quat = press_quat(np.array([math.cos(closing_yaw), math.sin(closing_yaw), 0.0]), normal)
    contact = np.asarray(task.point, dtype=float) + hand_lead(world, side) * normal
    depth = task.force * press_compliance(world, side, world.home_qpos(), into)

    def at(point: np.ndarray) -> tuple[HandTarget, ...]:
        return (HandTarget(side, point, quat),)

    above = contact + cfg.approach_height * normal
    touch = (task.target,)
    return [
        Step("move", f"{side}.pre_press", side, at(above)),
        Step("move", f"{side}.approach", side, at(contact + standoff * normal), allow_contact=touch),
        Step(
            "press",
            f"{side}.press",
            side,
            at(contact + depth * into),
            allow_contact=touch,
            obj=task.target,
            force=(float(task.force * into[0]), float(task.force * into[1]), float(task.force * into[2])),
            hold_s=task.duration,
        ),
        Step("retreat", f"{side}.release", side, at(above), allow_contact=touch),
        Step("home", f"{side}.home", side, (h.home[side],)),
    ]
