"""The one-arm alternatives on the shared Unitree G1 model, with truth equal to the estimate.

Skipped when the shared model is absent (see the g1_mjcf fixture). The outcome is
measured here from the truth world's MuJoCo data, not from the runner's report.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from executive.composition import plan_alternative
from executive.planning import Planner, PlanningError
from executive.runner import execute_plan
from executive.scenario import loads
from executive.world import build


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


@pytest.mark.slow
@pytest.mark.xfail(
    raises=PlanningError,
    strict=True,
    reason="known: the profile's top-down Dex3 hand frame has the open fingers 8.7 cm past the hand "
    "site, so the pre-grasp stalls above the book and the grasp would put them into the table",
)
@pytest.mark.parametrize("alternative", ["left", "right"])
def test_one_arm_alternative_succeeds_on_g1(g1_scenario_yaml: str, alternative: str) -> None:
    scenario = loads(g1_scenario_yaml, source="g1_book_transfer.yaml")
    task = scenario.mission[0]
    estimate, truth = build(scenario), build(scenario)
    book = truth.ids.object_bodies["book"]
    pelvis_z = float(truth.data.xpos[truth.ids.base_body][2])
    book_yaw = _yaw(truth.data.xquat[book])
    plan = plan_alternative(Planner(estimate), estimate, task, alternative)
    result = execute_plan(plan, truth, task)
    data = truth.data
    err = float(np.hypot(data.xpos[book][0] - task.to[0], data.xpos[book][1] - task.to[1]))
    dyaw = math.degrees(abs(math.remainder(_yaw(data.xquat[book]) - book_yaw, 2 * math.pi)))
    drop = pelvis_z - float(data.xpos[truth.ids.base_body][2])
    tilt = math.degrees(math.acos(min(1.0, float(data.xmat[truth.ids.torso_body][8]))))
    print(f"G1 {alternative}: {result.outcome}; book {err * 1000:.1f} mm / {dyaw:.1f} deg off")
    assert result.success, result.message
    assert result.failure is None
    assert err < 0.02 and dyaw < 10.0
    assert abs(drop) < 0.05 and tilt < 10.0
