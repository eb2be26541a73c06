"""Scene and task blocks of a scenario: the table, objects, obstacles and transfer tasks.

The keys and their ranges are declared in :mod:`executive.schema.scene_keys`; this reads with them.

Split from :mod:`executive.scenario` to keep each module small; the public entry
points are :func:`executive.scenario.load` and friends. Besides types and ranges,
this checks the scene's geometry: names are unique across objects and obstacles,
and no body penetrates the table top or the floor.
"""

from __future__ import annotations

import math

from executive.schema.declarations import Alternatives, Block, Vector
from executive.schema.scene_keys import (
    OBJECT,
    OBJECT_NAME,
    OBSTACLE,
    ORIENTATION,
    POSITION,
    SCENE,
    SIZE_LENGTHS,
    TABLE,
    TARGET,
    TO_YAW,
)
from executive.schema.types import Body, SceneConfig, Shape, Table
from executive.schema.yaml_nodes import Node

__all__ = [
    "SIZE_LENGTHS",
    "TOLERANCE",
    "over_table",
    "read_alternatives",
    "read_object",
    "read_scene",
    "read_target",
    "vertical_half_extent",
]

#: Penetration allowed (m) before a body counts as inside the table or the floor.
TOLERANCE = 1e-3


def read_scene(node: Node) -> SceneConfig:
    """The ``scene:`` block: ``table``, ``objects`` (non-empty) and ``obstacles`` (optional)."""
    SCENE.check_keys(node)
    table = _table(node.get("table"))
    names: dict[str, str] = {}
    objects = tuple(_body(item, table, names, OBJECT) for item in node.get("objects").items_list(1))
    obstacles_node = node.opt("obstacles")
    obstacles: tuple[Body, ...] = ()
    if obstacles_node is not None:
        obstacles = tuple(_body(item, table, names, OBSTACLE) for item in obstacles_node.items_list())
    return SceneConfig(table=table, objects=objects, obstacles=obstacles)


def _table(node: Node) -> Table:
    TABLE.check_keys(node)
    x, y = TABLE.read_key(node, "position")
    sx, sy, thickness = TABLE.read_key(node, "size")
    height = TABLE.read_key(node, "height")
    yaw = TABLE.read_key(node, "yaw")
    return Table(position=(x, y), size=(sx, sy, thickness), height=height, yaw_rad=yaw or 0.0)


def over_table(table: Table, x: float, y: float) -> bool:
    """Whether the point (x, y) lies over the table's top (its footprint, yaw included)."""
    dx, dy = x - table.position[0], y - table.position[1]
    c, s = math.cos(table.yaw_rad), math.sin(table.yaw_rad)
    u, v = c * dx + s * dy, -s * dx + c * dy
    return abs(u) <= table.size[0] / 2.0 and abs(v) <= table.size[1] / 2.0


def vertical_half_extent(shape: str, size: tuple[float, ...], rpy: tuple[float, float, float]) -> float:
    """Half the vertical extent of a body of ``shape`` and full ``size`` rotated by roll, pitch, yaw."""
    roll, pitch, _ = rpy
    # Third row of R = Rz(yaw) Ry(pitch) Rx(roll): the world-z components of the body axes.
    row = (-math.sin(pitch), math.cos(pitch) * math.sin(roll), math.cos(pitch) * math.cos(roll))
    if shape == "box":
        return sum(abs(r) * s / 2.0 for r, s in zip(row, size, strict=True))
    if shape == "cylinder":
        radius, length = size
        axis_z = abs(row[2])
        return axis_z * length / 2.0 + radius * math.sqrt(max(0.0, 1.0 - axis_z * axis_z))
    return size[0]


def _orientation(node: Node | None) -> tuple[float, float, float]:
    """``orientation``: a yaw or [roll, pitch, yaw] (degrees in the file), in radians."""
    if node is None:
        return (0.0, 0.0, 0.0)
    value = ORIENTATION.read(node)
    if isinstance(value, tuple):
        return (value[0], value[1], value[2])
    return (0.0, 0.0, value)


def _body(node: Node, table: Table, names: dict[str, str], spec: Block) -> Body:
    """An object (``spec`` :data:`OBJECT`) or an obstacle (:data:`OBSTACLE`) of the scene."""
    if spec is OBSTACLE and node.is_mapping() and node.has("mass"):
        node.child("mass", None).fail("obstacles are static and take no mass (objects do)")
    spec.check_keys(node)
    name_node = node.get("name")
    name = spec.keys["name"].read(name_node)
    if name in names:
        name_node.fail(f"duplicate name '{name}' (already used at {names[name]}); names must be unique")
    names[name] = name_node.path
    shape: Shape = _shape(node.get("shape"), spec)
    size_key = spec.keys["size"]
    assert isinstance(size_key, Vector)
    size = size_key.read(node.get("size"), lengths=(SIZE_LENGTHS[shape],))
    rpy = _orientation(node.opt("orientation"))
    position_node = node.get("position")
    position = POSITION.read(position_node)
    half = vertical_half_extent(shape, size, rpy)
    if len(position) == 3:
        x, y, z = position
    else:
        x, y = position
        z = (table.height if over_table(table, x, y) else 0.0) + half
    _check_clear_of_table(position_node, table, (x, y, z), half)
    given: dict[str, object] = {}
    if spec is OBJECT:
        given["mass"] = spec.read_key(node, "mass")
    for key in ("friction", "rgba"):
        value = spec.read_key(node, key)
        if value is not None:
            given[key] = value
    symmetry_node = node.opt("yaw_symmetry") if spec is OBJECT else None
    if symmetry_node is not None:
        given["yaw_symmetry"] = _yaw_symmetry(symmetry_node, shape, size, rpy)
    if spec is OBSTACLE:
        given.update(_obstacle_loss(node))
    return Body(name=name, shape=shape, size=size, position=(x, y, z), orientation_rad=rpy, **given)  # type: ignore[arg-type]


def _obstacle_loss(node: Node) -> dict[str, object]:
    """An obstacle's own ``severity`` (0, 1000], ``clearance`` (0, 1] m and ``category``, those given.

    Both numbers exclude 0: a zero severity or clearance would switch the obstacle's collision
    loss or its clearance check off.
    """
    keys = ("severity", "clearance", "category")
    values = {key: OBSTACLE.read_key(node, key) for key in keys}
    return {key: value for key, value in values.items() if value is not None}


def _yaw_symmetry(node: Node, shape: Shape, size: tuple[float, ...], rpy: tuple[float, float, float]) -> int:
    """``yaw_symmetry``: a rotation by 2*pi/n about the vertical maps the object onto itself."""
    n = int(OBJECT.keys["yaw_symmetry"].read(node))
    if n == 1:
        return n
    if abs(rpy[0]) > 1e-9 or abs(rpy[1]) > 1e-9:
        node.fail(f"yaw_symmetry {n} needs the object upright (roll = pitch = 0)")
    if shape == "box":
        square = abs(size[0] - size[1]) <= 1e-9
        allowed = (2, 4) if square else (2,)
        if n not in allowed:
            node.fail(
                f"a box with a {size[0]:g} x {size[1]:g} m footprint has yaw symmetry "
                f"{' or '.join(str(a) for a in (1, *allowed))}, not {n}"
            )
    return n


def _shape(node: Node, spec: Block) -> Shape:
    shape = spec.keys["shape"].read(node)
    if shape == "box":
        return "box"
    if shape == "cylinder":
        return "cylinder"
    return "sphere"


def _check_clear_of_table(node: Node, table: Table, centre: tuple[float, float, float], half: float) -> None:
    """A body over the table must not reach below its top; no body may reach below the floor."""
    x, y, z = centre
    bottom = z - half
    if over_table(table, x, y) and bottom < table.height - TOLERANCE:
        node.fail(
            f"the body is inside the table: its bottom is at z={bottom:.4g} m, below the table top "
            f"at z={table.height:.4g} m (omit z to rest it on the table)"
        )
    if bottom < -TOLERANCE:
        node.fail(f"the body is below the floor: its bottom is at z={bottom:.4g} m")


def read_target(
    node: Node, scene: SceneConfig
) -> tuple[str, tuple[float, float, float | None], float | None]:
    """``object``, ``to: [x, y(, z)]`` and ``to_yaw`` (deg) of a task that puts an object somewhere.

    Returns:
        The object's name, the target (z None: resting on the table) and the yaw (rad, None: keep it).
    """
    name = read_object(node, scene)
    body = next(b for b in scene.objects if b.name == name)
    to_node = node.get("to")
    to = TARGET.read(to_node)
    if len(to) == 3:
        target: tuple[float, float, float | None] = (to[0], to[1], to[2])
        _check_clear_of_table(
            to_node,
            scene.table,
            (to[0], to[1], to[2]),
            vertical_half_extent(body.shape, body.size, body.orientation_rad),
        )
    else:
        if not over_table(scene.table, to[0], to[1]):
            to_node.fail(
                "[x, y] is not over the table, so the object cannot rest on it there; give [x, y, z]"
            )
        target = (to[0], to[1], None)
    yaw = node.opt("to_yaw")
    return name, target, TO_YAW.read(yaw) if yaw is not None else None


def read_object(node: Node, scene: SceneConfig) -> str:
    """The ``object`` key: the name of one of the scene's objects."""
    object_node = node.get("object")
    name = OBJECT_NAME.read(object_node)
    bodies = {body.name: body for body in scene.objects}
    if name not in bodies:
        valid = ", ".join(bodies)
        hint = " (an obstacle; obstacles are static)" if any(b.name == name for b in scene.obstacles) else ""
        object_node.fail(f"unknown object '{name}'{hint}; the scene's objects are: {valid}")
    return name


def read_alternatives(node: Node, valid: tuple[str, ...]) -> tuple[str, ...]:
    """A list of distinct alternative names, each one of ``valid``."""
    return Alternatives("the alternatives", valid).read(node)
