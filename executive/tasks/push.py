"""The ``push`` task kind: slide an object along the table to a target with one hand.

YAML: ``push: {object, to: [x, y], alternatives: [left, right]}`` (the target over the table).

Alternatives (names stable): ``left``, ``right``: that hand comes down behind the object (on
the side away from the target), jaws closed, its fingers low on the object's side face,
pushes it in a straight line to the target, backs off, opens and goes home. The push step
carries the force the hand must exert: Coulomb sliding friction ``mu m g`` along the push
(``mu`` as MuJoCo mixes the object's and the table's frictions,
:func:`executive.risk.hold.contact_parameters`); the fall risk feels its reaction
(:func:`executive.risk.fall.assess_fall`). A sphere rolls (it cannot be stopped at a target by
one hand), an object in a hand does not rest on the table, and an object pushed above
``half_width / mu`` tips over instead of sliding: each is refused with the reason.

A push keeps the object's yaw only roughly (a flat finger face on a flat side turns it a
little): :meth:`PushKind.verify` checks its position only.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import PlanningError
from executive.risk.push import CONTACT_GAP, descent_gap
from executive.risk.push_contact import half_extent
from executive.schema.declarations import Block
from executive.schema.scene_keys import OBJECT_NAME, XY
from executive.schema.types import Body, SceneConfig
from executive.schema.yaml_nodes import Node
from executive.tasks.base import Alternative, Task, TaskKind, Verdict, alternatives_key
from executive.tasks.grasp_geometry import hand_geometry
from executive.tasks.hands import UP, HandFrames
from executive.tasks.variation import VariedPoint
from executive.world.model import World

__all__ = [
    "PUSH_LEG",
    "TIP_CLEARANCE",
    "PushKind",
    "PushLine",
    "PushTask",
    "push_force",
    "push_line",
    "push_steps",
]

FloatArray = NDArray[np.float64]
SIDES = ("left", "right")
#: m between the fingertips and the table top while pushing: the planner's 1 cm table distance
#: plus 5 mm for the arm servos' tracking error under the push.
TIP_CLEARANCE = 0.015
#: m, longest leg of the push planned as one motion (see :func:`push_steps`).
PUSH_LEG = 0.03


@dataclass(frozen=True, kw_only=True)
class PushTask(Task):
    """Slide ``object`` over the table until its centre is at ``to`` (x, y; z always None)."""

    kind = "push"
    # x, y in [-10, 10] (m), over the table, clear of obstacles and other objects
    to: tuple[float, float, float | None]
    to_yaw_rad: None = None  # a push does not set the yaw (the scene checks read this)

    def label(self) -> str:
        return f"push {self.object} to ({self.to[0]:.2f}, {self.to[1]:.2f})"


class PushKind(TaskKind):
    """Slide an object to a target on the table with one hand."""

    name = "push"
    alternative_names = SIDES
    keys = Block(
        "Slide an object along the table to a target with one hand",
        {
            "object": OBJECT_NAME,
            "to": dataclasses.replace(XY, description="where the object's centre goes: x, y over the table"),
            "alternatives": alternatives_key(SIDES),
        },
        required=("object", "to"),
        defaults={"alternatives": list(SIDES)},
    )

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``push: {object, to: [x, y], alternatives}``; errors name the key path."""
        from executive.schema.readers import over_table, read_object

        self.keys.check_keys(node)
        name = read_object(node, scene)
        to_node = node.get("to")
        x, y = self.keys.keys["to"].read(to_node)
        if not over_table(scene.table, x, y):
            to_node.fail(
                f"[{x:g}, {y:g}] is not over the table: a push slides the object along the table top"
            )
        return PushTask(object=name, to=(x, y, None), alternatives=self.read_alternatives(node, SIDES))

    def offered(self, task: Task, world: World) -> list[Alternative]:
        body = _body(world, task.object)
        reason = "a sphere rolls: one hand cannot stop it at the target" if body.shape == "sphere" else ""
        holder = world.held_by(task.object)
        if holder is not None:
            reason = f"'{task.object}' is in the {holder} hand: a push slides an object resting on the table"
        sides = world.profile.sides
        return [
            Alternative(s, reason if s in sides else f"robot '{world.profile.name}' has no {s} arm")
            for s in SIDES
        ]

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        assert isinstance(task, PushTask)
        if alternative not in SIDES:
            raise PlanningError(
                alternative, None, 0.0, 0.0, 0, reason=f"push has no alternative '{alternative}'"
            )
        return push_steps(world, task, alternative, config)

    def varied_points(self, task: Task) -> tuple[VariedPoint, ...]:
        """The target ``to`` on the table top, where the push leaves its object (its yaw as it was)."""
        assert isinstance(task, PushTask)
        return (VariedPoint("to", task.to, places=task.object),)

    def verify(self, task: Task, world: World, detector: object) -> Verdict | None:
        """The object rests within the scene's place tolerance of the target (position only:
        a push keeps the yaw only roughly)."""
        assert isinstance(task, PushTask)
        check = getattr(detector, "check_placed", None)
        if check is None:
            return None
        found = check(task.object, (task.to[0], task.to[1]), None, 1)
        if found is None:
            fields = {"object": task.object, "target": list(task.to[:2]), "yaw": "not checked (a push)"}
            return Verdict(True, "placed", fields)
        fields = {"mode": found.mode, "detail": found.detail, "behaviour": "placement", "time": found.time}
        return Verdict(False, "failure", fields, found)


def _body(world: World, name: str) -> Body:
    return next(b for b in world.scenario.scene.objects if b.name == name)


def push_force(world: World, obj: str) -> float:
    """N the hand must exert to slide ``obj`` on the table: Coulomb ``mu m g`` (quasi-static).

    ``mu``: the object's and the table top's sliding friction as MuJoCo mixes them; ``m``: the
    object's mass in ``world``'s model.
    """
    from executive.risk.hold import contact_parameters

    model = world.model
    mu = contact_parameters(model, world.ids.table_geoms[0], world.ids.object_geoms[obj]).mu
    mass = float(model.body_mass[world.ids.object_bodies[obj]])
    return mu * mass * float(np.linalg.norm(model.opt.gravity))


def _hand_face(
    world: World, side: str, site_quat: FloatArray, direction: FloatArray, band: tuple[float, float]
) -> tuple[float, float]:
    """How far the hand reaches from its site towards the object, and the top of that contact.

    Measured on the home keyframe's hand in its site frame (jaw opening does not change it):
    over the hand's collision geoms whose bounding boxes reach into ``band`` (m below the site,
    the object's side face), the largest extent along the push (``direction`` in the world, the
    hand at ``site_quat``), and how far above the site the highest such geom reaches.
    """
    model = world.model
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, world.ids.keyframe)
    mujoco.mj_kinematics(model, data)
    site = world.ids.hand_sites[side]
    origin, frame = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)
    target = np.zeros(9)
    mujoco.mju_quat2Mat(target, site_quat)
    push = target.reshape(3, 3).T @ direction  # the push direction in the site frame
    bodies = set(world.ids.hand_bodies[side])
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
    reach, top = 0.0, -np.inf
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) not in bodies or not (
            model.geom_contype[g] or model.geom_conaffinity[g]
        ):
            continue
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        rot = data.geom_xmat[g].reshape(3, 3)
        local = (data.geom_xpos[g] + (centre + signs * half) @ rot.T - origin) @ frame
        if local[:, 2].max() < band[0] or local[:, 2].min() > band[1]:
            continue
        reach = max(reach, float(np.max(local @ push)))
        top = max(top, float(-local[:, 2].min()))
    return reach, top


def _unpushable(step: str, side: str, reason: str) -> PlanningError:
    return PlanningError(step, side, 0.0, 0.0, 0, reason=reason)


@dataclass(frozen=True)
class PushLine:
    """Where a push's hand goes: its site behind the object at the start and end, yaw, direction."""

    start: FloatArray  # hand site, ``descent_gap`` behind the object's face
    end: FloatArray  # hand site when the object's centre is at the target
    hand_yaw: float  # the jaws close across the push: the fingers' face leads
    direction: FloatArray  # unit, horizontal


def push_line(world: World, task: PushTask, side: str) -> PushLine:
    """The hand's line for pushing ``task``'s object with ``side``, its fingers low on the side face.

    Raises:
        PlanningError: the object is at the target already, rests on something other than the
            table, is too low for the fingertips, or would tip over instead of sliding.
    """
    from executive.schema.readers import vertical_half_extent

    body = _body(world, task.object)
    pos, quat = world.object_pose(task.object)
    table = world.scenario.scene.table.height
    way = np.array([task.to[0] - pos[0], task.to[1] - pos[1], 0.0])
    distance = float(np.linalg.norm(way))
    if distance < 1e-3:
        raise _unpushable(f"{side}.push", side, f"'{task.object}' is at the target already")
    u = way / distance
    half_height = vertical_half_extent(body.shape, body.size, body.orientation_rad)
    bottom, height = float(pos[2]) - half_height, 2.0 * half_height
    if bottom > table + 0.002:
        raise _unpushable(
            f"{side}.push", side, f"'{task.object}' rests {bottom - table:.3f} m above the table top"
        )
    site_height = hand_geometry(world, side).finger_depth + TIP_CLEARANCE  # above the table top
    if height <= TIP_CLEARANCE + 0.005:
        raise _unpushable(
            f"{side}.push",
            side,
            f"'{task.object}' is {height * 100:.1f} cm tall: the fingertips stay "
            f"{TIP_CLEARANCE * 100:.1f} cm above the table and would pass over it",
        )
    hand_yaw = math.atan2(u[1], u[0])
    probe = HandFrames(world).target(side, np.zeros(3), hand_yaw)
    reach, top = _hand_face(world, side, probe.quat, u, (site_height - height, site_height))
    half = half_extent(body, quat, u)
    _check_slides(world, task.object, side, half, (TIP_CLEARANCE, min(height, site_height + top)))
    z = table + site_height
    start = np.array([pos[0], pos[1], z]) - (half + reach + descent_gap(world)) * u
    end = np.array([task.to[0], task.to[1], z]) - (half + reach) * u
    return PushLine(start, end, hand_yaw, u)


def push_steps(world: World, task: PushTask, side: str, cfg: CompositionConfig) -> list[Step]:
    """Above the object's back, down behind it, push to the target in legs, back off, open, home.

    Raises:
        PlanningError: as :func:`push_line`.
    """
    h = HandFrames(world)
    line = push_line(world, task, side)
    start, end, yaw, obj = line.start, line.end, line.hand_yaw, task.object
    force = tuple(float(f) for f in push_force(world, obj) * line.direction)
    # The planner's hand heads straight for its goal from wherever it is, and drifts off a long
    # line towards its posture; short legs keep it on the object's side face.
    legs = max(1, math.ceil(float(np.linalg.norm(end - start)) / PUSH_LEG))
    pushes = [
        Step(
            "push",
            f"{side}.push" if k == legs else f"{side}.push_{k}",
            side,
            (h.target(side, start + (end - start) * k / legs, yaw),),
            carried=(side, obj),
            allow_contact=(obj, "table_top"),
            force=(force[0], force[1], force[2]),
            straight=True,
        )
        for k in range(1, legs + 1)
    ]
    back = end - CONTACT_GAP * line.direction + cfg.approach_height * UP
    return [
        Step("move", f"{side}.pre_push", side, (h.target(side, start + cfg.approach_height * UP, yaw),)),
        Step("push", f"{side}.down", side, (h.target(side, start, yaw),), allow_contact=(obj,)),
        *pushes,
        Step("retreat", f"{side}.retreat", side, (h.target(side, back, yaw),), allow_contact=(obj,)),
        Step("release", f"{side}.open", side, obj=obj),
        Step("home", f"{side}.home", side, (h.home[side],), obj=obj),
    ]


def _check_slides(world: World, obj: str, side: str, half: float, contact: tuple[float, float]) -> None:
    """Refuse a push whose line of action is so high that the object tips before it slides.

    Quasi-static, about the leading bottom edge: ``mu m g z_c > m g half`` tips it, with ``z_c`` the
    middle of the fingers' contact on its side face (``contact``: m above the table).
    """
    from executive.risk.hold import contact_parameters

    mu = contact_parameters(world.model, world.ids.table_geoms[0], world.ids.object_geoms[obj]).mu
    z_c = 0.5 * (contact[0] + contact[1])
    if mu * z_c >= half:
        raise _unpushable(
            f"{side}.push",
            side,
            f"'{obj}' would tip over, not slide: pushed {z_c * 100:.1f} cm up its side with friction "
            f"{mu:.2f}, it tips once mu z > {half * 100:.1f} cm (half its depth along the push)",
        )
