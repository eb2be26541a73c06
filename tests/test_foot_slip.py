"""The foot-slip detector (executive/monitoring/detector_foot_slip.py) on MuJoCo physics.

Every slip here is made by MuJoCo: the floor's friction lowered (the floor's geom given the
contact's friction by its priority) under a robot pushed or walking. The references are the
physics itself: the foot body's displacement and turn since it started standing, its speed by
finite differences, the contact points of a foot rolled onto its edge. Numbers are printed
(pytest -s -n 0) and recorded in docs/detectors.md ("Foot slip") and docs/stepping.md.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import py_trees
import pytest

from behaviours.guard import install_monitor
from behaviours.robot_access import install
from behaviours.step import Step, foot_force
from executive import Executive
from executive.decision.physics_check import with_rollouts
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.detectors import DetectorError, DetectorThresholds, FailureDetector
from executive.monitoring.live_risk import LiveRiskMonitor
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner
from executive.scenario import load, loads
from executive.schema.failure_modes import mode_of_verdict
from executive.schema.types import Scenario
from executive.tasks.steps import build_subtree, plan_alternative
from executive.world.heading import yaw_of
from executive.world.model import World, build

Status = py_trees.common.Status
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
ICE = 0.005  # the floor's sliding friction on which the humanoid's first weight shift slides


def slippery(world: World, friction: float) -> World:
    """``world`` with its floor's sliding friction ``friction`` in every contact with it."""
    floor = world.ids.floor_geom
    world.model.geom_friction[floor, 0] = friction
    world.model.geom_priority[floor] = int(world.model.geom_priority.max()) + 1  # the floor's wins
    return world


def _foot(world: World, side: str) -> int:
    return int(world.model.body(world.profile.feet[side].body).id)


@pytest.fixture(scope="module")
def fall_steps() -> Scenario:
    return load(SCENARIOS / "fall_steps.yaml")


@pytest.fixture(scope="module")
def walk(fall_steps: Scenario) -> AlternativePlan:
    """fall_steps' 0.4 m walk, right foot first, planned on its estimate."""
    estimate = build(fall_steps)
    return plan_alternative(Planner(estimate), estimate, fall_steps.mission[0], "right_first")


def test_the_limits_come_from_the_sole_and_bad_ones_are_refused() -> None:
    world = build(load("book_transfer"))
    detector = FailureDetector(world)
    half = world.model.geom_size[world.model.geom("left_sole").id]  # the sole box's half sizes
    assert detector.foot_slip == pytest.approx(0.4 * half[1], rel=1e-4)  # 0.4 of its half width
    assert detector.foot_slip_yaw_deg == pytest.approx(math.degrees(0.4 * half[1] / half[0]), rel=1e-4)
    print(f"humanoid: {detector.foot_slip * 1000:.2f} mm, {detector.foot_slip_yaw_deg:.2f} deg")
    assert FailureDetector(world, DetectorThresholds(foot_slip=0.01)).foot_slip_yaw_deg == pytest.approx(
        math.degrees(0.01 / half[0]), rel=1e-4
    )
    for field in ("foot_slip", "foot_slip_yaw_deg", "foot_slip_load"):
        for bad in (0.0, -0.01, math.nan, math.inf):
            with pytest.raises(DetectorError, match=f"DetectorThresholds.{field}"):
                FailureDetector(world, DetectorThresholds(**{field: bad}))  # type: ignore[arg-type]
    with pytest.raises(DetectorError, match="no foot 'middle'; the robot has: left, right"):
        detector.set_phase(support=("middle",))
    assert mode_of_verdict("slip") == "fall"


def _push(
    world: World, force: tuple[float, float, float], thresholds: DetectorThresholds | None = None
) -> tuple[FailureDetector, list[tuple[float, np.ndarray, float]]]:
    """Push the standing robot's pelvis with a constant ``force`` (N along x and y, then N m
    about z) on the world's floor (fall_steps': open) until a failure or 3 s; per control period
    the time, both feet's body xy and the left foot's yaw."""
    detector = FailureDetector(world, thresholds, distance_stride=0)
    robot = SimulatedRobot(world, detector=detector)
    feet = [_foot(world, s) for s in ("left", "right")]
    data = world.data
    data.xfrc_applied[world.ids.base_body, :2] = force[:2]
    data.xfrc_applied[world.ids.base_body, 5] = force[2]
    trace = []
    while robot.time < 3.0 and robot.advance() is None:
        trace.append((robot.time, data.xpos[feet, :2].copy(), yaw_of(data.xquat[feet[0]])))
    data.xfrc_applied[:] = 0.0
    return detector, trace


def test_a_standing_robot_pushed_along_a_slippery_floor_slips() -> None:
    """60 N sideways on a floor of friction 0.01: the feet slide; the slip is the first failure,
    as far as the foot's body slid since the first check (the robot slides as a whole) and as
    fast."""
    world = slippery(build(load(SCENARIOS / "fall_steps.yaml")), 0.01)
    detector, trace = _push(world, (0.0, 60.0, 0.0))
    failure, slip = detector.failure, detector.slipped
    assert failure is not None and failure.mode == "slip" and slip is not None, failure
    print(failure.detail)
    k = ("left", "right").index(slip.side)
    moved = float(
        np.hypot(*(world.data.xpos[_foot(world, slip.side), :2] - trace[0][1][k]))
    )  # since it stood
    assert slip.distance == pytest.approx(moved, abs=0.001)
    (t0, before, _), (t1, after, _) = trace[-2], trace[-1]
    finite = float(np.hypot(*(after[k] - before[k]))) / (t1 - t0)  # over the period before the trip
    assert slip.speed == pytest.approx(finite, rel=0.3)
    assert detector.foot_slip < slip.distance < detector.foot_slip + slip.speed * 0.02 + 0.001
    assert failure.bodies == (world.profile.feet[slip.side].body,)
    assert f"the {slip.side} foot" in failure.detail and "mm/s" in failure.detail


def test_a_foot_turned_about_the_vertical_slips() -> None:
    """A torque about the vertical on the pelvis, the slide limit out of reach: the turn trips
    it, as far as the foot's yaw turned since the first check (when it started standing)."""
    world = slippery(build(load(SCENARIOS / "fall_steps.yaml")), 0.01)
    limits = DetectorThresholds(foot_slip=0.5, foot_slip_yaw_deg=5.0)
    detector, trace = _push(world, (0.0, 0.0, 40.0), limits)
    failure, slip = detector.failure, detector.slipped
    assert failure is not None and failure.mode == "slip" and slip is not None, failure
    print(failure.detail)
    assert slip.side == "left" and slip.distance < 0.5  # the first foot in the table's order
    turned = abs(math.remainder(yaw_of(world.data.xquat[_foot(world, "left")]) - trace[0][2], math.tau))
    assert slip.turn == pytest.approx(turned, abs=math.radians(0.05))
    assert math.radians(5.0) < slip.turn < math.radians(6.0)


def test_a_foot_that_carries_too_little_is_measured_afresh() -> None:
    """The same push with a load limit above the robot's weight: no foot counts as standing on the
    floor, so the feet slide far and nothing is called a slip."""
    world = slippery(build(load(SCENARIOS / "fall_steps.yaml")), 0.01)
    start = world.data.xpos[_foot(world, "left"), :2].copy()
    detector, _ = _push(world, (0.0, 60.0, 0.0), DetectorThresholds(foot_slip_load=1.5))
    moved = float(np.hypot(*(world.data.xpos[_foot(world, "left"), :2] - start)))
    print(f"slid {moved * 1000:.0f} mm unseen")
    assert moved > 3 * detector.foot_slip and detector.slipped is None
    assert detector.failure is None or detector.failure.mode != "slip"


def test_a_foot_rolled_onto_its_edge_is_no_slip() -> None:
    """Pushed sideways on the normal floor the robot tips over its left sole's outer edge: the
    sole's middle swings past a 2 mm slide limit while its edge stays where it stood (the edge's
    middle, from the sole box and the foot's pose); the verdict is the fall, not a slip."""
    world = build(load(SCENARIOS / "fall_steps.yaml"))
    model, data, left = world.model, world.data, _foot(world, "left")
    sole = model.geom("left_sole").id
    edge = model.geom_pos[sole] + model.geom_size[sole] * np.array([0.0, 1.0, -1.0])  # outer, bottom

    def edge_xy() -> np.ndarray:
        return (data.xpos[left] + data.xmat[left].reshape(3, 3) @ edge)[:2]

    start = edge_xy()
    detector, _ = _push(world, (0.0, 400.0, 0.0), DetectorThresholds(foot_slip=0.002))
    failure, now = detector.failure, detector.foot_slip_now("left")
    assert failure is not None, "the push did not topple the robot"
    middle = detector.largest_slip[0].distance
    moved = float(np.hypot(*(edge_xy() - start)))
    print(failure.detail)
    print(
        f"the sole's middle slid {middle * 1000:.1f} mm, its edge {moved * 1000:.2f} mm, its contacts "
        f"{now.distance * 1000 if now else math.nan:.2f} mm"
    )
    assert failure.mode == "fall" and detector.slipped is None
    assert middle > 0.002 and moved < 0.001  # the middle moved past the limit, the edge did not
    assert (
        now is not None
        and now.distance == pytest.approx(moved, abs=0.001)
        and now.load > detector.foot_slip_load
    )


def _walk(
    scenario: Scenario, plan: AlternativePlan, truth: World, after_s: float = 3.0
) -> tuple[SimulatedRobot, py_trees.behaviour.Behaviour, list[Step], list[tuple[float, np.ndarray]]]:
    """The walk on ``truth`` as the executive runs it (every footstep guarded), then ``after_s``
    more seconds of physics (holding) once it ended. Returns the robot, the walk's root, its
    steps and per control period the time and the left foot's body xy."""
    robot = SimulatedRobot(truth)
    install(robot)
    install_monitor(LiveRiskMonitor(build(scenario), scenario.risk.guard))
    root = build_subtree(plan, guard=True)
    steps = [n for n in root.iterate() if isinstance(n, Step)]
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    left = _foot(truth, "left")
    trace = [(robot.time, truth.data.xpos[left, :2].copy())]
    ended = math.inf
    while robot.time < min(plan.duration + 10.0, ended + after_s):
        if ended == math.inf:
            tree.tick()
            if root.status != Status.RUNNING:
                ended = robot.time
        robot.advance()
        trace.append((robot.time, truth.data.xpos[left, :2].copy()))
    return robot, root, steps, trace


def test_the_stance_foot_slides_in_a_weight_shift_on_ice_and_the_robot_holds(
    fall_steps: Scenario, walk: AlternativePlan
) -> None:
    """On a floor of friction 0.005 the left foot slides out under the first weight shift: the
    step stops with ``slip`` naming the foot, how far (as far as the foot's body slid since the
    walk began) and how fast, holds as a guard's trip holds, and the robot then stands on both
    feet for 3 s."""
    truth = slippery(build(fall_steps), ICE)
    robot, root, steps, trace = _walk(fall_steps, walk, truth)
    first = steps[0]
    print(first.feedback_message)
    assert root.status == Status.FAILURE and first.verdict == "slip" and first.slipped is not None
    slip = robot.detector.slipped
    assert slip is not None and slip.side == "left" and slip.since == pytest.approx(trace[1][0])
    assert first.feedback_message.startswith(
        first.slipped.detail + " in the 'shift' phase; "
    )  # the weight shift
    assert first.feedback_message.startswith("slip: the left foot (left_foot) slid ")
    assert "both feet" in first.feedback_message
    at = next(xy for t, xy in trace if t >= slip.time - 1e-9)
    moved = float(np.hypot(*(at - trace[1][1])))
    final = float(np.hypot(*(trace[-1][1] - trace[1][1])))
    print(
        f"the left foot slid {slip.distance * 1000:.1f} mm (its body {moved * 1000:.1f} mm) at "
        f"{slip.speed * 1000:.0f} mm/s, t={slip.time:.2f} s; {final * 1000:.1f} mm at t={trace[-1][0]:.1f} s"
    )
    assert slip.distance == pytest.approx(moved, abs=0.001)
    assert robot.failure is None  # standing after the hold: no fall, no second slip
    weight = truth.robot_mass * float(np.linalg.norm(truth.model.opt.gravity))
    assert min(foot_force(robot, s)[0] for s in ("left", "right")) >= 0.05 * weight


def test_the_executive_logs_the_slip_and_ends_the_task(tmp_path: Path) -> None:
    """The executive on the icy floor (fall_steps' walk, right foot first: its dry run on the
    estimate's normal floor passes): the task fails at once (a slip counts as the fall mode,
    which ends a task), and its ``failure`` line says which foot slipped and how the robot held."""
    text = (SCENARIOS / "fall_steps.yaml").read_text()
    assert "      to: [0.40, 0.0]\n" in text
    text = text.replace(
        "      to: [0.40, 0.0]\n", "      to: [0.40, 0.0]\n      alternatives: [right_first]\n"
    )
    scenario = with_rollouts(loads(text, source="fall_steps_right_first.yaml"), 0)
    executive = Executive(scenario, approval="auto", truth="exact", out=tmp_path / "run", background=False)
    assert executive.truth is not None
    slippery(executive.truth, ICE)
    summary = executive.run()
    assert summary["outcome"] != "success", summary
    lines = [json.loads(s) for s in (tmp_path / "run" / "decisions.jsonl").read_text().splitlines()]
    failures = [line for line in lines if line["kind"] == "failure"]
    assert len(failures) == 1, failures  # terminal: nothing else was tried
    failure = failures[0]
    print(failure["detail"])
    assert failure["mode"] == "slip" and failure["detail"].startswith("slip: the left foot (left_foot) slid ")
    assert "both feet" in failure["detail"]
    outcome = next(line for line in lines if line["kind"] == "outcome")
    assert outcome["outcome"] == "failed" and outcome["failure"]["mode"] == "slip"


def test_the_walk_on_the_normal_floor_never_comes_near_a_slip(
    fall_steps: Scenario, walk: AlternativePlan
) -> None:
    truth = build(fall_steps)
    robot, root, _, _ = _walk(fall_steps, walk, truth, after_s=0.0)
    slide, turn = robot.detector.largest_slip
    print(
        f"normal floor: largest slide {slide.distance * 1000:.2f} mm ({slide.side}, t={slide.time:.2f} s), "
        f"turn {math.degrees(turn.turn):.2f} deg; limits {robot.detector.foot_slip * 1000:.1f} mm, "
        f"{robot.detector.foot_slip_yaw_deg:.1f} deg"
    )
    assert root.status == Status.SUCCESS and robot.failure is None
    assert (
        slide.distance < robot.detector.foot_slip / 4
        and math.degrees(turn.turn) < robot.detector.foot_slip_yaw_deg / 4
    )
