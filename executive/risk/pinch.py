"""Where a grasp leaves the object in the hand, and what that does to the placement.

Parallel slide jaws (the bundled humanoid's) close symmetrically about the hand site: the
object ends centred on it, shift 0. A thumb against fingers (the G1's Dex3) holds it where
the two sides' forces balance (:func:`executive.risk.hand_grip.pinch_centre`), off the site
along its closing axis. The hand then places the object that far from where it aims.

The placement error in the table plane is then ``(e, mu)``: ``e`` the object's Gaussian
error along the jaws (closing does not correct it) and ``mu`` the shift's horizontal part
across them (deterministic: the pinch moves the object to its balance point whatever its
offset across the site before). Misplaced beyond ``tol``: e^2 + mu^2 > tol^2, i.e.
|e| > sqrt(tol^2 - mu^2) (certain when mu >= tol), one Gaussian's tail, exact.

Usage::

    mu = closing_shift(world, "left", "book")                    # m along the site's +y
    tol_e = placement_tolerance(0.02, horizontal_shift(mu, hand_rotation))
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from executive.risk.grasp_tolerance import has_slide_jaws
from executive.risk.hand_grip import pinch_centre
from executive.risk.model_geometry import half_extent
from executive.world.model import World

__all__ = ["closing_shift", "horizontal_shift", "placement_tolerance"]


def closing_shift(
    world: World, side: str, obj: str, closing_axis_object: ArrayLike = (0.0, 1.0, 0.0)
) -> float:
    """Offset (m) of ``obj``'s centre from the ``side`` hand site along the site's closing
    axis (+y) once the hand has closed on it.

    Args:
        world: the world whose robot has the hand.
        side: the arm.
        obj: the object (its width is its extent along ``closing_axis_object``).
        closing_axis_object: the object-frame axis the hand closes across.

    Returns:
        0.0 for slide jaws (symmetric about the site); the pinch centre for a dexterous hand.
    """
    if has_slide_jaws(world, side):
        return 0.0
    axis = np.asarray(closing_axis_object, dtype=float).reshape(3)
    width = 2.0 * half_extent(world.model, world.ids.object_geoms[obj], axis / np.linalg.norm(axis))
    return pinch_centre(world, side, width)


def horizontal_shift(shift: float, hand_rotation: ArrayLike) -> float:
    """Length (m) of the table-plane part of ``shift`` along the hand site's y axis (the
    closing axis; ``hand_rotation`` the site's 3x3 world rotation)."""
    y_axis = np.asarray(hand_rotation, dtype=float).reshape(3, 3)[:, 1]
    return abs(shift) * float(math.hypot(y_axis[0], y_axis[1]))


def placement_tolerance(tol: float, mu: float) -> float:
    """Largest |error| along the jaws that keeps an object shifted ``mu`` across them within
    ``tol`` of its target: sqrt(tol^2 - mu^2), 0 when mu >= tol, ``tol`` itself when mu is 0."""
    if mu == 0.0:
        return tol
    return math.sqrt(tol * tol - mu * mu) if mu < tol else 0.0
