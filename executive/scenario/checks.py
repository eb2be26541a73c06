"""Is a scenario's scene physically possible? Geometric checks run while a scenario is loaded.

:func:`check_scene` rejects, with the key path of the body or target at fault:

* an object overlapping (or inside) an obstacle or another object (exact signed distances with coal);
* an object off the table (its centre not over the table top and resting on the floor);
* an object floating: its bottom not resting on the table top, an obstacle or another object;
* a transfer target off the table, floating, or where the object would overlap an obstacle or
  another object;
* the table, a task's object or its target far outside the robot's reach (the reach measured in
  the robot's MJCF, :mod:`executive.robot.model`; ``REACH_SLACK`` beyond it);
* a task between a pick and the place of the object it picked (not supported: the physics
  checks and the detectors follow one object in hand, that task's own): a second pick of it
  (a pick needs its object on the table), a transfer, push or press (they need the hands free);
* a place of an object not in hand (nothing picked it, or an earlier place put it down).
  What a task leaves in hand or needs there is its kind's ``leaves_held`` / ``needs_held``
  (:class:`executive.tasks.base.TaskKind`).

Types and ranges are the readers' job (:mod:`executive.schema.readers`); this module assumes
they passed. It is called at the end of :func:`executive.scenario.load` and friends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NoReturn

import coal
import numpy as np

from executive.risk.shapes import body_geometry
from executive.robot.model import RobotFacts
from executive.schema.readers import over_table, vertical_half_extent
from executive.schema.types import Body, Scenario, Table
from executive.schema.yaml_nodes import Node
from executive.tasks.registry import get as task_kind

__all__ = ["OVERLAP_TOLERANCE", "REACH_SLACK", "REST_TOLERANCE", "check_scene"]

#: Penetration (m) two bodies may have before they count as overlapping (contact is fine).
OVERLAP_TOLERANCE = 1e-3
#: Gap (m) between a body's bottom and what it rests on before it counts as floating.
REST_TOLERANCE = 5e-3
#: How far (m) beyond the measured reach a point may be before it counts as far outside it
#: (the legs may shift and lower the pelvis a little).
REACH_SLACK = 0.10


@dataclass(frozen=True)
class _Placed:
    """A body shape at a pose, with the key path to blame."""

    name: str
    path: str
    body: Body
    centre: tuple[float, float, float]
    rpy: tuple[float, float, float]


def check_scene(root: Node, scenario: Scenario, facts: RobotFacts | None) -> None:
    """Fail at the offending key path of ``root``'s document if the scene is impossible."""
    scene = scenario.scene
    objects = [
        _placed(f"scene.objects[{i}]", b, b.position, b.orientation_rad) for i, b in enumerate(scene.objects)
    ]
    obstacles = [
        _placed(f"scene.obstacles[{i}]", b, b.position, b.orientation_rad)
        for i, b in enumerate(scene.obstacles)
    ]
    if facts is not None:
        _check_reach(root, scenario, facts)
    for i, item in enumerate(objects):
        _check_clear(root, f"{item.path}.position", item, [*obstacles, *objects[:i]], "the object")
        _check_resting(root, f"{item.path}.position", item, scene.table, [*obstacles, *objects], "the object")
    _check_in_hand(root, scenario)
    # Each target is checked against the objects where the tasks before it left them: a task
    # with a target leaves its object there, a pick takes it off the table into a hand.
    now = list(objects)
    for t, task in enumerate(scenario.mission):
        if not task.object:
            continue
        if getattr(task, "to", None) is not None:
            placed = _check_target(root, _task_path(root, t, task.kind), task, scenario, now, obstacles)
            now = [*(o for o in now if o.name != task.object), placed]
        elif task_kind(task.kind).leaves_held:
            now = [o for o in now if o.name != task.object]


def _check_in_hand(root: Node, scenario: Scenario) -> None:
    """Fail at a task the objects in hand do not allow, following what each task leaves held.

    A pick is a task whose kind ``leaves_held`` its object, a place one whose kind ``needs_held``
    it. A place needs its object in hand (picked earlier, not yet placed); while an object is
    held only its place may come next (a pick needs its object on the table, and every other
    task the hands free).
    """
    picked: tuple[str, str] | None = None  # (key path of the pick, object) in hand
    placed: dict[str, str] = {}  # object -> key path of the place that last put it down
    for t, task in enumerate(scenario.mission):
        kind = task_kind(task.kind)
        path = _task_path(root, t, task.kind)
        if picked is not None and not (kind.needs_held and task.object == picked[1]):
            again = kind.leaves_held and task.object == picked[1]
            why = (
                "a pick needs its object on the table"
                if again
                else "a task while an object is held is not supported"
            )
            held = f"'{picked[1]}' is still in hand (picked by {picked[0]})"
            _fail(root, path, f"{held}: only its place may come next; {why}")
        if kind.needs_held and picked is None:
            since = (
                f"it was put down by {placed[task.object]}" if task.object in placed else "nothing picked it"
            )
            _fail(
                root,
                path,
                f"'{task.object}' is not in hand ({since}): a {task.kind} needs its object held; "
                f"pick it in the task before",
            )
        if kind.needs_held:
            placed[task.object] = path
        picked = (path, task.object) if kind.leaves_held else None


def _task_path(root: Node, t: int, kind: str) -> str:
    """The key path of task ``t``'s block: ``mission[t].kind``, or ``mission[t]`` for a dotted kind."""
    mission = root.value.get("mission") if isinstance(root.value, dict) else None
    item = mission[t] if isinstance(mission, list) and t < len(mission) else None
    return f"mission[{t}]" if isinstance(item, dict) and "kind" in item else f"mission[{t}].{kind}"


def _placed(
    path: str, body: Body, centre: tuple[float, float, float], rpy: tuple[float, float, float]
) -> _Placed:
    return _Placed(body.name, path, body, centre, rpy)


def _fail(root: Node, path: str, problem: str) -> NoReturn:
    Node(None, root.source, path, root.error).fail(problem)


# --- overlap


def _rotation(rpy: tuple[float, float, float]) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), the scenario's convention."""
    roll, pitch, yaw = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def _distance(a: _Placed, b: _Placed) -> float:
    """Signed distance (m) between two placed bodies; negative when they overlap."""
    ta = coal.Transform3s(_rotation(a.rpy), np.asarray(a.centre, dtype=float))
    tb = coal.Transform3s(_rotation(b.rpy), np.asarray(b.centre, dtype=float))
    return float(
        coal.distance(
            body_geometry(a.body),
            ta,
            body_geometry(b.body),
            tb,
            coal.DistanceRequest(),
            coal.DistanceResult(),
        )
    )


def _check_clear(root: Node, path: str, item: _Placed, others: list[_Placed], what: str) -> None:
    for other in others:
        if other.name == item.name:
            continue
        d = _distance(item, other)
        if d < -OVERLAP_TOLERANCE:
            kind = "obstacle" if other.path.startswith("scene.obstacles") else "object"
            _fail(
                root,
                path,
                f"{what} '{item.name}' at ({_xyz(item.centre)}) overlaps the {kind} '{other.name}' "
                f"({other.path}) "
                f"by {-d * 1000:.0f} mm (or lies inside it); move it clear",
            )


# --- resting


def _footprint_contains(item: _Placed, x: float, y: float) -> bool:
    """Whether (x, y) lies within the horizontal bounding box of a placed body (a generous test)."""
    cx, cy, _ = item.centre
    if item.body.shape == "box":
        half = 0.5 * math.hypot(item.body.size[0], item.body.size[1])
    else:
        half = item.body.size[0] if item.body.shape != "cylinder" else max(item.body.size)
    return abs(x - cx) <= half and abs(y - cy) <= half


def _supports(item: _Placed, table: Table, others: list[_Placed]) -> list[tuple[float, str]]:
    """Heights of the tops that could hold ``item`` up, with what they are."""
    x, y, _ = item.centre
    tops = [(table.height, "the table top")] if over_table(table, x, y) else []
    for other in others:
        if other.name != item.name and _footprint_contains(other, x, y):
            top = other.centre[2] + vertical_half_extent(other.body.shape, other.body.size, other.rpy)
            tops.append((top, f"'{other.name}'"))
    return tops


def _check_resting(
    root: Node, path: str, item: _Placed, table: Table, others: list[_Placed], what: str
) -> None:
    x, y, z = item.centre
    bottom = z - vertical_half_extent(item.body.shape, item.body.size, item.rpy)
    tops = _supports(item, table, others)
    if any(abs(bottom - top) <= REST_TOLERANCE for top, _ in tops):
        return
    if not over_table(table, x, y) and not tops:
        where = (
            "on the floor" if abs(bottom) <= REST_TOLERANCE else f"its bottom {bottom:.3f} m above the floor"
        )
        _fail(
            root,
            path,
            f"{what} '{item.name}' at ({_xyz(item.centre)}) is off the table ({where}): (x, y) is not over "
            f"the table top (centre {table.position[0]:g}, {table.position[1]:g}, size {table.size[0]:g} x "
            f"{table.size[1]:g} m); put it on the table",
        )
    below = [top for top, _ in tops if top <= bottom + REST_TOLERANCE]
    support = max(below, default=0.0)
    on = next((name for top, name in tops if top == support), "the floor")
    _fail(
        root,
        path,
        f"{what} '{item.name}' floats in the air: its bottom is at z={bottom:.3f} m, "
        f"{bottom - support:.3f} m above "
        f"{on} (z={support:.3f} m); give z so that it rests on something, or omit z to rest it on the table",
    )


# --- targets


def _check_target(
    root: Node,
    path: str,
    task: Any,  # a task with object, to and to_yaw_rad
    scenario: Scenario,
    objects: list[_Placed],
    obstacles: list[_Placed],
) -> _Placed:
    """The object at ``task``'s target, checked clear of ``objects`` (as they are then) and obstacles."""
    body = next(b for b in scenario.scene.objects if b.name == task.object)
    rpy = body.orientation_rad
    if task.to_yaw_rad is not None:
        rpy = (rpy[0], rpy[1], task.to_yaw_rad)
    half = vertical_half_extent(body.shape, body.size, rpy)
    x, y, z = task.to
    z_at = z if z is not None else scenario.scene.table.height + half
    target = _placed(path, body, (x, y, z_at), rpy)
    others = [*obstacles, *(o for o in objects if o.name != task.object)]
    _check_clear(root, f"{path}.to", target, others, "the target of")
    if z is not None:
        _check_resting(root, f"{path}.to", target, scenario.scene.table, others, "the target of")
    return target


# --- reach


def _stances(scenario: Scenario, facts: RobotFacts) -> list[np.ndarray]:
    """Where the robot's base stands for each task: the start, then after every task whose kind
    ``moves_base`` (a ``step``) the stance it walks to."""
    base = np.asarray(facts.base, dtype=float)
    out = []
    for task in scenario.mission:
        out.append(base)
        stance = getattr(task, "stance", None)
        if task_kind(task.kind).moves_base and stance is not None:
            base = np.array([stance[0], stance[1], base[2]])
    return out


def _check_reach(root: Node, scenario: Scenario, facts: RobotFacts) -> None:
    stances = _stances(scenario, facts)
    limit = facts.max_reach + REACH_SLACK
    table = scenario.scene.table
    reached = [
        (float(np.linalg.norm(_nearest_on_table(table, b) - b)), b)
        for b in stances or [np.asarray(facts.base)]
    ]
    d, base = min(reached, key=lambda r: r[0])
    nearest = _nearest_on_table(table, base)
    if d > limit:
        _fail(
            root,
            "scene.table.position",
            f"the table is far outside the robot's reach: its top's nearest point "
            f"({_xyz(tuple(nearest))}) is "
            f"{d:.2f} m from the robot's base, and {facts.describe()}",
        )
    objects = {b.name: (i, b) for i, b in enumerate(scenario.scene.objects)}
    for t, task in enumerate(scenario.mission):
        to = getattr(task, "to", None)
        if not task.object or to is None:
            continue
        base = stances[t]
        i, body = objects[task.object]
        radius = 0.5 * math.sqrt(sum(s * s for s in body.size)) if body.shape == "box" else max(body.size)
        z = to[2] if to[2] is not None else table.height + body.half_height()
        for path, point in (
            (f"scene.objects[{i}].position", body.position),
            (f"{_task_path(root, t, task.kind)}.to", (to[0], to[1], z)),
        ):
            d = float(np.linalg.norm(np.asarray(point) - base)) - radius
            if d > limit:
                where = (
                    "the robot's base"
                    if t == 0 or np.array_equal(base, stances[0])
                    else "where the robot stands then"
                )
                _fail(
                    root,
                    path,
                    f"'{task.object}' at ({_xyz(point)}) is far outside the robot's reach: "
                    f"its nearest side is "
                    f"{d:.2f} m from {where}, and {facts.describe()}",
                )


def _nearest_on_table(table: Table, point: np.ndarray) -> np.ndarray:
    """The point of the table's top rectangle nearest to ``point``."""
    c, s = math.cos(table.yaw_rad), math.sin(table.yaw_rad)
    dx, dy = point[0] - table.position[0], point[1] - table.position[1]
    u = max(-table.size[0] / 2, min(table.size[0] / 2, c * dx + s * dy))
    v = max(-table.size[1] / 2, min(table.size[1] / 2, -s * dx + c * dy))
    return np.array([table.position[0] + c * u - s * v, table.position[1] + s * u + c * v, table.height])


def _xyz(point: tuple[float, ...]) -> str:
    return ", ".join(f"{v:.3g}" for v in point)
