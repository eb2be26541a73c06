"""Seeded variants of a scenario's scene: the same task on scenes nobody tuned for.

Variant ``k`` is drawn by ``numpy.random.default_rng([seed, k])``: a suite is reproducible and
variant ``k`` does not depend on how many others are drawn. Every draw is uniform in
:class:`VariationRanges` (the defaults, or a scene family's own:
:mod:`executive.validation.variation_ranges`): the table's height, each object's yaw, mass,
friction and extents, and the positions of objects, obstacles and the tasks' varied points
(:meth:`executive.tasks.base.TaskKind.varied_points`). A draw is kept only when it is physically
valid (:func:`scene_problem`: resting, on the table, clear of the other bodies by coal
distances, at the targets too, and it compiles); an invalid one is redrawn, at most
``max_redraws`` times, the reasons returned with the variant. :func:`write_variant` writes it as
the scenario's own YAML with the scene and the varied points replaced (docs/risk_in_physics.md,
"Every scene family").
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
import yaml
from numpy.typing import NDArray

from executive.errors import ExecutiveError, ScenarioError
from executive.risk.shapes import body_geometry
from executive.schema.readers import TOLERANCE, over_table, vertical_half_extent
from executive.schema.types import Body, Scenario, SceneConfig, Table, Task
from executive.tasks.registry import get as task_kind
from executive.tasks.variation import VariedPoint
from executive.validation.variation_ranges import VariationRanges, check_names

__all__ = [
    "Variant",
    "VariationRanges",
    "base_document",
    "make_variant",
    "scene_problem",
    "variant_trial_seed",
    "varied_points",
    "write_variant",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Variant:
    """Variant ``index`` of a scenario: its YAML document, the scenario it loads into, its draws.

    ``redraws``: invalid scenes drawn (and discarded) before this one; ``rejections``
    counts them by reason (``off_table``, ``overlap``, ``target``, ``shape``, ``invalid``, ``world``).
    """

    index: int
    document: dict[str, Any]
    scenario: Scenario
    draws: dict[str, Any]
    redraws: int
    rejections: dict[str, int]


def base_document(scenario: Scenario) -> dict[str, Any]:
    """The scenario's YAML document, its robot made independent of the file's folder.

    Raises:
        ExecutiveError: the scenario was not loaded from a file.
    """
    from executive.schema.yaml_nodes import load_yaml_file

    if scenario.source is None or not Path(scenario.source).is_file():
        raise ExecutiveError(f"scenario {scenario.name} has no YAML file to vary")
    document = copy.deepcopy(load_yaml_file(Path(scenario.source)).value)
    if not isinstance(document, dict):
        raise ExecutiveError(f"{scenario.source}: not a mapping at the top level")
    if not isinstance(document.get("robot"), str):  # a relative MJCF or profile path: make it absolute
        document["robot"] = {"mjcf": str(scenario.robot.mjcf), "profile": str(scenario.robot.profile)}
    return document


def make_variant(
    base: Scenario, document: dict[str, Any], seed: int, index: int, ranges: VariationRanges | None = None
) -> Variant:
    """Draw variant ``index`` of ``base`` (its YAML ``document``, see :func:`base_document`).

    Args:
        base: the scenario as loaded.
        document: its YAML document.
        seed: the suite's seed; with ``index`` it seeds the generator.
        index: the variant's number (0, 1, ...).
        ranges: what to draw from (default :class:`VariationRanges`).

    Returns:
        The first valid draw, with the count of invalid ones before it.

    Raises:
        ExecutiveError: no valid scene in ``ranges.max_redraws`` + 1 draws; a body the ranges
            name is not in the scene (a ScenarioError).
    """
    from executive.scenario import from_dict

    r = ranges or VariationRanges()
    check_names(r, [b.name for b in _bodies(base.scene)], base.name, "the variation ranges")
    rng = np.random.default_rng([seed, index])
    resting = {b.name for b in _bodies(base.scene) if _rests_on_table(b, base.scene.table)}
    # A wall standing on the table's edge rests on it but is not checked to stay inside it.
    inside = {b.name for b in _bodies(base.scene) if _over_table(b, base.scene.table)}
    rejections: dict[str, int] = {}
    from_dict(document, f"{base.name} (the document variants are drawn from)")  # its own errors first
    last = ""
    for attempt in range(r.max_redraws + 1):
        scene, points, draws = _draw(base, rng, r)
        doc = _variant_document(base, document, scene, points, index, seed)
        problem = _shape_problem(base.scene, scene)
        scenario: Scenario | None = None
        if problem is None:
            try:
                scenario = dataclasses.replace(from_dict(doc, f"variant {index}"), source=None)
            except ScenarioError as exc:
                problem = f"invalid: {exc}"
        if scenario is not None and problem is None:
            problem = scene_problem(scenario, resting, r.clearance_m, base.scene, inside) or _world_problem(
                scenario
            )
        if problem is None and scenario is not None:
            return Variant(index, doc, scenario, draws, attempt, rejections)
        last = problem or "invalid"
        key = last.split(":")[0]
        rejections[key] = rejections.get(key, 0) + 1
    raise ExecutiveError(
        f"variant {index} of {base.name}: no valid scene in {r.max_redraws + 1} draws "
        f"(rejected: {', '.join(f'{k} {v}' for k, v in sorted(rejections.items()))}; the last: {last}); "
        "the scene leaves too little room for these ranges"
    )


def _world_problem(scenario: Scenario) -> str | None:
    """``world: ...`` when the scene does not compile into a MuJoCo world."""
    from executive.errors import WorldError
    from executive.world.model import build

    try:
        build(scenario)
    except WorldError as exc:
        return f"world: {exc}"
    return None


def write_variant(variant: Variant, path: Path) -> Scenario:
    """Write the variant's YAML to ``path`` and load it back (as ``executive run`` would)."""
    from executive.scenario import load

    header = (
        f"# Variant {variant.index} of a fidelity suite, drawn by executive/validation/variants.py "
        f"({variant.redraws} invalid draw(s) discarded before it).\n"
        f"# Draws: {yaml.safe_dump(variant.draws, default_flow_style=True, width=10_000).strip()}\n"
    )
    text = header + yaml.safe_dump(variant.document, sort_keys=False, default_flow_style=None, width=100)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return load(path)


# --- drawing ----------------------------------------------------------------------------------


def _bodies(scene: SceneConfig) -> Iterator[Body]:
    yield from scene.objects
    yield from scene.obstacles


def _rests_on_table(body: Body, table: Table) -> bool:
    bottom = body.position[2] - vertical_half_extent(body.shape, body.size, body.orientation_rad)
    return over_table(table, body.position[0], body.position[1]) and abs(bottom - table.height) <= TOLERANCE


def _over_table(body: Body, table: Table) -> bool:
    return all(over_table(table, x, y) for x, y, _ in _outline(body))


def _scaled(body: Body, rng: np.random.Generator, low: float, high: float) -> tuple[float, ...]:
    """Each extent times a factor in [low, high]; a square box's footprint stays square."""
    factors = rng.uniform(low, high, len(body.size))
    if body.shape == "box" and body.yaw_symmetry == 4:
        factors[1] = factors[0]
    return tuple(float(s * f) for s, f in zip(body.size, factors, strict=True))


def _moved(body: Body, dx: float, dy: float, dz: float) -> tuple[float, float, float]:
    """The body shifted by (dx, dy, dz) (a resting body's z is set again by the loader)."""
    x, y, z = body.position
    return (x + dx, y + dy, z + dz)


Points = list[dict[str, tuple[float, float, float | None]]]  # per task: its block's key -> the point


def varied_points(task: Task) -> tuple[VariedPoint, ...]:
    """The points of ``task``'s block a variant moves, as its kind says (:mod:`executive.tasks.variation`)."""
    return task_kind(task.kind).varied_points(task)


def _draw(
    base: Scenario, rng: np.random.Generator, r: VariationRanges
) -> tuple[SceneConfig, Points, dict[str, Any]]:
    """One draw, in a fixed order: table, then each object, each obstacle, each task's points.

    A fixed body draws as any other (so the other draws do not depend on which are fixed) and
    keeps its own values.
    """
    table = base.scene.table
    dz = float(rng.uniform(-r.table_height_m, r.table_height_m))
    draws: dict[str, Any] = {"table_height_change_m": round(dz, 4), "objects": {}, "obstacles": {}}
    shifts: dict[str, tuple[float, float]] = {}
    objects = []
    for body in base.scene.objects:
        dyaw = math.radians(float(rng.uniform(-r.yaw_deg, r.yaw_deg)))
        mass = float(rng.uniform(*r.mass_kg))
        size = _scaled(body, rng, *r.scale)
        friction = float(rng.uniform(*r.friction))
        limit = r.body_shift(body.name, obstacle=False)
        dx, dy = (float(v) for v in rng.uniform(-limit, limit, 2))
        if body.name in r.fixed:
            dyaw, mass, size, friction = 0.0, body.mass or mass, body.size, body.friction
        roll, pitch, yaw = body.orientation_rad
        objects.append(
            dataclasses.replace(
                body,
                size=size,
                mass=mass,
                friction=friction,
                orientation_rad=(roll, pitch, yaw + dyaw),
                position=_moved(body, dx, dy, dz),
            )
        )
        shifts[body.name] = (dx, dy)
        draws["objects"][body.name] = {
            "yaw_change_deg": round(math.degrees(dyaw), 2),
            "mass_kg": round(mass, 3),
            "size": [round(s, 4) for s in size],
            "friction": round(friction, 3),
            "shift_m": [round(dx, 4), round(dy, 4)],
        }
    obstacles = []
    for body in base.scene.obstacles:
        limit = r.body_shift(body.name, obstacle=True)
        dx, dy = (float(v) for v in rng.uniform(-limit, limit, 2))
        obstacles.append(dataclasses.replace(body, position=_moved(body, dx, dy, dz)))
        shifts[body.name] = (dx, dy)
        if limit > 0.0:
            draws["obstacles"][body.name] = {"shift_m": [round(dx, 4), round(dy, 4)]}
    points: Points = []
    for i, task in enumerate(base.mission):
        moved: dict[str, tuple[float, float, float | None]] = {}
        for vp in varied_points(task):
            if vp.follows:
                dx, dy = shifts.get(vp.follows, (0.0, 0.0))
            else:
                dx, dy = (float(v) for v in rng.uniform(-r.target_shift, r.target_shift, 2))
                label = "target" if vp.key == "to" else vp.key
                draws[f"task{i}_{label}_shift_m"] = [round(dx, 4), round(dy, 4)]
            x, y, z = vp.point
            moved[vp.key] = (x + dx, y + dy, None if z is None else z + dz)
        points.append(moved)
    new_table = dataclasses.replace(table, height=table.height + dz)
    return SceneConfig(new_table, tuple(objects), tuple(obstacles)), points, draws


def _shape_problem(base: SceneConfig, scene: SceneConfig) -> str | None:
    """``shape: ...`` when a scaled box's footprint swapped its long and short axis."""
    for old, new in zip(base.objects, scene.objects, strict=True):
        if old.shape == "box" and (old.size[0] >= old.size[1]) != (new.size[0] >= new.size[1]):
            return f"shape: {new.name}'s footprint turned its long axis"
    return None


# --- the YAML document ------------------------------------------------------------------------


def _r(x: float) -> float:
    return round(float(x), 6)


def _body_document(body: Body, resting: bool) -> dict[str, Any]:
    x, y, z = body.position
    out: dict[str, Any] = {
        "name": body.name,
        "shape": body.shape,
        "size": [_r(s) for s in body.size],
        # A body that rested on the table omits z: the loader rests it on the new top.
        "position": [_r(x), _r(y)] if resting else [_r(x), _r(y), _r(z)],
        "orientation": [_r(math.degrees(a)) for a in body.orientation_rad],
    }
    if body.mass is not None:
        out["mass"] = _r(body.mass)
    out["friction"] = _r(body.friction)
    if body.rgba is not None:
        out["rgba"] = [_r(c) for c in body.rgba]
    if body.mass is not None and body.yaw_symmetry != 1:
        out["yaw_symmetry"] = body.yaw_symmetry
    # An obstacle's own loss and clearance (a variant keeps its breach obstacles' limits).
    if body.severity is not None:
        out["severity"] = body.severity
    if body.clearance is not None:
        out["clearance"] = body.clearance
    if body.category != "obstacle":
        out["category"] = body.category
    return out


def _variant_document(
    base: Scenario,
    document: dict[str, Any],
    scene: SceneConfig,
    points: Points,
    index: int,
    seed: int,
) -> dict[str, Any]:
    doc = copy.deepcopy(document)
    doc["name"] = f"{base.name}-variant-{index:02d}"
    doc["description"] = f"Variant {index} (seed {seed}) of {base.name}: {base.description}"
    t = scene.table
    base_table = base.scene.table
    old = {b.name: b for b in _bodies(base.scene)}
    doc["scene"] = {
        "table": {
            "position": [_r(t.position[0]), _r(t.position[1])],
            "size": [_r(s) for s in t.size],
            "height": _r(t.height),
            "yaw": _r(math.degrees(t.yaw_rad)),
        },
        "objects": [_body_document(b, _rests_on_table(old[b.name], base_table)) for b in scene.objects],
        "obstacles": [_body_document(b, _rests_on_table(old[b.name], base_table)) for b in scene.obstacles],
    }
    for item, task, moved in zip(doc["mission"], base.mission, points, strict=True):
        block = item[task.kind] if isinstance(item.get(task.kind), dict) else item  # or a dotted kind's
        for key, (x, y, z) in moved.items():
            block[key] = [_r(x), _r(y)] if z is None else [_r(x), _r(y), _r(z)]
    # The variant is one scene the executive estimates and decides on once (its physics check
    # included); its trials vary the truth only, from truth seeds of its own (a variant that
    # reused the base's would draw the same truth errors as every other variant).
    trials = doc.get("trials")
    trials = trials if isinstance(trials, dict) else {}
    trials.pop("scene_variation", None)
    trials["seed"] = variant_trial_seed(seed, index)
    doc["trials"] = trials
    return doc


def variant_trial_seed(seed: int, index: int) -> int:
    """The ``trials.seed`` of variant ``index`` of a suite seeded ``seed`` (its truths' and rollouts')."""
    return int(np.random.SeedSequence([seed, index, 0x7121A15]).generate_state(1)[0] >> 1)


# --- validity ---------------------------------------------------------------------------------


def _rotation(rpy: tuple[float, float, float]) -> FloatArray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), the scenario's convention (scenario_types)."""
    roll, pitch, yaw = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))  # fmt: skip
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def _outline(body: Body) -> FloatArray:
    """Points of the body's surface whose horizontal hull is its footprint (world frame)."""
    if body.shape == "box":
        half = np.asarray(body.size, dtype=float) / 2.0
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    else:
        radius = float(body.size[0])
        angles = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
        ring = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros_like(angles)], axis=1)
        if body.shape == "sphere":
            local = ring
        else:
            half_length = float(body.size[1]) / 2.0
            axis = np.array([0.0, 0.0, half_length])
            local = np.concatenate([ring - axis, ring + axis])
    return np.asarray(body.position, dtype=float) + local @ _rotation(body.orientation_rad).T


def _distance(a: Body, b: Body) -> float:
    request = coal.DistanceRequest()
    request.enable_signed_distance = True
    ta = coal.Transform3s(_rotation(a.orientation_rad), np.asarray(a.position, dtype=float))
    tb = coal.Transform3s(_rotation(b.orientation_rad), np.asarray(b.position, dtype=float))
    return float(coal.distance(body_geometry(a), ta, body_geometry(b), tb, request, coal.DistanceResult()))


def _at_point(body: Body, point: VariedPoint, table: Table) -> Body:
    """``body`` left at ``point`` (resting on the table when the point has no z)."""
    roll, pitch, yaw = body.orientation_rad
    rpy = (roll, pitch, yaw if point.yaw_rad is None else point.yaw_rad)
    x, y, z = point.point
    at_z = table.height + vertical_half_extent(body.shape, body.size, rpy) if z is None else z
    return dataclasses.replace(body, position=(x, y, at_z), orientation_rad=rpy)


def scene_problem(
    scenario: Scenario,
    resting: set[str],
    clearance: float,
    base: SceneConfig | None = None,
    inside: set[str] | None = None,
) -> str | None:
    """Why ``scenario``'s scene is not physically valid, or None when it is.

    Args:
        scenario: the scene to check.
        resting: names of the bodies that must rest on the table top.
        clearance: least distance (m) between an object (at its start or its target) and
            any other body.
        base: the scene it was drawn from: an obstacle that moved must keep ``clearance`` from
            every body it kept it from there (None: obstacles are not checked).
        inside: names of the resting bodies whose footprint must stay on the table top (None:
            all of ``resting``).

    Returns:
        ``"<reason>: <detail>"`` with reason ``off_table`` (a footprint leaves the table top,
        or a resting body does not rest on it), ``overlap`` (an object near an obstacle or
        another object, a moved obstacle near another body) or ``target`` (the object at a
        task's target, the objects where the tasks before left them, leaves the table or
        meets a body); None for a valid scene.
    """
    table = scenario.scene.table
    for body in _bodies(scenario.scene):
        if body.name in resting:
            if not _rests_on_table(body, table):
                return f"off_table: {body.name} does not rest on the table top"
            if (inside is None or body.name in inside) and not _over_table(body, table):
                return f"off_table: {body.name} reaches over the table's edge"
    objects, others = scenario.scene.objects, list(_bodies(scenario.scene))
    for body in objects:
        for other in others:
            if other.name != body.name and _distance(body, other) < clearance:
                return f"overlap: {body.name} is within {clearance:g} m of {other.name}"
    return _obstacle_problem(scenario.scene, base, clearance) or _target_problem(scenario, clearance)


def _obstacle_problem(scene: SceneConfig, base: SceneConfig | None, clearance: float) -> str | None:
    """``overlap: ...`` when a moved obstacle comes within ``clearance`` of a body it was clear of."""
    if base is None:
        return None
    before = {b.name: b for b in base.obstacles}
    for body in scene.obstacles:
        old = before.get(body.name)
        if old is None or old.position == body.position:
            continue
        for other in scene.obstacles:
            if other.name == body.name or _distance(body, other) >= clearance:
                continue
            if _distance(old, before.get(other.name, other)) >= clearance:
                return f"overlap: {body.name} is within {clearance:g} m of {other.name}"
    return None


def _target_problem(scenario: Scenario, clearance: float) -> str | None:
    """``target: ...`` when an object at a task's target leaves the table or meets a body.

    Each target is checked against the objects where the tasks before it left them: a task
    leaves its object at its point (``places``), a pick takes it into a hand.
    """
    table = scenario.scene.table
    start = {b.name: b for b in scenario.scene.objects}
    now = dict(start)
    for task in scenario.mission:
        for point in varied_points(task):
            if not point.places or point.places not in start:
                continue
            placed = _at_point(start[point.places], point, table)
            if point.point[2] is None and not all(over_table(table, x, y) for x, y, _ in _outline(placed)):
                return f"target: {placed.name} at its target reaches over the table's edge"
            for other in [*scenario.scene.obstacles, *now.values()]:
                if other.name != placed.name and _distance(placed, other) < clearance:
                    return f"target: {placed.name} at its target is within {clearance:g} m of {other.name}"
            now[placed.name] = placed
        if task.object and task_kind(task.kind).leaves_held:
            now.pop(task.object, None)
    return None
