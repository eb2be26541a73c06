"""A Unitree G1 walk (executive/planning/stepping*.py, the ``step`` task) planned and run in physics.

The G1 book scene of tests/conftest.py with its table moved 0.25 m further away (its hips, 0.49 to
0.70 m high, would pass under the 0.62 m table top's front edge 0.15 m ahead) and its mission a
0.15 m walk forward: it plans (two steps) and the executive runs it to success on the exact truth.
Numbers in docs/stepping.md ("Sampled truths"). Skips without the shared G1 model.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from executive import Executive
from executive.decision.physics_check import with_rollouts
from executive.planning.stepping import StepPlanner, plan_steps
from executive.scenario import loads
from executive.world.model import build


def _walk_scene(g1_scenario_yaml: str) -> str:
    """The G1 fixture's scene with the table, book and stack 0.25 m further away and a 0.15 m
    walk forward as its mission."""
    text = g1_scenario_yaml.replace("name: g1_book_transfer", "name: g1_walk")
    for old, new in (
        ("[0.47, 0.0]", "[0.72, 0.0]"),
        ("[0.30, 0.22]", "[0.55, 0.22]"),
        ("[0.48, 0.0]", "[0.73, 0.0]"),
    ):
        assert old in text, old
        text = text.replace(old, new)
    mission = "  - transfer: {object: book, to: [0.30, -0.22]}"
    assert mission in text
    return text.replace(mission, "  - step: {to: [0.15, 0.0]}")


def test_g1_walks_plan(g1_scenario_yaml: str) -> None:
    """Forward, sideways and turning walks of the G1 plan (none did with a fixed 3 cm CoM margin
    on its 6.5 cm sole and its straight knees)."""
    world = build(loads(_walk_scene(g1_scenario_yaml), source="g1_walk.yaml"))
    planner = StepPlanner(world)
    knee = planner.ik.knees["left"]
    assert knee.joint == "left_knee_joint" and abs(knee.straight) < 0.01 and knee.bends == 1.0
    sole = planner.sole_polygon(("left",))
    assert planner.sole_margin(sole) == pytest.approx(0.4 * sole.margin(sole.centre))
    q = world.home_qpos()
    start = planner.footholds(q)
    for goal, steps in (((0.15, 0.0, 0.0), 2), ((0.0, 0.10, 0.0), 3), ((0.0, 0.0, math.radians(30)), 3)):
        plans = plan_steps(planner, q, goal)
        assert len(plans) == steps, goal
        for side, foot in plans[-1].footholds.items():
            assert foot.yaw == pytest.approx(goal[2], abs=math.radians(1.0)), (goal, side)
            if goal[2] == 0.0:
                moved = (foot.x - start[side].x, foot.y - start[side].y)
                assert moved == pytest.approx(goal[:2], abs=0.005), (goal, side)


@pytest.mark.slow
def test_g1_walk_runs_to_success_on_the_exact_truth(g1_scenario_yaml: str, tmp_path: Path) -> None:
    path = tmp_path / "g1_walk.yaml"
    path.write_text(_walk_scene(g1_scenario_yaml))
    from executive.scenario import load

    scenario = with_rollouts(load(str(path)), 0)
    executive = Executive(scenario, approval="auto", truth="exact", out=tmp_path / "run", background=False)
    summary = executive.run()
    assert summary["outcome"] == "success", summary
    truth = executive.truth
    for side, foot in truth.profile.feet.items():  # each foot within 1 cm of 0.15 m ahead of its start
        x, y = truth.data.xpos[truth.model.body(foot.body).id][:2]
        assert abs(x - 0.15) < 0.01 and abs(abs(y) - 0.1185) < 0.01, (side, x, y)
