"""A mission's tasks planned in order: each from where the one before leaves the robot and objects.

``state_after`` brings the estimate to the end of a task's chosen plan. Checked against physics:
the pick of pick_place_push executed on the exact truth ends with the book in the same hand and
within a few millimetres of where the estimate puts it; the place that follows plans, where
planned from the scene's start it is refused ("held by no hand").
"""

from __future__ import annotations

import numpy as np
import pytest

from executive.decision.after_task import chosen_index, state_after
from executive.decision.assessment import assess_task
from executive.execution.runner import execute_plan
from executive.planning.plan import Step, held_at_end
from executive.scenario import load
from executive.world.model import build


def test_held_at_end_follows_grasps_and_releases() -> None:
    pick = [
        Step("grasp", "l.grasp", "left", obj="book"),
        Step("lift", "l.lift", "left", carried=("left", "book")),
    ]
    place = [Step("place", "l.place", "left", carried=("left", "book")), Step("release", "l.release", "left")]
    push = [Step("push", "r.push", "right", carried=("right", "block"))]
    assert held_at_end(pick) == {"left": "book"}
    assert held_at_end(place) == {}
    assert held_at_end([*pick, *place]) == {}
    assert held_at_end(push) == {}


@pytest.fixture(scope="module")
def after_pick() -> tuple:
    scenario = load("pick_place_push")
    world = build(scenario)
    pick = assess_task(world, scenario.mission[0])
    q = state_after(scenario, world, scenario.mission[0], pick, None)
    return scenario, world, pick, q


def test_the_estimate_after_the_pick_is_where_physics_leaves_the_book(after_pick: tuple) -> None:
    scenario, world, pick, q = after_pick
    chosen = pick[chosen_index(pick, scenario.risk.ordering)]
    assert chosen.plan is not None and q is not None
    assert world.held == {"book": chosen.name}
    truth = build(scenario)
    result = execute_plan(chosen.plan, truth, scenario.mission[0])
    assert result.outcome == "success", result
    book_truth, _ = truth.object_pose("book")
    book_estimate, _ = world.object_pose("book")
    assert np.linalg.norm(book_truth - book_estimate) < 0.02  # the plan's end vs physics' end


def test_the_place_after_the_pick_plans(after_pick: tuple) -> None:
    scenario, world, _, q = after_pick
    side = world.held["book"]
    place = {a.name: a for a in assess_task(world, scenario.mission[1], q_start=q)}
    assert place[side].feasible, place[side].error
    cold = {a.name: a for a in assess_task(build(scenario), scenario.mission[1])}
    assert not cold[side].feasible and "held by no hand" in cold[side].error
