"""Grasp candidates per object and hand: the ways one hand can close on an object.

A grasp is named for where the hand comes from (:data:`GRASPS`, extended with
:func:`register_grasp`); after MoveIt Task Constructor's grasp generator stage, which samples
approach directions about the object and keeps the hand frames the hand can make:

* ``top``: from above, the jaws across the object's local y (the default, as every grasp was);
* ``top_across``: from above, the jaws across the object's local x;
* ``front``: level, along the robot's forward direction, the jaws closing level across it;
* ``side``: level, from the hand's own side towards the midline, the jaws closing along the
  robot's forward direction;
* ``front_45``, ``front_75``, ``side_45``, ``side_75``: those two dipping 45 or 75 deg below level
  (the jaws still close level), for a hand whose wrist cannot come in level at the table.

Of the two ways to close along an axis, a hand takes the one nearer its home pose's (a grasp from
above the one :class:`executive.tasks.hands.HandFrames` takes, the profile's ``closing_yaw``).

:func:`grasp_candidates` lays each asked grasp out for one hand and object: the hand site's
point and frame (+z the approach, +y the closing axis, as :class:`HandFrame` has it), the
object's width across the jaws and, when the hand cannot make it, why. The hand's measured
geometry decides (:func:`executive.tasks.grasp_geometry.hand_geometry`: jaw opening, finger
depth, the hand's half thickness and the free length to its palm), not constants per robot; a
site farther from the base than the hand's chain reaches is refused too. :func:`rank_grasps`
prunes the feasible candidates of one hand to a bounded number, by the grasp model's chance that
the object's position error puts it outside the jaws, then by the wrist's turn from home.

Usage::

    for c in grasp_candidates(world, "left", "can", ("top", "front"), cfg, table_clearance=0.02):
        print(c.grasp, c.width, c.reason or "feasible")
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import CompositionConfig
from executive.risk.gaussian import exceed_probability
from executive.risk.grasp_tolerance import grasp_tolerance
from executive.risk.model_geometry import half_extent
from executive.robot.model import robot_facts
from executive.schema.types import Body
from executive.tasks.grasp_geometry import HandGeometry, hand_geometry, hand_points
from executive.tasks.hands import HandFrames
from executive.tasks.phases import grasp_height
from executive.world.model import World

__all__ = [
    "DEFAULT_GRASPS",
    "GRASPS",
    "GraspCandidate",
    "GraspKind",
    "grasp_candidates",
    "grasp_frame",
    "home_approach",
    "rank_grasps",
    "register_grasp",
]

FloatArray = NDArray[np.float64]
#: m of floating-point rounding in the geometry.
_ROUNDING = 1e-6
_Y = np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class GraspKind:
    """A way to close one hand on an object.

    Attributes:
        name: the grasp's name (scenario key ``grasps``, alternative names ``<side>_<name>``).
        approach: ``down`` (from above), ``forward`` (along the robot's heading) or ``inward``
            (from the hand's own side towards the midline).
        closing: ``object_y`` or ``object_x`` (across the object's local axis, from above), or
            ``level`` (level and across the approach).
        pitch_deg: how far the approach dips below level (0: level, 90: straight down).
        description: one line for the schema and the docs.
    """

    name: str
    approach: str
    closing: str
    pitch_deg: float
    description: str

    @property
    def level(self) -> bool:
        """Whether the hand comes in from a side (the jaws close level across that side)."""
        return self.approach != "down"

    @property
    def from_above(self) -> bool:
        """Whether the hand comes in steeper than 45 deg: it closes under the top, as a top grasp."""
        return self.pitch_deg >= 45.0


#: Every grasp by name; :func:`register_grasp` adds one.
GRASPS: dict[str, GraspKind] = {}
#: The grasps a task tries unless its scenario asks for others.
DEFAULT_GRASPS = ("top",)


def register_grasp(kind: GraspKind) -> None:
    """Add (or replace) a grasp by its name."""
    GRASPS[kind.name] = kind


register_grasp(GraspKind("top", "down", "object_y", 90.0, "from above, the jaws across the object's width"))
register_grasp(GraspKind("top_across", "down", "object_x", 90.0, "from above, the jaws across its length"))
for _pitch in (0, 45, 75):
    _tail = f"_{_pitch}" if _pitch else ""
    _dip = f", dipping {_pitch} deg" if _pitch else ", level"
    register_grasp(
        GraspKind(
            f"front{_tail}",
            "forward",
            "level",
            float(_pitch),
            f"from the front{_dip}, the jaws closing level",
        )
    )
    register_grasp(
        GraspKind(
            f"side{_tail}", "inward", "level", float(_pitch), f"from the hand's own side{_dip}, jaws fore-aft"
        )
    )


@dataclass(frozen=True)
class GraspCandidate:
    """One grasp of one hand on one object, as laid out on the estimate.

    Attributes:
        grasp: the grasp's name (:data:`GRASPS`).
        side: the hand.
        site: where the hand site closes (world, m).
        approach: the site's +z in the world (unit): the way the hand moves in.
        closing: the site's +y in the world (unit): the axis the jaws close along.
        width: the object's extent along ``closing`` (m).
        opening: the hand's jaw opening (m).
        reason: why the hand cannot make this grasp ("" when it can).
    """

    grasp: str
    side: str
    site: FloatArray
    approach: FloatArray
    closing: FloatArray
    width: float
    opening: float
    reason: str = ""

    @property
    def quat(self) -> FloatArray:
        """The site's orientation (w x y z) for this grasp."""
        return grasp_frame(self.approach, self.closing)

    def miss_probability(self, position_sigma: float) -> float:
        """P(the object's position error along the jaws exceeds their clearance (opening - width) / 2)."""
        clearance = (self.opening - self.width) / 2.0
        return float(exceed_probability(clearance, position_sigma))


def grasp_frame(approach: FloatArray, closing: FloatArray) -> FloatArray:
    """The quaternion (w x y z) of a site frame with +z ``approach`` and +y ``closing`` (x = y cross z)."""
    z = np.asarray(approach, dtype=float) / np.linalg.norm(approach)
    y = np.asarray(closing, dtype=float) - float(np.dot(closing, z)) * z
    y /= np.linalg.norm(y)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([np.cross(y, z), y, z]).ravel())
    return quat


def _cm(length: float) -> str:
    return f"{length * 100:.1f}".rstrip("0").rstrip(".")


def _axes(kind: GraspKind, h: HandFrames, side: str, obj_rot: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The approach and closing axes (world, unit) of ``kind`` for the ``side`` hand."""
    down = np.array([0.0, 0.0, -1.0])
    if kind.approach == "down":
        axis = obj_rot[:, 1] if kind.closing == "object_y" else obj_rot[:, 0]
        approach, closing = down, np.array([axis[0], axis[1], 0.0])
    else:
        forward = np.array([math.cos(h.heading), math.sin(h.heading), 0.0])
        left = np.array([-forward[1], forward[0], 0.0])
        inward = -left if h.side_of_body(h.home[side].position) > 0 else left
        level = forward if kind.approach == "forward" else inward
        pitch = math.radians(kind.pitch_deg)
        approach = math.cos(pitch) * level + math.sin(pitch) * down
        closing = np.cross(np.array([0.0, 0.0, 1.0]), level)
    closing /= np.linalg.norm(closing)
    if float(np.dot(closing, _home_frame(h, side)[:, 1])) < 0.0:  # of the two, the one nearer home's
        closing = -closing
    return approach, closing


def _home_frame(h: HandFrames, side: str) -> FloatArray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, h.home[side].quat)
    return mat.reshape(3, 3)


def _site(
    kind: GraspKind,
    body: Body,
    centre: FloatArray,
    approach: FloatArray,
    along: float,
    hand: HandGeometry,
    cfg: CompositionConfig,
) -> FloatArray:
    """Where the site closes before the table is considered: under the top (from above) or at the
    centre's height (from a side), back from the centre along a level approach where the object
    would otherwise reach the palm."""
    if kind.from_above:
        return np.array([centre[0], centre[1], grasp_height(body, float(centre[2]), cfg)])
    level = np.array([approach[0], approach[1], 0.0]) / max(float(np.hypot(approach[0], approach[1])), 1e-9)
    return centre - max(0.0, along - hand.palm_gap) * level


def _reason(
    c: GraspCandidate,
    kind: GraspKind,
    table_gap: float,
    above_table: float,
    thickness: float,
    cfg: CompositionConfig,
) -> str:
    """Why the hand cannot make the laid-out grasp ``c`` ("" when it can).

    ``table_gap``: how far the hand reaches below its site in this grasp's frame; ``above_table``:
    the site's height above the table as laid out, raised to keep that clear; ``thickness``: the
    object's height above the table.
    """
    if c.width >= c.opening:
        return (
            f"grasp '{c.grasp}': the object is {_cm(c.width)} cm across the jaws, wider than the "
            f"{_cm(c.opening)} cm jaw opening of the {c.side} hand"
        )
    if above_table > thickness - cfg.grip_depth + _ROUNDING:
        return (
            f"grasp '{c.grasp}': the {_cm(thickness)} cm tall object is lower than the "
            f"{_cm(above_table + cfg.grip_depth)} cm the {c.side} hand needs above the table to close "
            f"on it this way (it reaches {_cm(table_gap)} cm below its grasp point)"
        )
    return ""


def grasp_candidates(
    world: World,
    side: str,
    obj: str,
    names: tuple[str, ...],
    cfg: CompositionConfig,
    *,
    table_clearance: float,
) -> list[GraspCandidate]:
    """The grasps ``names`` of the ``side`` hand on ``obj`` as it rests on the estimate's table.

    Args:
        world: the estimate world.
        side: the hand.
        obj: the object's name.
        names: grasp names (:data:`GRASPS`).
        cfg: the composition's geometry (``grip_depth``: how far under the top the site goes).
        table_clearance: how far (m) the planner keeps the hand off the table.

    Returns:
        One :class:`GraspCandidate` per name, in order; its ``reason`` says why the hand cannot
        make it: wider than the jaws, too low for a level grasp above the table, or out of reach.

    Raises:
        ValueError: an unknown grasp name.
    """
    h = HandFrames(world)
    hand, points = hand_geometry(world, side), hand_points(world, side)
    pos, quat = world.object_pose(obj)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, quat)
    obj_rot = rot.reshape(3, 3)
    geom = world.ids.object_geoms[obj]
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    table = world.scenario.scene.table.height
    thickness = float(pos[2]) + half_extent(world.model, geom, obj_rot.T @ np.array([0.0, 0.0, 1.0])) - table
    # The hand's opening, as the grasp model has it: slide jaws' travel, else the measured span.
    opening = 2.0 * grasp_tolerance(world, side, obj).closing + 2.0 * half_extent(world.model, geom, _Y)
    out = []
    for name in names:
        kind = GRASPS.get(name)
        if kind is None:
            raise ValueError(f"unknown grasp '{name}'; grasps: {', '.join(GRASPS)}")
        approach, closing = _axes(kind, h, side, obj_rot)
        frame = np.column_stack([np.cross(closing, approach), closing, approach])
        below = max(0.0, -float(np.min((points @ frame.T)[:, 2])))  # the hand's reach under its site
        width = 2.0 * half_extent(world.model, geom, obj_rot.T @ closing)
        along = half_extent(world.model, geom, obj_rot.T @ approach)
        site = _site(kind, body, np.asarray(pos, dtype=float), approach, along, hand, cfg)
        site[2] = max(float(site[2]), table + table_clearance + below)
        c = GraspCandidate(name, side, site, approach, closing, width, opening)
        reason = _reason(c, kind, below, float(site[2]) - table, thickness, cfg) or _reach_reason(world, h, c)
        out.append(dataclasses.replace(c, reason=reason))
    return out


def _reach_reason(world: World, h: HandFrames, c: GraspCandidate) -> str:
    """Out of reach: the site farther from the base than the whole chain reaches (measured in its MJCF)."""
    facts = robot_facts(world.profile.mjcf, world.profile) if world.profile.mjcf is not None else None
    if facts is None or c.side not in facts.reach:
        return ""
    distance = float(np.linalg.norm(c.site - h.base))
    reach = facts.reach[c.side]
    if distance <= reach:
        return ""
    return (
        f"grasp '{c.grasp}': its grasp point is {distance:.2f} m from the base, beyond the "
        f"{reach:.2f} m the {c.side} hand reaches"
    )


def rank_grasps(
    candidates: list[GraspCandidate], position_sigma: float, limit: int, home_approach: FloatArray
) -> list[GraspCandidate]:
    """The candidates of one hand with a pruning reason on all but the ``limit`` best feasible ones.

    Best: the smallest chance that the object's position error (``position_sigma`` per axis, m)
    exceeds the jaws' clearance along the closing axis (the grasp model's closing tolerance,
    :func:`executive.risk.grasp_tolerance.tolerance_probabilities`), to a tenth of a percent;
    then the least turn of the approach from the hand's at home (``home_approach``, its site's z):
    the wrist's likeliest reach; then the asked order.

    Returns:
        The candidates in their order, the pruned ones with a ``reason`` that says so.
    """
    feasible = [c for c in candidates if not c.reason]

    def score(c: GraspCandidate) -> tuple[float, float]:
        turn = math.acos(float(np.clip(np.dot(c.approach, home_approach), -1.0, 1.0)))
        return round(c.miss_probability(position_sigma), 3), turn

    ranked = sorted(feasible, key=score)
    kept = {id(c) for c in ranked[:limit]}
    out = []
    for c in candidates:
        if c.reason or id(c) in kept:
            out.append(c)
            continue
        p = c.miss_probability(position_sigma)
        reason = (
            f"pruned: the {c.side} hand plans its {limit} likeliest grasps; '{c.grasp}' misses the "
            f"object with P {p:.3f} or turns the wrist further from home"
        )
        out.append(dataclasses.replace(c, reason=reason))
    return out


def home_approach(world: World, side: str) -> FloatArray:
    """The ``side`` hand's approach axis (its site's z, world) at home."""
    return _home_frame(HandFrames(world), side)[:, 2].copy()
