"""The reaction of a press on the robot, for the fall model.

A press step (:class:`executive.planning.plan.Step` of kind ``press``) carries in ``force`` what
the hand exerts on the panel (world frame, N); the robot feels the opposite at the hand, which
moves its zero moment point (:func:`executive.risk.fall.zero_moment_points`). Unlike a push's,
the force is commanded, not set by an object's mass and friction: it has no spread.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import AlternativePlan
from executive.risk.fall import ExternalForce

__all__ = ["press_forces"]

FloatArray = NDArray[np.float64]


def press_forces(plan: AlternativePlan) -> ExternalForce | None:
    """The hand forces of ``plan``'s press steps per knot of its concatenated trajectory.

    Knot order as :func:`executive.decision.assessment.concatenate` (each step after the first
    drops its repeated start knot). A press step's force is counted over all its knots, the way in
    included (the hold is at its last knot); the other steps' knots carry none.

    Args:
        plan: a planned alternative.

    Returns:
        The forces and the hand sites they act at, or None when the plan presses nothing.
    """
    if not any(s.kind == "press" and s.force is not None for s in plan.steps):
        return None
    forces: list[FloatArray] = []
    points: list[FloatArray] = []
    for step in plan.steps:
        traj = plan.trajectories.get(step.name)
        if traj is None:
            continue
        skip = 1 if forces else 0
        force = step.force if step.kind == "press" and step.force is not None else (0.0, 0.0, 0.0)
        forces.append(np.tile(np.asarray(force, dtype=float), (len(traj.times) - skip, 1)))
        points.append(np.asarray(traj.hand_paths[step.side], dtype=float)[skip:])
    return ExternalForce(np.concatenate(forces), np.concatenate(points))
