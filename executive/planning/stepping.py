"""Quasi-static stepping: one step as five timed whole-body phases, and a walk of such steps.

The public entry of the step planner (docs/stepping.md). One step of the ``swing`` foot to a
:class:`Foothold` (:meth:`StepPlanner.plan_step`, :func:`plan_step`) is, in order
(:data:`PHASES`): ``shift`` the CoM over the stance sole, ``lift`` the swing foot, ``swing`` it
above its foothold, ``touchdown`` flat, ``shift_back`` the CoM between the feet. Each phase is a
:class:`~executive.planning.timing.Trajectory` timed as any planned motion, its zero-moment point
inside the phase's support polygon; with a carried object (``StepPlanner(world, carried=...)``)
the CoM is the robot's and the object's together. A foothold the leg cannot reach is refused
with a :class:`StepPlanningError` naming the limits that bind (``binds``). :func:`measure_reach`
measures how far a foot can step; :func:`plan_steps` walks to a goal stance.

Usage::

    planner = StepPlanner(world)
    feet = planner.footholds(q)
    right = feet["right"]
    plan = planner.plan_step(q, "right", Foothold("right", right.x + 0.12, right.y, right.yaw))
    walk = plan_steps(world, q, (0.5, 0.0, 0.0))  # pelvis to x = 0.5 m
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from executive.planning.stepping_ik import StepPlanningError
from executive.planning.stepping_planner import StepPlanner
from executive.planning.stepping_types import PHASES, Foothold, StepConfig, StepPhase, StepPlan, StepReach
from executive.planning.stepping_walk import measure_reach
from executive.planning.stepping_walk import plan_steps as _plan_steps
from executive.world.model import World

__all__ = [
    "PHASES",
    "Foothold",
    "StepConfig",
    "StepPhase",
    "StepPlan",
    "StepPlanner",
    "StepPlanningError",
    "StepReach",
    "measure_reach",
    "plan_step",
    "plan_steps",
]

FloatArray = NDArray[np.float64]


def plan_step(
    world: World, q_start: FloatArray, swing: str, target: Foothold, config: StepConfig | None = None
) -> StepPlan:
    """One step (:meth:`StepPlanner.plan_step`) on a planner built for it.

    Args:
        world: the (estimate) world to plan on.
        q_start: the start configuration, both feet on the floor.
        swing: the side of the foot that steps.
        target: where it goes.
        config: the step planner's tuning (defaults when None).

    Returns:
        The step's plan.

    Raises:
        StepPlanningError: when the step cannot be planned (naming what binds).
    """
    return StepPlanner(world, config).plan_step(q_start, swing, target)


def plan_steps(
    world: World | StepPlanner,
    q_start: FloatArray,
    goal: tuple[float, float, float],
    config: StepConfig | None = None,
    first: str | None = None,
    max_steps: int = 12,
) -> list[StepPlan]:
    """Steps to the stance whose pelvis stands at ``goal`` (x, y (m), yaw (rad)), alternating feet.

    See :func:`executive.planning.stepping_walk.plan_steps`.

    Args:
        world: the (estimate) world to plan on, or a step planner of it to reuse.
        q_start: the start configuration, both feet on the floor.
        goal: the pelvis's goal on the floor.
        config: the step planner's tuning when a world is given (defaults when None).
        first: the foot that steps first (None: the one whose goal lies more outward).
        max_steps: the most steps before giving up.

    Returns:
        The steps' plans in order (empty when the feet are at the goal already).

    Raises:
        StepPlanningError: when a step cannot be planned or the goal is not reached.
    """
    planner = world if isinstance(world, StepPlanner) else StepPlanner(world, config)
    return _plan_steps(planner, q_start, goal, first, max_steps)
