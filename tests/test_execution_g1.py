"""The one-arm alternatives on the shared Unitree G1 model, with truth equal to the estimate.

Skipped when the shared model is absent (see the g1_mjcf fixture). The outcome is
measured here from the truth world's MuJoCo data, not from the runner's report.
The scene is laid out for the G1's Dex3 grasp (tests/conftest.py, g1_scenario_yaml).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from executive.execution.runner import execute_plan
from executive.planning.planner import Planner
from executive.scenario import loads
from executive.tasks.steps import plan_alternative
from executive.tasks.transfer import transfer_steps
from executive.world.model import build


def _yaw(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def test_a_hand_that_placed_across_the_body_goes_back_to_its_side_first(g1_scenario_yaml: str) -> None:
    """The left hand places the book right of the midline: it returns along the lane to its own
    side before it turns home. The right hand places on its own side and goes straight home."""
    scenario = loads(g1_scenario_yaml, source="g1_book_transfer.yaml")
    world = build(scenario)
    left = transfer_steps(world, scenario.mission[0], "left")
    names = [s.name for s in left]
    assert names[-3:] == ["left.retreat", "left.back", "left.home"]
    back, retreat = left[-2].targets[0], left[-3].targets[0]
    assert back.position[1] > 0.0 > retreat.position[1]  # from the right of the midline to the left
    assert np.allclose(back.quat, retreat.quat)  # as it is: the hand turns on the way home only
    right = [s.name for s in transfer_steps(world, scenario.mission[0], "right")]
    assert right[-2:] == ["right.retreat", "right.home"]


def test_g1_hands_close_with_their_fingers_towards_the_midline(g1_scenario_yaml: str) -> None:
    """The profile's closing_yaw picks, of the two ways to close across the book, the one whose
    closing axis (+y of the hand frame, thumb to fingers) points -y for the left hand and +y for
    the right, at the grasp, the place and in between (the book keeps its yaw)."""
    scenario = loads(g1_scenario_yaml, source="g1_book_transfer.yaml")
    world = build(scenario)
    for side, sign in (("left", -1.0), ("right", 1.0)):
        steps = transfer_steps(world, scenario.mission[0], side)
        names = {step.name for step in steps}
        assert {f"{side}.{n}" for n in ("pre_grasp", "approach", "lift", "place", "retreat")} <= names
        targets = [t for step in steps if step.kind != "home" for t in step.targets]
        for t in targets:
            rotation = np.zeros(9)
            mujoco.mju_quat2Mat(rotation, t.quat)
            assert rotation.reshape(3, 3)[:, 1] == pytest.approx([0.0, sign, 0.0], abs=1e-9), t
            assert rotation.reshape(3, 3)[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)


@pytest.mark.slow
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
    print(
        f"G1 {alternative}: {result.outcome}; book {err * 1000:.1f} mm / {dyaw:.1f} deg off; "
        f"planned {plan.duration:.1f} s; simulated {result.sim_time_s:.1f} s in {result.wall_s:.1f} s"
    )
    assert result.success, result.message
    assert result.failure is None
    assert err < 0.02 and dyaw < 10.0
    assert abs(drop) < 0.05 and tilt < 10.0
