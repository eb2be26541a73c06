"""A move that stalls names what binds: the active set of the IK step's QP (executive.planning.active_set).

Small constructed cases on the bundled book scene (a wall put in the hand's way, a hand turned
beyond what its joints allow) and the scenes of tests/data (a block 1.5 cm beyond the book's
target, a second stack of binders beyond it). What is named is checked against the geometry at
the configuration the move stalled at: coal's distance of the named pair equals the reported
distance, and it sits at the pair's clearance; a named joint is at its range's bound in the MJCF.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import coal
import mujoco
import numpy as np
import pytest
import yaml

from executive.decision.assessment import assess_task
from executive.decision.selector_rows import risk_row
from executive.planning.planner import HandTarget, Planner, PlanningError
from executive.planning.types import PlannerConfig
from executive.report.plots import risk_json
from executive.risk.shapes import coal_geometry, coal_transform
from executive.scenario import from_dict, load
from executive.schema.catalog import scenario_path
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build

DATA = Path(__file__).parent / "data"
TOLERANCE = PlannerConfig().clearance_tolerance  # what the IK keeps beyond a pair's clearance


def _book_world(extra: list[dict[str, Any]] = ()) -> World:  # type: ignore[assignment]
    doc: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["scene"]["obstacles"] = [*doc["scene"]["obstacles"], *extra]
    return build(from_dict(doc))


def _hand_pose(world: World, side: str) -> tuple[np.ndarray, np.ndarray]:
    data = mujoco.MjData(world.model)
    data.qpos[:] = world.home_qpos()
    mujoco.mj_forward(world.model, data)
    site = world.ids.hand_sites[side]
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, data.site_xmat[site])
    return data.site_xpos[site].copy(), quat


def _stall(world: World, exc: PlanningError) -> mujoco.MjData:
    assert exc.stall is not None
    data = mujoco.MjData(world.model)
    data.qpos[:] = exc.stall
    mujoco.mj_forward(world.model, data)
    return data


def _coal_distance(world: World, data: mujoco.MjData, pair: str) -> float:
    """coal's distance of the geoms named ``"a vs b"`` at ``data``'s configuration."""
    model = world.model
    g1, g2 = (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in pair.split(" vs "))
    shapes = [coal_geometry(model, g) for g in (g1, g2)]
    assert shapes[0] is not None and shapes[1] is not None
    result = coal.DistanceResult()
    coal.distance(
        shapes[0],
        coal_transform(data.geom_xpos[g1], data.geom_xmat[g1]),
        shapes[1],
        coal_transform(data.geom_xpos[g2], data.geom_xmat[g2]),
        coal.DistanceRequest(),
        result,
    )
    return float(result.min_distance)


def _check_pairs(world: World, exc: PlanningError) -> list[str]:
    """Every named pair: coal's distance at the stall is the reported one, at its clearance."""
    data = _stall(world, exc)
    pairs = [b for b in exc.binding if b.kind == "collision"]
    for b in pairs:
        assert _coal_distance(world, data, b.name) == pytest.approx(b.value, abs=1e-5)
        assert b.bound - 1e-3 <= b.value <= b.bound + TOLERANCE + 1e-3
    return [b.name for b in pairs]


def _check_joints(world: World, exc: PlanningError) -> list[str]:
    """Every named joint is at the bound of its range in the MJCF (the stall's qpos)."""
    model, q = world.model, exc.stall
    assert q is not None
    joints = [b for b in exc.binding if b.kind == "joint_range"]
    for b in joints:
        joint = model.joint(b.name)
        bound = float(joint.range[1 if b.side == "upper" else 0])
        assert b.bound == pytest.approx(bound)
        assert float(q[model.jnt_qposadr[joint.id]]) == pytest.approx(bound, abs=5e-3)
    return [b.name for b in joints]


def test_a_wall_in_the_way_is_named_with_its_clearance() -> None:
    # A thin wall 10 cm ahead of the right hand, across its way forward (no way over: the
    # target is level with the hand, the wall 40 cm tall).
    world = _book_world(
        [{"name": "wall", "shape": "box", "size": [0.02, 0.30, 0.40], "position": [0.40, -0.25]}]
    )
    position, quat = _hand_pose(world, "right")
    target = HandTarget("right", np.array([0.50, position[1], position[2]]), quat)
    with pytest.raises(PlanningError) as caught:
        Planner(world).move(world.home_qpos(), [target], name="through_wall")
    exc = caught.value
    pairs = _check_pairs(world, exc)
    assert pairs and pairs[0].startswith("right_") and pairs[0].endswith(" vs wall")
    assert exc.binding[0].kind == "collision"  # the pairs come first
    assert f"binding: {pairs[0]} at " in str(exc)
    _check_joints(world, exc)


def test_a_target_beyond_the_wrist_names_the_joints_at_their_limits() -> None:
    # The right hand turned 170 deg about its own y axis where it is: beyond its wrist and elbow.
    world = _book_world()
    position, quat = _hand_pose(world, "right")
    turn, goal = np.empty(4), np.empty(4)
    mujoco.mju_axisAngle2Quat(turn, np.array([0.0, 1.0, 0.0]), np.radians(170.0))
    mujoco.mju_mulQuat(goal, quat, turn)
    with pytest.raises(PlanningError) as caught:
        Planner(world).move(world.home_qpos(), [HandTarget("right", position, goal)], name="turn")
    exc = caught.value
    joints = _check_joints(world, exc)
    assert "right_wrist_pitch" in joints and "right_wrist_roll" in joints
    assert not [b for b in exc.binding if b.kind == "collision"]  # nothing near the hand
    assert "right_wrist_pitch at its upper limit (0.60 rad)" in str(exc)


def test_the_tight_spot_names_the_book_against_the_block() -> None:
    scenario = load(DATA / "book_transfer_tight.yaml")
    world = build(scenario)
    with pytest.raises(PlanningError) as caught:
        plan_alternative(Planner(world), world, scenario.mission[0], "right")
    exc = caught.value
    assert exc.name == "right.pre_place"
    assert _check_pairs(world, exc)[0] == "book vs block"


def test_the_binders_hold_the_one_arm_carry_but_not_the_handover() -> None:
    scenario = load(DATA / "book_transfer_binders.yaml")
    world = build(scenario)
    planner = Planner(world)
    with pytest.raises(PlanningError) as caught:
        plan_alternative(planner, world, scenario.mission[0], "right")
    assert _check_pairs(world, caught.value)[0] == "right_palm_geom vs binders_2"
    plan = plan_alternative(planner, world, scenario.mission[0], "left_to_right")
    assert "right.place" in plan.trajectories


def test_binding_reaches_the_plan_json_and_the_audit_row() -> None:
    doc: dict[str, Any] = yaml.safe_load((DATA / "book_transfer_tight.yaml").read_text())
    doc["mission"][0]["transfer"]["alternatives"] = ["right"]
    scenario = from_dict(doc)
    (alt,) = assess_task(build(scenario), scenario.mission[0])
    assert not alt.feasible and alt.binding and alt.binding[0]["name"] == "book vs block"
    row = json.loads(risk_json(scenario, [("transfer", [alt])]))["tasks"][0]["alternatives"][0]
    assert row["binding"] == json.loads(json.dumps(list(alt.binding)))
    assert risk_row(alt, scenario.risk.ordering)["binding"][0]["kind"] == "collision"
