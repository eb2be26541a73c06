"""The estimate after a task: where the chosen alternative's plan leaves the robot and the objects.

``executive plan`` plans a mission's tasks in order on one estimate world; what a task leaves
(an object in a hand after a pick, a book on its new spot, the robot where a walk ended) is
where the next one starts, as in a run, where the robot's look after each task brings the
estimate there (:func:`executive.world.observation.update_estimate`).

Usage::

    q_start = None
    for task in scenario.mission:
        alternatives = assess_task(world, task, q_start=q_start)
        q_start = state_after(scenario, world, task, alternatives, q_start)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from executive.decision.assessment import AlternativeRisk
from executive.planning.plan import held_at_end
from executive.schema.types import Scenario, Task
from executive.tasks.registry import get as task_kind
from executive.world.model import World
from executive.world.observation import Observation, update_estimate

__all__ = ["chosen_index", "state_after"]

FloatArray = NDArray[np.float64]


def chosen_index(alternatives: Sequence[AlternativeRisk], ordering: str) -> int | None:
    """Index of the feasible alternative with the lowest risk by ``ordering`` (None if none is feasible)."""
    feasible = [(a.risk.value(ordering), i) for i, a in enumerate(alternatives) if a.risk is not None]
    return min(feasible)[1] if feasible else None


def state_after(
    scenario: Scenario,
    world: World,
    task: Task,
    alternatives: Sequence[AlternativeRisk],
    q_start: FloatArray | None,
) -> FloatArray | None:
    """The start of the next task after ``task``'s chosen alternative, with ``world`` brought there.

    The robot where the chosen plan ends (after a walk, the estimate's base put there too); the
    objects where the plan leaves them, and the hands holding what they hold at its end, as a
    look at that state would give them (``world.held``, ``world.grips``).

    Args:
        scenario: the scenario (its ``risk.ordering`` picks the chosen alternative).
        world: the estimate world the tasks are planned on; updated in place.
        task: the task just planned.
        alternatives: its alternatives, assessed (and checked in physics, if they were).
        q_start: where ``task`` started (None: home).

    Returns:
        The full configuration the next task starts from; ``q_start`` when no alternative is
        feasible (nothing would be done).
    """
    chosen = chosen_index(alternatives, scenario.risk.ordering)
    plan = alternatives[chosen].plan if chosen is not None else None
    if plan is None:
        return q_start
    end = plan.ordered_trajectories()[-1].qpos[-1].copy()
    if task_kind(task.kind).moves_base or any(plan.walks.values()):
        world.data.qpos[world.base_qpos] = end[world.base_qpos]
        world.follows_base = True
    objects = {
        name: (end[adr : adr + 3], end[adr + 3 : adr + 7]) for name, adr in world.ids.object_qpos.items()
    }
    update_estimate(world, end, Observation(objects, held_at_end(plan.steps), {"source": "plan"}, 0.0))
    return end
