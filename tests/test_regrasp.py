"""The regrasp alternatives of ``transfer`` (executive/tasks/regrasp.py) on the book transfer.

The book is declared yaw-sensitive (yaw_symmetry 1): the handover refuses it, the regrasp
plans with the real planner and runs in MuJoCo with the truth equal to the estimate. The
midway spot is checked against closed forms of the scene's geometry; the outcome is
measured from the truth world's book body.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
import yaml

from executive.execution.runner import execute_plan
from executive.planning.plan import CompositionConfig
from executive.planning.planner import Planner, PlanningError
from executive.scenario import from_dict
from executive.schema.catalog import scenario_path
from executive.schema.types import Scenario
from executive.tasks.regrasp import midway_spot
from executive.tasks.steps import plan_alternative
from executive.tasks.transfer import TransferKind, transfer_steps
from executive.world.model import build

GRID = 0.01  # the spot search's grid step (m), on a grid through the table's centre


def _scenario(alternatives: list[str], *, stack: bool = True) -> Scenario:
    doc: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["scene"]["objects"][0]["yaw_symmetry"] = 1
    if not stack:
        doc["scene"]["obstacles"] = []
    doc["mission"][0]["transfer"]["alternatives"] = alternatives
    return from_dict(doc)


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def test_names_and_offer() -> None:
    scenario = _scenario(["left_regrasp_right"])
    offered = {a.name: a.unsupported for a in TransferKind().offered(scenario.mission[0], build(scenario))}
    assert offered["left_regrasp_right"] == "" and offered["right_regrasp_left"] == ""
    assert "left_regrasp_right" not in TransferKind.default_alternatives


def test_midway_spot_is_the_free_spot_nearest_the_midline() -> None:
    clearance = CompositionConfig().obstacle_clearance
    world = build(_scenario(["left_regrasp_right"]))
    pos, _ = world.object_pose("book")
    target = np.array([0.52, -0.26, pos[2]])
    spot = midway_spot(world, "book", pos, target, clearance)
    # The stack spans y in [-0.08, 0.08]; the book (0.11 wide, yaw 0) must stay `clearance` from it:
    # |y| >= 0.08 + 0.055 + clearance, the first grid line past it, on the book's side (nearer its start).
    need = 0.08 + 0.055 + clearance
    assert spot.centre[1] == pytest.approx(math.ceil(need / GRID - 1e-9) * GRID, abs=1e-9)
    assert spot.centre[0] == pytest.approx(0.52, abs=1e-9)  # midway in depth between start and target
    assert spot.centre[2] == pytest.approx(0.80 + 0.025, abs=1e-9)  # resting on the table
    # Without the stack the spot is on the midline itself.
    free = build(_scenario(["left_regrasp_right"], stack=False))
    assert midway_spot(free, "book", pos, target, clearance).centre[:2] == pytest.approx(
        [0.52, 0.0], abs=1e-9
    )


def test_no_free_spot_says_what_is_in_the_way() -> None:
    world = build(_scenario(["left_regrasp_right"]))
    pos, _ = world.object_pose("book")
    with pytest.raises(PlanningError, match=r"no free spot on the table.*'book_stack'"):
        midway_spot(world, "book", pos, np.array([0.52, -0.26, pos[2]]), clearance=1.0)


def test_handover_refuses_a_yaw_sensitive_book_and_the_regrasp_runs() -> None:
    scenario = _scenario(["left_regrasp_right"])
    task = scenario.mission[0]
    estimate = build(scenario)
    with pytest.raises(PlanningError, match="yaw_symmetry 1"):
        transfer_steps(estimate, task, "left_to_right")
    plan = plan_alternative(Planner(estimate), estimate, task, "left_regrasp_right")
    names = [s.name for s in plan.steps]
    # The left hand lets go and is home before the right hand grasps.
    assert names.index("left.release") < names.index("left.home") < names.index("right.grasp")
    truth = build(scenario)
    book = truth.ids.object_bodies["book"]
    start_yaw = _yaw(truth.data.xquat[book])
    result = execute_plan(plan, truth, task)
    err = float(np.hypot(truth.data.xpos[book][0] - 0.52, truth.data.xpos[book][1] + 0.26))
    dyaw = math.degrees(abs(math.remainder(_yaw(truth.data.xquat[book]) - start_yaw, 2 * math.pi)))
    print(
        f"left_regrasp_right: {result.outcome}; planned {plan.duration:.1f} s, simulated "
        f"{result.sim_time_s:.1f} s in {result.wall_s:.1f} s wall; "
        f"book {err * 1000:.1f} mm / {dyaw:.1f} deg off"
    )
    assert result.success, result.message
    assert err < 0.02 and dyaw < 10.0  # placed, and its yaw (which matters) kept
    assert truth.data.xpos[book][2] == pytest.approx(0.825, abs=0.01)  # resting on the table


def test_the_regrasp_risks_both_grasps_off_the_table() -> None:
    """Each hand takes the book off the table once: the drop mode counts both grasps, the second
    where the first hand set the book down (not where the estimate first saw it), its pose error
    grown by the set-down's (the hands' execution errors from the tracking model)."""
    from executive.decision.assessment import assess_plan
    from executive.decision.drop_model import _off_table, _table_grasp
    from executive.risk.tracking import predict_tracking

    scenario = from_dict(yaml.safe_load(scenario_path("book_transfer").read_text()), "book_transfer")
    world = build(scenario)
    planner = Planner(world)
    plan = plan_alternative(planner, world, scenario.mission[0], "left_regrasp_right")
    grasps = [i for i in range(len(plan.steps)) if _off_table(plan, i)]
    assert [plan.steps[i].name for i in grasps] == ["left.grasp", "right.grasp"]
    exact = [_table_grasp(world, plan, i).probability for i in grasps]  # as if executed exactly
    assert exact[1] == pytest.approx(exact[0], abs=0.005)  # the same grasp, twice
    tracking = predict_tracking(world, plan)
    first, second = (_table_grasp(world, plan, i, tracking).probability for i in grasps)
    left = plan_alternative(planner, world, scenario.mission[0], "left")
    one_hand = assess_plan(world, left, _model(world))
    # the same top-down grasp of the same book, once where it lay and once where it was set down
    assert first == pytest.approx(one_hand.components["drop"].probability, abs=0.002)
    assert exact[0] < first and exact[1] < second and first < second  # execution adds; a set-down more
    risk = assess_plan(world, plan, _model(world))
    assert risk.components["drop"].probability == pytest.approx(1 - (1 - first) * (1 - second), rel=1e-9)


def _model(world: Any) -> Any:
    from executive.risk.collision import CollisionModel

    return CollisionModel(world, world.scenario.risk, uncertainty=world.scenario.uncertainty)
