"""The ``press`` task kind (executive/tasks/press.py, behaviours/press.py): read, laid out, run in MuJoCo.

A 16 x 16 x 6 cm panel (a box obstacle) stands on the table in front of the right hand. The YAML
reader is checked for the key path of each bad value; the geometry against closed forms; the
press in real physics (truth equal to the estimate) against the commanded force, measured by the
behaviour on the hand-panel contacts and, independently, by the floor under the feet: the panel
pushes the robot up by what the hand pushes it down with, so the feet carry the robot's weight
less the press force.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

import behaviours.press as press_behaviour
from executive.decision.assessment import assess_task, concatenate
from executive.errors import ScenarioError
from executive.execution.runner import execute_plan
from executive.monitoring.detectors import FailureDetector
from executive.planning.plan import CompositionConfig
from executive.planning.planner import Planner
from executive.planning.press_geometry import hand_lead, press_compliance, surface_at
from executive.risk.fall import assess_fall
from executive.risk.press import press_forces
from executive.runtime.mission import Executive
from executive.scenario import from_dict
from executive.schema.types import Body, Scenario
from executive.tasks.press import PressKind, PressTask
from executive.tasks.steps import plan_alternative
from executive.world.model import Perturbation, World, build

PANEL = {"name": "panel", "shape": "box", "size": [0.16, 0.16, 0.06], "position": [0.45, -0.22]}
TOP = 0.80 + 0.06  # the panel's top face (table top 0.80 m)
DOC: dict[str, Any] = {
    "name": "press_panel",
    "robot": "humanoid",
    "scene": {
        "table": {"position": [0.62, 0.0], "size": [0.60, 1.30, 0.04], "height": 0.80},
        "objects": [
            {
                "name": "book",
                "shape": "box",
                "size": [0.22, 0.11, 0.05],
                "position": [0.52, 0.40],
                "mass": 0.6,
            }
        ],
        "obstacles": [PANEL],
    },
    "mission": [{"press": {"target": "panel", "point": [0.45, -0.22, TOP], "force": 15, "duration": 1.0}}],
}


def _scenario(**press: Any) -> Scenario:
    doc = copy.deepcopy(DOC)
    doc["mission"][0]["press"].update(press)
    return from_dict(doc)


@pytest.fixture(scope="module")
def estimate() -> World:
    return build(_scenario(alternatives=["right"]))


@pytest.fixture(scope="module")
def planner(estimate: World) -> Planner:
    return Planner(estimate)


def test_reads_a_press() -> None:
    task = _scenario(alternatives=["right"]).mission[0]
    assert isinstance(task, PressTask)
    assert task.target == "panel" and task.object == "" and task.alternatives == ("right",)
    assert task.point == (0.45, -0.22, TOP) and task.normal == (0.0, 0.0, 1.0)
    assert (task.force, task.duration, task.tolerance) == (15.0, 1.0, 1.5)  # 10 % of the force
    side = _scenario(point=[0.37, -0.20, 0.83], tolerance=0.4).mission[0]  # the face towards the robot
    assert isinstance(side, PressTask)
    assert side.normal == (-1.0, 0.0, 0.0) and side.tolerance == 0.4
    assert side.alternatives == ("left", "right")  # both hands unless the block names them
    assert PressKind().moved_objects(task) == ()


@pytest.mark.parametrize(
    ("press", "path", "words"),
    [
        (
            {"target": "shelf"},
            "mission[0].press.target",
            "unknown obstacle 'shelf'; the scene's obstacles are: panel",
        ),
        ({"target": "book"}, "mission[0].press.target", "an object; a press pushes an obstacle"),
        ({"point": [0.45, -0.22, 0.87]}, "mission[0].press.point", "10.0 mm outside the surface of 'panel'"),
        ({"point": [0.45, -0.22, 0.84]}, "mission[0].press.point", "20.0 mm inside the surface of 'panel'"),
        ({"point": [0.45, -0.22]}, "mission[0].press.point", "expected"),
        ({"force": 0}, "mission[0].press.force", "0"),
        ({"force": 150}, "mission[0].press.force", "150"),
        ({"duration": 0}, "mission[0].press.duration", "0"),
        ({"duration": 61}, "mission[0].press.duration", "61"),
        ({"tolerance": 20}, "mission[0].press.tolerance", "20"),
        ({"alternatives": ["left_to_right"]}, "mission[0].press.alternatives[0]", "left_to_right"),
        ({"object": "book"}, "mission[0].press.object", "unknown key"),
    ],
)
def test_bad_press_blocks_name_the_key(press: dict[str, Any], path: str, words: str) -> None:
    with pytest.raises(ScenarioError) as info:
        _scenario(**press)
    assert info.value.key_path == path, str(info.value)
    assert words in str(info.value)


def test_a_face_looking_down_is_refused() -> None:
    doc = copy.deepcopy(DOC)
    doc["scene"]["obstacles"] = [{**PANEL, "position": [0.45, -0.22, 1.20]}]  # a shelf board in the air
    doc["mission"][0]["press"]["point"] = [0.45, -0.22, 1.17]
    with pytest.raises(ScenarioError, match="underside of 'panel'") as info:
        from_dict(doc)
    assert info.value.key_path == "mission[0].press.point"


def test_surface_closed_forms() -> None:
    yaw = math.radians(30)
    box = Body("b", "box", (0.2, 0.1, 0.04), (1.0, 2.0, 0.5), (0.0, 0.0, yaw))
    along_y = np.array([-math.sin(yaw), math.cos(yaw), 0.0])  # the box's local +y in the world
    face = surface_at(box, np.array([1.0, 2.0, 0.5]) + 0.05 * along_y)
    np.testing.assert_allclose(face.normal, along_y, atol=1e-12)
    assert face.distance == pytest.approx(0.0, abs=1e-12)
    sphere = surface_at(
        Body("s", "sphere", (0.1,), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0)), np.array([0.0, 0.3, 1.4])
    )
    np.testing.assert_allclose(sphere.normal, [0.0, 0.6, 0.8])
    assert sphere.distance == pytest.approx(0.4)
    cylinder = Body("c", "cylinder", (0.05, 0.2), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    top = surface_at(cylinder, np.array([0.01, 0.0, 1.1]))
    np.testing.assert_allclose(top.normal, [0.0, 0.0, 1.0])
    assert top.distance == pytest.approx(0.0, abs=1e-12)
    rim = surface_at(cylinder, np.array([0.0, 0.06, 1.0]))
    np.testing.assert_allclose(rim.normal, [0.0, 1.0, 0.0])
    assert rim.distance == pytest.approx(0.01)


def test_steps_lay_the_press_out(estimate: World) -> None:
    task = estimate.scenario.mission[0]
    assert isinstance(task, PressTask)
    cfg = CompositionConfig()
    steps = PressKind().steps(task, estimate, "right", cfg)
    assert [s.kind for s in steps] == ["move", "move", "press", "retreat", "home"]
    lead = hand_lead(estimate, "right")
    z = [s.targets[0].position[2] for s in steps[:4]]
    depth = 15.0 * press_compliance(estimate, "right", estimate.home_qpos(), np.array([0.0, 0.0, -1.0]))
    assert 0.0 < depth < 0.005  # a few mm: arm servos of 200-3000 Nm/rad
    np.testing.assert_allclose(
        z,
        [
            TOP + lead + cfg.approach_height,
            TOP + lead + PressKind.standoff,
            TOP + lead - depth,
            TOP + lead + cfg.approach_height,
        ],
    )
    press = steps[2]
    assert press.force == (0.0, 0.0, -15.0) and press.hold_s == 1.0  # on the panel, downwards
    assert all(s.allow_contact == ("panel",) for s in steps[1:4]) and steps[0].allow_contact == ()
    for s in steps[:4]:  # the hand points its site's z axis into the face
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, s.targets[0].quat)
        np.testing.assert_allclose(mat.reshape(3, 3)[:, 2], [0.0, 0.0, -1.0], atol=1e-9)


def _run(
    planner: Planner, task: PressTask, monkeypatch: pytest.MonkeyPatch, truth: World | None = None
) -> tuple[Any, list[tuple[float, float]], list[tuple[float, float, str]]]:
    """Plan and execute the right-hand press.

    Returns:
        The run's result, the feet's total normal force (time, N) per press tick, and the press
        behaviour's trace (time, contact force, phase).
    """
    world = planner.world
    plan = plan_alternative(planner, world, task, "right")
    truth = truth or build(world.scenario)
    feet = {g for gs in truth.ids.foot_geoms.values() for g in gs}
    floor: list[tuple[float, float]] = []
    update = press_behaviour.Press.update

    def watched(self: press_behaviour.Press) -> Any:
        status = update(self)
        pressing.append(self)
        d, wrench, total = truth.data, np.zeros(6), 0.0
        for i in range(d.ncon):
            if int(d.contact.geom[i, 0]) in feet or int(d.contact.geom[i, 1]) in feet:
                mujoco.mj_contactForce(truth.model, d, i, wrench)
                total += wrench[0]
        floor.append((float(d.time), total))
        return status

    pressing: list[press_behaviour.Press] = []
    monkeypatch.setattr(press_behaviour.Press, "update", watched)
    result = execute_plan(plan, truth, task)
    return result, floor, (pressing[-1].trace if pressing else [])


def test_presses_15_newtons_for_a_second(planner: Planner, monkeypatch: pytest.MonkeyPatch) -> None:
    task = planner.world.scenario.mission[0]
    assert isinstance(task, PressTask)
    result, floor, trace = _run(planner, task, monkeypatch)
    assert result.outcome == "success", result.message
    verdict = PressKind().verify(task, planner.world, None)
    assert verdict is not None and verdict.ok and verdict.event == "pressed"
    r = verdict.fields
    assert r["commanded_n"] == 15.0 and r["held_s"] >= 1.0 and r["samples"] >= 50
    assert 13.5 <= r["min_n"] and r["max_n"] <= 16.5  # every sample of the hold within 1.5 N
    assert abs(r["mean_n"] - 15.0) < 0.5 and r["std_n"] < 0.5
    # Independent: the floor carries the robot's weight less the press force during the hold.
    weight = planner.world.robot_mass * -planner.world.model.opt.gravity[2]
    hold = [f for t, f in floor if r["start_s"] <= t <= r["start_s"] + r["held_s"]]
    relief = weight - float(np.mean(hold))
    assert relief == pytest.approx(r["mean_n"], abs=1.5), (weight, relief)
    # The hand comes in slowly (seek_speed): the first touch does not overshoot the command much.
    peak = max(f for _, f, phase in trace if phase != "out")
    assert peak <= task.force + 2 * task.tolerance, peak


def test_more_force_than_the_arm_gives_is_reported(planner: Planner, monkeypatch: pytest.MonkeyPatch) -> None:
    task = planner.world.scenario.mission[0]
    assert isinstance(task, PressTask)
    strong = dataclasses.replace(task, force=300.0, tolerance=30.0)  # beyond the YAML's 100 N, on purpose
    result, _, _ = _run(planner, strong, monkeypatch)
    assert result.outcome == "failed"
    assert "press: force 300 N needs" in result.message and "beyond its servo's" in result.message


def test_a_panel_that_is_not_there_is_no_contact(planner: Planner, monkeypatch: pytest.MonkeyPatch) -> None:
    task = planner.world.scenario.mission[0]
    assert isinstance(task, PressTask)
    moved = build(
        planner.world.scenario, Perturbation(obstacle_offsets={"panel": (0.0, -0.30)}), kind="truth"
    )
    result, _, _ = _run(planner, task, monkeypatch, truth=moved)
    assert result.outcome == "failed"
    assert "press: no contact between the right hand and panel" in result.message


def test_only_the_pressing_hand_may_touch_the_panel(planner: Planner, estimate: World) -> None:
    task = estimate.scenario.mission[0]
    plan = plan_alternative(planner, estimate, task, "right")
    truth = build(estimate.scenario)
    truth.data.qpos[:] = plan.trajectories["right.press"].qpos[-1]
    truth.data.qpos[2] -= 0.003  # the whole robot 3 mm lower: the fingertips well into the panel
    closed = truth.profile.arms["right"].gripper.closed  # the fist the press closes
    for actuator, q in zip(truth.ids.gripper_actuators["right"], closed, strict=True):
        truth.data.qpos[truth.model.jnt_qposadr[truth.model.actuator_trnid[actuator, 0]]] = q
    mujoco.mj_forward(truth.model, truth.data)
    detector = FailureDetector(truth, distance_stride=0)
    detector.set_phase(grasping=("right", "panel"))
    assert detector.check() is None
    other = FailureDetector(truth, distance_stride=0)
    other.set_phase(grasping=("left", "panel"))
    found = other.check()
    assert found is not None and found.mode == "collision" and "panel" in found.detail


def test_the_executive_presses_and_logs_pressed(tmp_path: Path) -> None:
    doc = copy.deepcopy(DOC)
    doc["risk"] = {"rollouts": {"count": 0}}
    executive = Executive(from_dict(doc), approval="deny", truth="exact", out=tmp_path / "run")
    summary = executive.run()
    assert summary["outcome"] == "success", summary
    lines = [json.loads(line) for line in (tmp_path / "run" / "decisions.jsonl").read_text().splitlines()]
    plan = next(e for e in lines if e["kind"] == "plan" and e["name"] == "right")
    assert plan["feasible"] and plan["risk"]["collision"] < 1e-3  # the hand on the panel is planned
    (pressed,) = [e for e in lines if e["kind"] == "pressed"]
    assert pressed["target"] == "panel" and pressed["commanded_n"] == 15.0 and pressed["held_s"] >= 1.0
    assert 13.5 <= pressed["min_n"] and pressed["max_n"] <= 16.5


def test_the_press_reaction_moves_the_zmp(planner: Planner) -> None:
    world = planner.world
    task = world.scenario.mission[0]
    plan = plan_alternative(planner, world, task, "right")
    external = press_forces(plan)
    assert external is not None
    risk, uncertainty = world.scenario.risk, world.scenario.uncertainty
    pressed = assess_fall(
        world, concatenate(plan.ordered_trajectories(), plan.name), risk, uncertainty, external
    )
    # ZMP with the panel pushing the hand up by F at p: zmp - c = F (c - p) / (m g - F) (Kajita 2014, 3.2).
    press = plan.trajectories["right.press"]
    weight = world.robot_mass * -world.model.opt.gravity[2]
    lever = np.linalg.norm(press.com_path[:, :2] - press.hand_paths["right"][:, :2], axis=1)
    shift = 15.0 * lever.max() / (weight - 15.0)
    assert pressed.details["max_zmp_shift"] == pytest.approx(shift, rel=0.02)
    assert pressed.details["max_external_force"] == pytest.approx(15.0)
    # The assessment gives the fall model the press's force; at 100 N the press's knots hold the
    # plan's least margin, which shrinks by at most the 100 N shift.
    (alternative,) = assess_task(world, task)
    assert alternative.risk is not None
    assert alternative.risk.components["fall"].details["max_zmp_shift"] == pytest.approx(shift, rel=0.02)
    assert isinstance(task, PressTask)
    strong = dataclasses.replace(task, force=100.0, tolerance=10.0)
    (hard,) = assess_task(world, strong)
    assert hard.risk is not None and hard.plan is not None
    whole = concatenate(hard.plan.ordered_trajectories(), hard.plan.name)
    plain = float(assess_fall(world, whole, risk, uncertainty).details["min_margin"])
    margin = float(hard.risk.components["fall"].details["min_margin"])
    bound = 100.0 * lever.max() / (weight - 100.0) + 0.005  # the plan's own press pose differs by mm
    assert 0.01 < plain - margin <= bound, (plain, margin, bound)


def test_the_g1_presses_with_its_dex3_hand(g1_mjcf: Path) -> None:
    doc = {
        "name": "g1_press",
        "robot": {"mjcf": str(g1_mjcf), "profile": "unitree_g1"},
        "scene": {
            "table": {"position": [0.47, 0.0], "size": [0.50, 1.0, 0.04], "height": 0.66},
            "objects": [
                {
                    "name": "book",
                    "shape": "box",
                    "size": [0.14, 0.09, 0.04],
                    "position": [0.30, 0.22],
                    "mass": 0.3,
                }
            ],
            "obstacles": [
                {"name": "panel", "shape": "box", "size": [0.12, 0.12, 0.05], "position": [0.32, -0.18]}
            ],
        },
        "mission": [
            {"press": {"target": "panel", "point": [0.32, -0.18, 0.71], "force": 10, "duration": 1.0}}
        ],
    }
    scenario = from_dict(doc)
    world = build(scenario)
    task = scenario.mission[0]
    assert isinstance(task, PressTask)
    result = execute_plan(plan_alternative(Planner(world), world, task, "right"), build(scenario), task)
    assert result.outcome == "success", result.message
    verdict = PressKind().verify(task, world, None)
    assert verdict is not None and verdict.event == "pressed"
    assert (
        9.0 <= verdict.fields["min_n"] and verdict.fields["max_n"] <= 11.0 and verdict.fields["held_s"] >= 1.0
    )


def test_a_failed_press_is_a_task_failure_not_a_fall() -> None:
    """A press that cannot reach or hold its force did not do its task; no risk mode predicts
    that and the robot is standing: campaigns and rollouts must not count it as a fall."""
    from behaviours.gripper import Release
    from executive.execution.runner import behaviour_failure
    from executive.risk.fusion import observed_as
    from executive.schema.failure_modes import mode_names, mode_of_verdict

    press = Release("press", "left", "book")  # Press fails through RobotBehaviour.fail, as every behaviour
    assert press.fail("task", "press: force 3.1 N below 15 N - 1.5 N at t=2.0 s").name == "FAILURE"
    failure = behaviour_failure(press, 2.0)
    assert failure.mode == "task" and failure.detail.startswith("press: force 3.1 N")
    assert mode_of_verdict("task") is None
    assert not any("task" in observed_as(m) for m in mode_names())
