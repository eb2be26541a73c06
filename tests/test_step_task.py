"""The ``step`` task: a walk planned, assessed and run through the executive; afterwards the
estimate stands where the robot's odometry says and later tasks plan from there."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from executive import Executive
from executive.decision.assessment import assess_task
from executive.decision.physics_check import with_rollouts
from executive.planning.types import HandTarget
from executive.scenario import load
from executive.tasks.hands import HandFrames
from executive.world.model import build


def _walk_only(tmp_path: Path, base_sigma: float) -> Path:
    """walk_to_table with its walk alone and the odometry's sigma ``base_sigma`` (m)."""
    import yaml

    from executive.schema import catalog

    data = yaml.safe_load(catalog.scenario_path("walk_to_table").read_text())
    data["mission"] = data["mission"][:1]
    data["uncertainty"]["base_position"] = base_sigma
    path = tmp_path / "walk.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_hand_frames_move_with_the_base_a_walk_measured() -> None:
    """Home hand poses after a walk of (dx, dy) and a turn: the start's, turned about the start
    base and shifted (a rigid planar motion, checked point by point)."""
    world = build(load("walk_to_table"))
    start = HandFrames(world)
    dx, dy, turn = 0.40, -0.05, math.radians(20.0)
    base = world.base_qpos
    world.data.qpos[base.start : base.start + 2] += (dx, dy)
    world.data.qpos[base.start + 3 : base.start + 7] = [math.cos(turn / 2), 0.0, 0.0, math.sin(turn / 2)]
    world.follows_base = True
    moved = HandFrames(world)
    c, s = math.cos(turn), math.sin(turn)
    for side, home in start.home.items():
        rel = home.position - start.base
        want = start.base + np.array([c * rel[0] - s * rel[1] + dx, s * rel[0] + c * rel[1] + dy, rel[2]])
        assert moved.home[side].position == pytest.approx(want, abs=1e-12)
        assert isinstance(moved.home[side], HandTarget)
    assert moved.heading == pytest.approx(start.heading + turn)
    assert moved.to_world((0.30, 0.0)) == pytest.approx((0.30 * c + dx, 0.30 * s + dy))


def test_the_transfer_beyond_reach_plans_from_where_the_walk_ends() -> None:
    scenario = with_rollouts(load("walk_to_table"), 0)
    walk, transfer = scenario.mission
    world = build(scenario)
    from_start = assess_task(world, transfer)
    assert not any(a.feasible for a in from_start), [a.error for a in from_start]
    (left_first, right_first) = assess_task(world, walk)
    assert left_first.feasible and right_first.feasible and left_first.plan is not None
    end = left_first.plan.ordered_trajectories()[-1].qpos[-1]
    assert end[world.base_qpos][0] == pytest.approx(0.40, abs=0.02)  # the pelvis where the walk goes
    world.data.qpos[world.base_qpos] = end[world.base_qpos]
    world.follows_base = True
    there = {a.name: a for a in assess_task(world, transfer, q_start=end)}
    arms = ("left", "right", "left_to_right")
    assert all(there[n].feasible for n in arms), {n: there[n].error for n in arms}
    # Both arms reach from there: the side-steps are not needed (planned only where an arm falls short).
    assert all(there[n].error.startswith("not needed") for n in ("left_sidestep", "right_sidestep"))
    loss = {n: a.risk.expected_loss for n, a in there.items() if a.risk is not None}
    assert min(loss, key=loss.__getitem__) == "left_to_right"  # as in book_transfer, from where it stands


@pytest.mark.slow
def test_a_walk_in_physics_leaves_the_estimate_where_odometry_measures_the_base(tmp_path: Path) -> None:
    sigma = 0.01
    scenario = with_rollouts(load(str(_walk_only(tmp_path, sigma))), 0)
    executive = Executive(scenario, approval="deny", out=tmp_path / "run", background=False)
    summary = executive.run()
    assert summary["outcome"] == "success", summary
    lines = [json.loads(x) for x in (tmp_path / "run" / "decisions.jsonl").read_text().splitlines()]
    stood = next(x for x in lines if x["kind"] == "stood")
    assert stood["stance_error_m"] < 0.02  # the pelvis within 2 cm of its goal, in physics
    seen = [x for x in lines if x["kind"] == "observation" and x["reason"] == "after_task"][-1]
    truth = executive.truth.data.qpos[executive.truth.base_qpos]
    logged = np.array(seen["base"]["position"])
    assert np.all(np.abs(logged[:2] - truth[:2]) < 4 * sigma) and np.any(logged[:2] != truth[:2])
    estimate = executive.estimate.data.qpos[executive.estimate.base_qpos]
    assert estimate[:2] == pytest.approx(logged[:2]) and executive.estimate.follows_base
    assert float(np.linalg.norm(truth[:2] - (0.40, 0.0))) < 0.03
