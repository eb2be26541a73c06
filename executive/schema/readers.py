"""Scene and task blocks of a scenario: the table, objects, obstacles and transfer tasks.

Split from :mod:`executive.scenario` to keep each module small; the public entry
points are :func:`executive.scenario.load` and friends. Besides types and ranges,
this checks the scene's geometry: names are unique across objects and obstacles,
and no body penetrates the table top or the floor.
"""

from __future__ import annotations

import math

from executive.schema import ranges as R
from executive.schema.types import OBSTACLE_CATEGORIES, SHAPES, Body, SceneConfig, Shape, Table
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

#: How many size numbers each shape takes: box [x, y, z], cylinder [radius, length], sphere [radius].
SIZE_LENGTHS: dict[str, int] = {"box": 3, "cylinder": 2, "sphere": 1}
#: Penetration allowed (m) before a body counts as inside the table or the floor.
TOLERANCE = 1e-3

_BODY_KEYS = ("name", "shape", "size", "position")
_BODY_OPTIONAL = ("orientation", "friction", "rgba")
_OBJECT_OPTIONAL = (*_BODY_OPTIONAL, "yaw_symmetry")
_OBSTACLE_OPTIONAL = (*_BODY_OPTIONAL, "severity", "clearance", "category")


def read_scene(node: Node) -> SceneConfig:
    """The ``scene:`` block: ``table``, ``objects`` (non-empty) and ``obstacles`` (optional)."""
    node.check_keys(("table", "objects"), ("obstacles",))
    table = _table(node.get("table"))
    names: dict[str, str] = {}
    objects = tuple(_body(item, table, names, is_object=True) for item in node.get("objects").items_list(1))
    obstacles_node = node.opt("obstacles")
    obstacles: tuple[Body, ...] = ()
    if obstacles_node is not None:
        obstacles = tuple(_body(item, table, names, is_object=False) for item in obstacles_node.items_list())
    return SceneConfig(table=table, objects=objects, obstacles=obstacles)


def _table(node: Node) -> Table:
    node.check_keys(("position", "size", "height"), ("yaw",))
    x, y = node.get("position").numbers(2, ge=-R.POSITION_MAX, le=R.POSITION_MAX)
    sx, sy = node.get("size").numbers(3, gt=0.0, le=R.TABLE_SIZE_MAX)[:2]
    thickness = node.get("size").items_list()[2].number(gt=0.0, le=R.TABLE_THICKNESS_MAX)
    yaw = node.opt("yaw")
    return Table(
        position=(x, y),
        size=(sx, sy, thickness),
        height=node.get("height").number(gt=0.0, le=R.TABLE_HEIGHT_MAX),
        yaw_rad=_angle(yaw) if yaw is not None else 0.0,
    )


def _angle(node: Node) -> float:
    """An angle in degrees within +-360, in radians."""
    return math.radians(node.number(ge=-R.ANGLE_MAX_DEG, le=R.ANGLE_MAX_DEG))


def _position(node: Node) -> tuple[float, ...]:
    """[x, y] or [x, y, z] (m): |x|, |y| within POSITION_MAX, z within [0, HEIGHT_MAX]."""
    if not isinstance(node.value, list) or len(node.value) not in (2, 3):
        node.expected("a list of 2 or 3 numbers")
    items = node.items_list()
    values = [item.number(ge=-R.POSITION_MAX, le=R.POSITION_MAX) for item in items[:2]]
    if len(items) == 3:
        values.append(items[2].number(ge=0.0, le=R.HEIGHT_MAX))
    return tuple(values)


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
    if node is None:
        return (0.0, 0.0, 0.0)
    if isinstance(node.value, list):
        roll, pitch, yaw = node.numbers(3, ge=-R.ANGLE_MAX_DEG, le=R.ANGLE_MAX_DEG)
        return (math.radians(roll), math.radians(pitch), math.radians(yaw))
    if isinstance(node.value, bool) or not isinstance(node.value, int | float):
        node.expected("a yaw angle in degrees or a list [roll, pitch, yaw] in degrees")
    return (0.0, 0.0, _angle(node))


def _body(node: Node, table: Table, names: dict[str, str], *, is_object: bool) -> Body:
    if is_object:
        node.check_keys((*_BODY_KEYS, "mass"), _OBJECT_OPTIONAL)
    else:
        if node.is_mapping() and node.has("mass"):
            node.child("mass", None).fail("obstacles are static and take no mass (objects do)")
        node.check_keys(_BODY_KEYS, _OBSTACLE_OPTIONAL)
    name_node = node.get("name")
    name = name_node.string()
    if name in names:
        name_node.fail(f"duplicate name '{name}' (already used at {names[name]}); names must be unique")
    names[name] = name_node.path
    shape: Shape = _shape(node.get("shape"))
    size_max = R.OBJECT_SIZE_MAX if is_object else R.OBSTACLE_SIZE_MAX
    size = node.get("size").numbers(SIZE_LENGTHS[shape], ge=R.BODY_SIZE_MIN, le=size_max)
    rpy = _orientation(node.opt("orientation"))
    position_node = node.get("position")
    position = _position(position_node)
    half = vertical_half_extent(shape, size, rpy)
    if len(position) == 3:
        x, y, z = position
    else:
        x, y = position
        z = (table.height if over_table(table, x, y) else 0.0) + half
    _check_clear_of_table(position_node, table, (x, y, z), half)
    mass = node.get("mass").number(ge=R.MASS_MIN, le=R.MASS_MAX) if is_object else None
    friction = node.opt("friction")
    rgba = node.opt("rgba")
    rgba_values = rgba.numbers(4, ge=0.0, le=1.0) if rgba is not None else None
    symmetry_node = node.opt("yaw_symmetry") if is_object else None
    symmetry = _yaw_symmetry(symmetry_node, shape, size, rpy) if symmetry_node is not None else 1
    severity, clearance, category = (None, None, "obstacle") if is_object else _obstacle_loss(node)
    return Body(
        name=name,
        shape=shape,
        size=size,
        position=(x, y, z),
        orientation_rad=rpy,
        mass=mass,
        friction=friction.number(ge=R.FRICTION_MIN, le=R.FRICTION_MAX) if friction is not None else 1.0,
        rgba=(rgba_values[0], rgba_values[1], rgba_values[2], rgba_values[3]) if rgba_values else None,
        yaw_symmetry=symmetry,
        severity=severity,
        clearance=clearance,
        category=category,
    )


def _obstacle_loss(node: Node) -> tuple[float | None, float | None, str]:
    """An obstacle's own ``severity`` (0, 1000], ``clearance`` (0, 1] m and ``category``.

    Both numbers exclude 0: a zero severity or clearance would switch the obstacle's collision
    loss or its clearance check off.
    """
    severity_node, clearance_node = node.opt("severity"), node.opt("clearance")
    category_node = node.opt("category")
    return (
        severity_node.number(gt=0.0, le=R.SEVERITY_MAX) if severity_node is not None else None,
        clearance_node.number(gt=0.0, le=R.CLEARANCE_MAX) if clearance_node is not None else None,
        category_node.choice(OBSTACLE_CATEGORIES) if category_node is not None else "obstacle",
    )


def _yaw_symmetry(node: Node, shape: Shape, size: tuple[float, ...], rpy: tuple[float, float, float]) -> int:
    """``yaw_symmetry``: a rotation by 2*pi/n about the vertical maps the object onto itself."""
    value = node.value
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        node.expected("a whole number >= 1 (1: the yaw matters; 2: a half turn leaves it unchanged)")
    n = int(value)
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


def _shape(node: Node) -> Shape:
    shape = node.choice(SHAPES)
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
    to = _position(to_node)
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
    return name, target, _angle(yaw) if yaw is not None else None


def read_object(node: Node, scene: SceneConfig) -> str:
    """The ``object`` key: the name of one of the scene's objects."""
    object_node = node.get("object")
    name = object_node.string()
    bodies = {body.name: body for body in scene.objects}
    if name not in bodies:
        valid = ", ".join(bodies)
        hint = " (an obstacle; obstacles are static)" if any(b.name == name for b in scene.obstacles) else ""
        object_node.fail(f"unknown object '{name}'{hint}; the scene's objects are: {valid}")
    return name


def read_alternatives(node: Node, valid: tuple[str, ...]) -> tuple[str, ...]:
    """A list of distinct alternative names, each one of ``valid``."""
    seen: list[str] = []
    for item in node.items_list(min_len=1):
        value = item.choice(valid)
        if value in seen:
            item.fail(f"duplicate alternative '{value}'")
        seen.append(value)
    return tuple(seen)
