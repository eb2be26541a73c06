"""Push contact: does a push's planned hand stay on the face of the object it pushes?

A push slides its object only while the hand presses on the face behind it. The planner moves
the block with the hand (it is ``carried`` in the plan), so nothing in the plan keeps the hand
on that face: a leg whose hand rises until its fingertips pass over the object's top, or swings
across the push beyond the face's edge, leaves the object behind. In physics the hand then
comes down on the object's top (the push stalls, the hand above its planned end) or strikes
its corner and turns it off its line (it rests off its target): both are the push's ``drop``.

The model, per alternative, over every knot ``k`` of its pushing legs (steps with a ``force``):

* across the push: the hand's site line at lateral offset ``l_k`` from the object's centre line
  (on the estimate) stays on the face while ``|l_k - e| <= W``, ``W`` the object's half extent
  across the push (its support function, :func:`half_extent`) and ``e ~ N(0, s^2)`` the true
  object's offset across the push (``uncertainty.object_position``), one draw for the whole
  push: ``P(hold) = Phi((min l + W) / s) - Phi((max l - W) / s)``;
* up: the fingertips (``finger_depth`` below the site) pass over the top once the highest
  knot's site is more than ``top + finger_depth``; the hand's height spreads by the tracking
  statics' unmodelled error per axis (:data:`executive.risk.tracking.UNMODELLED_SIGMA`):
  ``P(over) = Phi((z_max - finger_depth - top) / sigma)``.

``P(lost) = 1 - P(hold) (1 - P(over))``. Use :func:`face_contact` on a planned alternative;
:func:`executive.risk.push.assess_placement` folds it into the push's drop probability.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.gaussian import normal_cdf
from executive.risk.hand_span import hand_span
from executive.risk.tracking import UNMODELLED_SIGMA
from executive.schema.types import Body, Uncertainty
from executive.world.model import World

__all__ = ["FaceContact", "face_contact", "half_extent", "loss_probability"]

FloatArray = NDArray[np.float64]


def half_extent(body: Body, quat: FloatArray, direction: FloatArray) -> float:
    """Half the extent (m) of ``body`` at orientation ``quat`` along the horizontal unit ``direction``
    (its support function)."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(quat, dtype=float))
    axes = rot.reshape(3, 3)  # columns: the body's axes in the world
    along = np.abs(np.asarray(direction, dtype=float) @ axes)
    if body.shape == "box":
        return float(np.sum(along * np.asarray(body.size) / 2.0))
    if body.shape == "cylinder":
        radius, length = body.size
        return float(along[2] * length / 2.0 + radius * math.sqrt(max(0.0, 1.0 - along[2] ** 2)))
    return float(body.size[0])


def loss_probability(
    lateral: tuple[float, float], half_width: float, rise: float, sigma: float, height_sigma: float
) -> float:
    """P(a push's hand leaves the face): its offsets across the push (least, greatest; m) against
    the face's ``half_width`` with the object's offset ``N(0, sigma^2)`` shared by every knot, or
    its fingertips ``rise`` m over the object's top with the hand's height ``N(0, height_sigma^2)``
    (module docstring)."""
    low, high = lateral
    if sigma > 0.0:
        hold = max(
            0.0,
            float(normal_cdf((low + half_width) / sigma)) - float(normal_cdf((high - half_width) / sigma)),
        )
    else:
        hold = 1.0 if high - half_width <= 0.0 <= low + half_width else 0.0
    over = float(normal_cdf(rise / height_sigma)) if height_sigma > 0.0 else float(rise > 0.0)
    return 1.0 - hold * (1.0 - over)


@dataclass(frozen=True)
class FaceContact:
    """How a push's planned hand keeps to its object's face (:func:`face_contact`).

    ``lateral``: the knots' least and greatest offsets across the push from the object's centre
    line (m); ``half_width``: the face's half extent across the push (m); ``rise``: how far the
    highest knot's fingertips are above the object's top (m, negative: below it);
    ``probability``: P(the hand leaves the face somewhere along the push).
    """

    lateral: tuple[float, float]
    half_width: float
    rise: float
    probability: float

    def details(self) -> dict[str, float]:
        """The report's fields."""
        return {
            "face_lateral_low": self.lateral[0],
            "face_lateral_high": self.lateral[1],
            "face_half_width": self.half_width,
            "fingertips_over_top": self.rise,
            "face_loss_probability": self.probability,
        }


def _object_body(world: World, name: str) -> Body:
    return next(b for b in world.scenario.scene.objects if b.name == name)


def face_contact(world: World, plan: Any, uncertainty: Uncertainty) -> FaceContact | None:
    """Whether ``plan``'s pushing hand stays on its object's face (module docstring).

    Args:
        world: the estimate the plan was made on (the object where the push starts).
        plan: the planned alternative (``executive.planning.plan.AlternativePlan``).
        uncertainty: the scene's uncertainty (its ``object_position``, per horizontal axis).

    Returns:
        The :class:`FaceContact`, or None when the plan pushes nothing.
    """
    across_paths: list[FloatArray] = []
    highest = -np.inf
    pushed: tuple[str, str] | None = None
    direction = np.zeros(3)
    for step in plan.steps:
        traj = plan.trajectories.get(step.name)
        if traj is None or step.kind != "push" or step.carried is None or not np.any(step.force or 0.0):
            continue
        pushed = step.carried
        direction = np.asarray(step.force, dtype=float) / float(np.linalg.norm(step.force))
        path = np.asarray(traj.hand_paths[step.side], dtype=float)
        across = np.array([-direction[1], direction[0], 0.0])
        across_paths.append(path @ across)
        highest = max(highest, float(np.max(path[:, 2])))
    if pushed is None:
        return None
    side, name = pushed
    across = np.array([-direction[1], direction[0], 0.0])
    pos, quat = world.object_pose(name)
    body = _object_body(world, name)
    offsets = np.concatenate(across_paths) - float(np.asarray(pos) @ across)
    width = half_extent(body, quat, across)
    top = float(pos[2]) + half_extent(body, quat, np.array([0.0, 0.0, 1.0]))
    depth = max(hand_span(world, side).finger_depth, hand_span(world, side, closed=True).finger_depth)
    rise = highest - depth - top
    lateral = (float(np.min(offsets)), float(np.max(offsets)))
    sigma = float(uncertainty.object_position)
    return FaceContact(lateral, width, rise, loss_probability(lateral, width, rise, sigma, UNMODELLED_SIGMA))
