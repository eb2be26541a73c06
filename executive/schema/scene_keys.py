"""The keys of a scenario's ``scene:`` block (the table, objects, obstacles) and of a task's target.

Declared once (:mod:`executive.schema.declarations`): :mod:`executive.schema.readers` reads the
scene with them and the JSON Schema (``executive schema``) describes it from them. The limits are
the constants of :mod:`executive.schema.ranges`. Units: metres, kilograms, degrees; sizes are
full edge lengths; the robot's base stands at the origin facing +x, +y to its left.
"""

from __future__ import annotations

from executive.schema import ranges as R
from executive.schema.declarations import Block, Choice, Either, Integer, Key, ListOf, Number, Text, Vector
from executive.schema.types import OBSTACLE_CATEGORIES, SHAPES, Body, Table

__all__ = [
    "BODY_NAME",
    "OBJECT",
    "OBJECT_NAME",
    "OBSTACLE",
    "ORIENTATION",
    "POSITION",
    "SCENE",
    "SIZE_LENGTHS",
    "TABLE",
    "TARGET",
    "TO_YAW",
    "XY",
]

#: How many size numbers each shape takes: box [x, y, z], cylinder [radius, length], sphere [radius].
SIZE_LENGTHS: dict[str, int] = {"box": 3, "cylinder": 2, "sphere": 1}

_COORD = Number("horizontal coordinate", "m", -R.POSITION_MAX, R.POSITION_MAX)
_HEIGHT = Number("height of the centre above the floor", "m", 0.0, R.HEIGHT_MAX)
_DEGREES = Number("angle", "deg", -R.ANGLE_MAX_DEG, R.ANGLE_MAX_DEG, to_radians=True)

#: A point on the floor plan: [x, y] (m).
XY = Vector("x, y in the world frame", (_COORD, _COORD), (2,), ("x", "y"), unit="m")
#: A body's centre or a target: [x, y] resting on what is below, or [x, y, z].
POSITION = Vector(
    "centre x, y (and z) in the world frame; without z the body rests on the table top where it is "
    "over the table, else on the floor",
    (_COORD, _COORD, _HEIGHT),
    (2, 3),
    ("x", "y", "z"),
    unit="m",
)
ORIENTATION = Either(
    "yaw in degrees, or [roll, pitch, yaw] in degrees (applied z-y-x)",
    _DEGREES,
    Vector("roll, pitch, yaw", (_DEGREES,), (3,), ("roll", "pitch", "yaw"), unit="deg"),
    "a yaw angle in degrees or a list [roll, pitch, yaw] in degrees",
    unit="deg",
)
TO_YAW = Number(
    "the object's yaw at the target; absent: it keeps its yaw",
    "deg",
    -R.ANGLE_MAX_DEG,
    R.ANGLE_MAX_DEG,
    to_radians=True,
)
#: A task's target position: over the table, clear of obstacles and other objects, within reach.
TARGET = Vector(
    "where the object's centre goes: [x, y] resting on the table top, or [x, y, z] resting on the "
    "table or on something on it; clear of obstacles and other objects, within the robot's reach",
    (_COORD, _COORD, _HEIGHT),
    (2, 3),
    ("x", "y", "z"),
    unit="m",
)

TABLE = Block(
    "A rectangular table; the objects rest on its top",
    {
        "position": Vector(
            "centre of the top, x y; within the robot's reach", (_COORD, _COORD), (2,), ("x", "y"), "m"
        ),
        "size": Vector(
            "depth (x), width (y) and top thickness",
            (
                Number("depth", "m", 0.0, R.TABLE_SIZE_MAX, open_low=True),
                Number("width", "m", 0.0, R.TABLE_SIZE_MAX, open_low=True),
                Number("top thickness", "m", 0.0, R.TABLE_THICKNESS_MAX, open_low=True),
            ),
            (3,),
            ("depth", "width", "thickness"),
            "m",
        ),
        "height": Number("top surface above the floor", "m", 0.0, R.TABLE_HEIGHT_MAX, open_low=True),
        "yaw": Number(
            "rotation of the table about the vertical",
            "deg",
            -R.ANGLE_MAX_DEG,
            R.ANGLE_MAX_DEG,
            to_radians=True,
        ),
    },
    required=("position", "size", "height"),
    factory=Table,
    fields={"yaw": "yaw_rad"},
)

BODY_NAME = Text("the body's name, unique among the objects and obstacles")
#: A task's ``object``: one of the scene's objects, by name.
OBJECT_NAME = Text("the name of one of the scene's objects (not an obstacle)")
_SIZE = Vector(
    "full extents: a box [x, y, z], a cylinder [radius, length], a sphere [radius]",
    (Number("extent", "m", R.BODY_SIZE_MIN, R.OBJECT_SIZE_MAX),),
    (1, 2, 3),
    unit="m",
)


def _size(high: float) -> Vector:
    return Vector(
        "full extents: a box [x, y, z], a cylinder [radius, length], a sphere [radius]",
        (Number("extent", "m", R.BODY_SIZE_MIN, high),),
        (1, 2, 3),
        unit="m",
    )


def _body_keys(size_max: float) -> dict[str, Key]:
    return {
        "name": BODY_NAME,
        "shape": Choice("the body's shape", SHAPES),
        "size": _size(size_max),
        "position": POSITION,
        "orientation": ORIENTATION,
    }


_FRICTION = Number("sliding friction coefficient", "", R.FRICTION_MIN, R.FRICTION_MAX)
_RGBA = Vector(
    "colour: red, green, blue, opacity", (Number("channel", "", 0.0, 1.0),), (4,), ("r", "g", "b", "a")
)
#: The body's size length follows its shape (a box 3 numbers, a cylinder 2, a sphere 1).
_SIZE_BY_SHAPE = tuple(
    {
        "if": {"properties": {"shape": {"const": shape}}, "required": ["shape"]},
        "then": {"properties": {"size": {"minItems": n, "maxItems": n}}},
    }
    for shape, n in SIZE_LENGTHS.items()
)
_BODY_FIELDS = {"orientation": "orientation_rad"}

OBJECT = Block(
    "An object the robot may manipulate",
    {
        **_body_keys(R.OBJECT_SIZE_MAX),
        "mass": Number("mass", "kg", R.MASS_MIN, R.MASS_MAX),
        "friction": _FRICTION,
        "rgba": _RGBA,
        "yaw_symmetry": Integer(
            "order of the object's rotational symmetry about the vertical: 1, its yaw matters (a "
            "labelled container, a book whose spine must face one way); 2, a half turn leaves it "
            "where it was (a plain box), which a handover needs (it turns the object a half turn); "
            "yaw errors count modulo 360 / yaw_symmetry degrees",
            low=1,
            expected="a whole number >= 1 (1: the yaw matters; 2: a half turn leaves it unchanged)",
        ),
    },
    required=("name", "shape", "size", "position", "mass"),
    factory=Body,
    fields=_BODY_FIELDS,
    defaults={"orientation": 0},
    conditions=_SIZE_BY_SHAPE,
)

OBSTACLE = Block(
    "A static obstacle; it may stand on the floor beside the table",
    {
        **_body_keys(R.OBSTACLE_SIZE_MAX),
        "friction": _FRICTION,
        "rgba": _RGBA,
        "severity": Number(
            "the loss of touching this obstacle; absent: risk.severity.collision",
            "",
            0.0,
            R.SEVERITY_MAX,
            open_low=True,
        ),
        "clearance": Number(
            "the planner keeps this much from the obstacle and the collision risk uses it as the "
            "obstacle's d_safety; absent: the planner's 0.02 m and risk.d_safety",
            "m",
            0.0,
            R.CLEARANCE_MAX,
            open_low=True,
        ),
        "category": Choice(
            "breach: touching it breaches containment (a glovebox's window, a port rim); the risk "
            "report gives the probability and expected loss of touching any breach obstacle separately",
            OBSTACLE_CATEGORIES,
        ),
    },
    required=("name", "shape", "size", "position"),
    factory=Body,
    fields=_BODY_FIELDS,
    defaults={"orientation": 0},
    conditions=_SIZE_BY_SHAPE,
)


SCENE = Block(
    "The scene: a table, the objects on it and the obstacles",
    {
        "table": TABLE,
        "objects": ListOf("the objects the robot may manipulate", OBJECT, min_len=1),
        "obstacles": ListOf("the static obstacles", OBSTACLE),
    },
    required=("table", "objects"),
)
