"""The transfer's side-step: composed from the robot and the scene, planned only where the arm alone
falls short, the object carried through the walk, run in physics, the estimate following the base."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from executive import Executive
from executive.decision.assessment import assess_task
from executive.decision.physics_check import with_rollouts
from executive.planning.planner import Planner
from executive.scenario import load
from executive.schema import catalog
from executive.tasks.hands import HandFrames
from executive.tasks.sidestep import sidestep_stance
from executive.tasks.steps import plan_alternative
from executive.world.model import build


def _lateral(frames: HandFrames, point: np.ndarray) -> float:
    """The point's offset from the base along the base's left axis (m)."""
    left = np.array([-np.sin(frames.heading), np.cos(frames.heading)])
    return float((np.asarray(point[:2]) - frames.base[:2]) @ left)


def test_the_stance_brings_the_place_to_the_hands_side_of_the_body_and_no_further() -> None:
    """Closed form of the rule: a place across the midline ends on it; one beyond the hand's home
    line and its pick ends on the farther of the two; one in between needs no step."""
    frames = HandFrames(build(load("sidestep_or_handover")))
    home = frames.home["left"].position
    pick = np.array([0.50, 0.40, 0.85])
    across = np.array([0.50, -0.55, 0.85])
    x, y, heading = sidestep_stance(frames, "left", pick, across)
    assert (x, heading) == pytest.approx((frames.base[0], frames.heading), abs=1e-12)
    assert y - frames.base[1] == pytest.approx(_lateral(frames, across), abs=1e-12)  # onto the midline
    outward = np.array([0.50, 0.70, 0.85])  # beyond the pick (0.40) and the home line
    far = max(_lateral(frames, home), _lateral(frames, pick))
    assert sidestep_stance(frames, "left", pick, outward)[1] - frames.base[1] == pytest.approx(
        _lateral(frames, outward) - far, abs=1e-12
    )
    inside = np.array([0.50, 0.10, 0.85])
    assert sidestep_stance(frames, "left", pick, inside) == pytest.approx(frames.stance(), abs=1e-12)


def test_the_side_step_is_planned_only_where_the_arm_alone_falls_short() -> None:
    """sidestep_or_handover: neither one-arm carry plans, the side-step and the handover do; on
    book_transfer, where the left arm reaches, the left side-step is not needed."""
    scenario = load("sidestep_or_handover")
    rows = {r.name: r for r in assess_task(build(scenario), scenario.mission[0])}
    assert not rows["left"].feasible and not rows["right"].feasible
    assert rows["left_to_right"].feasible and rows["left_sidestep"].feasible
    plan = rows["left_sidestep"].plan
    assert plan is not None and [s.kind for s in plan.steps].count("step") == 1
    scenario = load("book_transfer")
    task = scenario.mission[0].restricted(("left", "left_sidestep"))
    near = {r.name: r for r in assess_task(build(scenario), task)}
    assert near["left"].feasible and not near["left_sidestep"].feasible
    assert near["left_sidestep"].error.startswith("not needed: 'left'")


def test_the_walk_carries_the_book_in_the_hand_and_ends_where_the_rule_says() -> None:
    """Along the planned walk the book keeps its pose in the hand (the planner attaches it), and the
    base ends within the walk's tolerance of the stance."""
    scenario = load("sidestep_or_handover")
    world = build(scenario)
    plan = plan_alternative(Planner(world), world, scenario.mission[0], "left_sidestep")
    walk = next(s for s in plan.steps if s.kind == "step")
    traj = plan.trajectories[walk.name]
    data = mujoco.MjData(world.model)
    site, book = world.ids.hand_sites["left"], world.ids.object_bodies["book"]
    offsets = []
    for q in traj.qpos[:: max(1, len(traj.qpos) // 50)]:
        data.qpos[:] = q
        mujoco.mj_kinematics(world.model, data)
        rotation = data.site_xmat[site].reshape(3, 3)
        offsets.append(rotation.T @ (data.xpos[book] - data.site_xpos[site]))
    assert np.ptp(np.array(offsets), axis=0).max() < 1e-3  # the book rides in the hand
    assert walk.stance is not None
    end = traj.qpos[-1][world.base_qpos][:2]
    assert float(np.hypot(end[0] - walk.stance[0], end[1] - walk.stance[1])) < 0.02
    assert plan.walks[walk.name] and all(step.swing in ("left", "right") for step in plan.walks[walk.name])


def test_the_side_step_places_the_book_in_physics_and_the_estimate_follows_the_base(tmp_path: Path) -> None:
    """Executed on a sampled truth through the same subtree, servos and guards: the book is placed,
    and the observation after the task puts the estimate's base where odometry measures it."""
    data = yaml.safe_load(catalog.scenario_path("sidestep_or_handover").read_text())
    data["mission"][0]["transfer"]["alternatives"] = ["left_sidestep"]
    path = tmp_path / "sidestep.yaml"
    path.write_text(yaml.safe_dump(data))
    scenario = with_rollouts(load(str(path)), 0)
    executive = Executive(scenario, approval="auto", out=tmp_path / "run", background=False)
    summary = executive.run()
    assert summary["outcome"] == "success", summary
    lines = [json.loads(x) for x in (tmp_path / "run" / "decisions.jsonl").read_text().splitlines()]
    assert any(x["kind"] == "execute" and x["alternative"] == "left_sidestep" for x in lines)
    seen = [x for x in lines if x["kind"] == "observation" and x["reason"] == "after_task"][-1]
    truth = executive.truth.data.qpos[executive.truth.base_qpos]
    sigma = scenario.uncertainty.base_position
    assert np.all(np.abs(np.array(seen["base"]["position"][:2]) - truth[:2]) < 4 * sigma)
    assert abs(float(truth[1]) - (-0.55)) < 0.05 and executive.estimate.follows_base
