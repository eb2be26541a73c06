"""The G1's Dex3 hand in the risk models, against physics on the shared model.

The jaw opening, the grasp tolerance and the hold's grip force are computed from the hand's
own geometry and servos (executive/risk/hand_span.py, hand_grip.py); here each is checked
against what MuJoCo does when the left hand grasps and lifts a book (exact truth): the contact
normal forces on the book while lifted, and the widest book the hand takes off the table.
Skipped when the shared model is absent (the g1_mjcf fixture).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from executive.execution.runner import RunResult, execute_plan
from executive.planning.planner import Planner
from executive.risk.grasp import grasp_tolerance
from executive.risk.hand_grip import dexterous_squeeze, hand_chains
from executive.risk.hand_span import hand_span
from executive.risk.hold import grip
from executive.scenario import loads
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build

BOOK = "0.14, 0.09, 0.05"


def _lift(text: str, width: float) -> tuple[World, World, RunResult]:
    """Plan the left alternative for a book ``width`` wide; run it in physics until the lift ends."""
    scenario = loads(text.replace(BOOK, f"0.14, {width}, 0.05"), source="g1_width.yaml")
    estimate, truth = build(scenario), build(scenario)
    plan = plan_alternative(Planner(estimate), estimate, scenario.mission[0], "left")
    end = 0.0
    for step in plan.steps:
        end += (
            plan.trajectories[step.name].duration if step.name in plan.trajectories else 0.0
        ) + step.hold_s
        if step.name == "left.lift":
            break
    return estimate, truth, execute_plan(plan, truth, scenario.mission[0], time_limit_s=end + 0.5)


def _contact_forces(truth: World) -> dict[bool, float]:
    """Sum of the hand's contact normal forces on the book (N), thumb side (True) and fingers."""
    model, data = truth.model, truth.data
    book = truth.ids.object_geoms["book"]
    thumbs = {c.geom: c.thumb for c in hand_chains(truth, "left")}
    hand = set(truth.ids.hand_bodies["left"])
    sums = {True: 0.0, False: 0.0}
    wrench = np.zeros(6)
    for i in range(data.ncon):
        g1, g2 = int(data.contact.geom[i][0]), int(data.contact.geom[i][1])
        other = g1 if g2 == book else g2 if g1 == book else -1
        if other < 0 or int(model.geom_bodyid[other]) not in hand:
            continue
        mujoco.mj_contactForce(model, data, i, wrench)
        sums[thumbs.get(other, False)] += float(wrench[0])
    return sums


def test_dex3_opening_and_tolerance_from_its_geometry(g1_scenario_yaml: str) -> None:
    """Open, the thumb and fingers leave ~14.7 cm; closed, the fingers stop ~4 cm past the site
    and the thumb passes it: the book's closing tolerance is (opening - 9 cm) / 2."""
    world = build(loads(g1_scenario_yaml, source="g1_book_transfer.yaml"))
    for side in ("left", "right"):
        span = hand_span(world, side)
        assert span.opening == pytest.approx(0.1466, abs=0.002)
        assert grasp_tolerance(world, side, "book").closing == pytest.approx(
            (span.opening - 0.09) / 2, abs=1e-12
        )
        fingers = [c for c in hand_chains(world, side) if not c.thumb]
        assert len(fingers) == 2 and all(0.03 < c.point[1] < 0.05 for c in fingers)
    assert dexterous_squeeze(world, "left", 0.02).force == 0.0  # narrower than the closed hand


def test_dex3_grip_force_matches_the_contact_forces_of_a_lifted_book(g1_scenario_yaml: str) -> None:
    """The model's squeeze (the thumb's saturated servos through its Jacobian) against the
    normal forces MuJoCo's contacts carry while the 9 cm book is held off the table."""
    estimate, truth, result = _lift(g1_scenario_yaml, 0.09)
    book_z = float(truth.data.xpos[truth.ids.object_bodies["book"]][2])
    assert result.failure is None and book_z > 0.66 + 0.02 + 0.05  # lifted: 5 cm above resting
    measured = _contact_forces(truth)
    model = grip(estimate, "left", "book", np.array([0.0, 1.0, 0.0])).force
    print(f"grip: model {model:.1f} N; physics thumb {measured[True]:.1f} N, fingers {measured[False]:.1f} N")
    assert model == pytest.approx(measured[True], rel=0.2)
    assert model == pytest.approx(measured[False], rel=0.2)


def test_the_widest_book_the_dex3_takes_is_its_measured_opening(g1_scenario_yaml: str) -> None:
    """A 13 cm book (1 cm inside the 14.7 cm opening) is lifted; a 14.5 cm one (closing
    tolerance under 1 mm) is landed on by the open thumb on the way down."""
    _, truth, result = _lift(g1_scenario_yaml, 0.13)
    assert result.failure is None
    assert float(truth.data.xpos[truth.ids.object_bodies["book"]][2]) > 0.66 + 0.02 + 0.05
    estimate, _, wide = _lift(g1_scenario_yaml, 0.145)
    assert grasp_tolerance(estimate, "left", "book").closing < 0.001
    assert wide.failure is not None and "landed on book" in wide.message
