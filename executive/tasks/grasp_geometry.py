"""Grasp geometry as named reasons: does an object fit the hand, and can the fingers reach round it?

Checked before planning (:func:`executive.tasks.steps.plan_alternative`), so that a grasp the
hand cannot make is refused with what is wrong ("the 14 cm 'box' is wider than the 12 cm
jaw opening of the left hand") instead of an IK residual ("12 mm short").

* Width: the object's extent across the jaws (its local y, the axis a top-down grasp closes
  along) against the jaw opening. Both come from
  :func:`executive.risk.grasp.grasp_tolerance` (the opening from the gripper's open and
  closed positions); for a hand whose actuators do not drive slide jaws the opening is
  measured on the model instead (:func:`hand_geometry`).
* Thickness: a top-down grasp puts the hand site ``grip_depth`` under the object's top (never
  below its centre), and the hand reaches ``finger_depth`` further down; the fingertips must
  keep the planner's table clearance above the table top.

Usage::

    geometry = hand_geometry(world, "left")
    check_grasp(world, "left", "book", site_above_table=0.04, table_clearance=0.01, motion="left.approach")
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from executive.planning.types import PlanningError
from executive.risk.grasp import grasp_tolerance
from executive.risk.hand_span import FAN_HALF_WIDTH, hand_collision_geoms, hand_span, posed_hand, ray_to_hand
from executive.risk.model_geometry import geom_corners
from executive.world.model import World

__all__ = [
    "GraspGeometryError",
    "HandGeometry",
    "check_grasp",
    "hand_geometry",
    "hand_profile",
    "min_thickness",
]


#: m of floating-point rounding in the geometry (box corners and targets from rotations).
_ROUNDING = 1e-6


class GraspGeometryError(PlanningError):
    """An object the hand cannot grasp: too wide for its jaws, or too thin for its fingers above the table."""

    def __init__(self, motion: str, side: str, reason: str) -> None:
        super().__init__(motion, side, 0.0, 0.0, 0, reason)


@dataclass(frozen=True)
class HandGeometry:
    """A hand's open geometry around its grasp site (m).

    Attributes:
        jaw_opening: free span between the open jaws along the site's closing axis (y),
            through the site; inf when nothing of the hand closes across the site.
        finger_depth: how far the hand reaches past its site along the approach (site z).
        half_thickness: how far the hand reaches from its site either way across the approach
            and the closing axis (site x, the larger side): below the site in a grasp from the side.
        palm_gap: free length from the site back along the approach to the palm (the deepest an
            object may reach into the hand past the site).
    """

    jaw_opening: float
    finger_depth: float
    half_thickness: float = 0.0
    palm_gap: float = float("inf")


def hand_geometry(world: World, side: str) -> HandGeometry:
    """Measure the ``side`` hand on the world's model.

    The jaw opening is the free span through the site along its closing axis, open (the home
    keyframe); the finger depth the hand's reach past the site along its approach axis, open
    or closed, whichever is deeper: fingers that curl as they close (the Dex3's) reach lower
    closed than open (:func:`executive.risk.hand_span.hand_span`).

    Args:
        world: the world whose robot has the hand.
        side: the arm ("left" or "right").

    Returns:
        The hand's :class:`HandGeometry`.
    """
    span, closed = hand_span(world, side), hand_span(world, side, closed=True)
    thickness, palm = hand_profile(world, side)
    return HandGeometry(
        jaw_opening=span.opening,
        finger_depth=max(span.finger_depth, closed.finger_depth),
        half_thickness=thickness,
        palm_gap=palm,
    )


def hand_profile(world: World, side: str) -> tuple[float, float]:
    """The open ``side`` hand's half thickness along its site's x and its palm gap (m).

    Measured on the model at the home keyframe: the hand's collision geoms' bounding-box corners
    in the site frame give the thickness; a fan of rays from the site's region back along -z
    (:func:`executive.risk.hand_span.ray_to_hand`) the nearest surface behind the site.
    """
    data = posed_hand(world, side)
    site = world.ids.hand_sites[side]
    origin, frame = data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3)
    thickness = float(np.max(np.abs(hand_points(world, side)[:, 0])))
    # Rays from a pad's width about the site, back along the approach: the first hand surface.
    back = -frame[:, 2]
    starts = [origin + a * frame[:, 0] for a in np.linspace(-FAN_HALF_WIDTH, FAN_HALF_WIDTH, 5)]
    geoms = hand_collision_geoms(world, side)
    gap = min(ray_to_hand(world.model, data, geoms, p, back) for p in starts)
    return thickness, gap


def hand_points(world: World, side: str) -> np.ndarray:
    """The corners (n, 3) of the ``side`` hand's collision geoms in its site frame, open and closed.

    Turned into a grasp's frame they give how far the hand reaches below its site (fingers that
    curl as they close, the Dex3's, reach further closed than open).
    """
    grip = world.profile.arms[side].gripper
    site = world.ids.hand_sites[side]
    geoms = hand_collision_geoms(world, side)
    out = []
    for targets in (None, tuple(grip.closed)):
        data = posed_hand(world, side, targets)
        origin, frame = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)
        out.append((np.vstack([geom_corners(world.model, data, g) for g in geoms]) - origin) @ frame)
    return np.vstack(out)


def _width_and_opening(
    world: World, side: str, obj: str, closing_axis_object: tuple[float, float, float] = (0.0, 1.0, 0.0)
) -> tuple[float, float]:
    """The object's width across the jaws and the jaw opening (m), from ``grasp_tolerance``.

    ``closing = (opening - width) / 2``: asked with a zero opening it gives the width; asked
    with the gripper's own opening (its slide jaws' travel, or a dexterous hand's measured
    span) the opening.
    """
    width = (
        -2.0
        * grasp_tolerance(world, side, obj, jaw_opening=0.0, closing_axis_object=closing_axis_object).closing
    )
    opening = 2.0 * grasp_tolerance(world, side, obj, closing_axis_object=closing_axis_object).closing + width
    return width, opening


def _cm(length: float) -> str:
    """A length in cm to a millimetre, without a trailing ".0" (4, 4.5)."""
    return f"{length * 100:.1f}".rstrip("0").rstrip(".")


def min_thickness(finger_depth: float, table_clearance: float, grip_depth: float) -> float:
    """The thinnest object (m) a top-down grasp takes off a table with the fingers clear of it.

    The site is ``grip_depth`` under the top, never below the centre: ``max(t / 2, t - grip_depth)``
    above the table for thickness ``t``; the fingertips are ``finger_depth`` lower and must stay
    ``table_clearance`` above the table.
    """
    need = finger_depth + table_clearance
    return need + grip_depth if need >= grip_depth else 2.0 * need


def check_grasp(
    world: World,
    side: str,
    obj: str,
    *,
    motion: str,
    site_above_table: float | None,
    table_clearance: float,
    grip_depth: float,
    closing_axis_object: tuple[float, float, float] = (0.0, 1.0, 0.0),
) -> None:
    """Raise :class:`GraspGeometryError` if the ``side`` hand cannot grasp ``obj`` top-down.

    Args:
        world: the estimate world.
        side: the grasping hand.
        obj: the object's name.
        motion: the motion that brings the hand onto the object (named in the error).
        site_above_table: the grasp site's planned height above the table top (m); None for a
            grasp away from the table (a handover), where only the width is checked.
        table_clearance: how far (m) the planner keeps the hand off the table.
        grip_depth: how far (m) under the object's top the composition puts the site.
        closing_axis_object: the jaws' closing axis in the object's frame (default its y).

    Raises:
        GraspGeometryError: naming the object's width and the jaw opening, or its thickness and
            the thickness the fingers need above the table.
    """
    width, opening = _width_and_opening(world, side, obj, closing_axis_object)
    if width >= opening:
        raise GraspGeometryError(
            motion,
            side,
            f"the {width * 100:.0f} cm '{obj}' is wider than the {opening * 100:.0f} cm jaw opening "
            f"of the {side} hand",
        )
    if site_above_table is None:
        return
    depth = hand_geometry(world, side).finger_depth
    if site_above_table - depth >= table_clearance - _ROUNDING:
        return
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    thickness = 2.0 * body.half_height()
    need = min_thickness(depth, table_clearance, grip_depth)
    raise GraspGeometryError(
        motion,
        side,
        f"the {_cm(thickness)} cm '{obj}' is thinner than the {_cm(need)} cm the fingers need "
        f"above the table (the {side} hand reaches {depth * 100:.1f} cm past its grasp point, which is "
        f"{site_above_table * 100:.1f} cm above the table, and keeps {table_clearance * 100:.0f} cm off it)",
    )
