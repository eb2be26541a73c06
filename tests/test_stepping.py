"""Quasi-static stepping (executive/planning/stepping*.py, behaviours/step.py) in physics.

The bundled humanoid and the Unitree G1 (when the shared model is there) step from their standing
start in MuJoCo (the plan made on the estimate world, executed on a truth world): forward and
sideways, the fall detector silent, the foot landing near its planned foothold, the CoM inside the
stance sole while the other foot is off the floor (measured from the simulated states here, not
taken from the behaviour). Numbers are printed (pytest -s -n 0) and recorded in docs/stepping.md.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import mujoco
import numpy as np
import py_trees
import pytest

from behaviours.robot_access import install
from behaviours.step import Step, foot_force, foothold
from executive.execution.simulated import JointTargetController, SimulatedRobot
from executive.planning.limits import SupportPolygon
from executive.planning.stepping import (
    PHASES,
    Foothold,
    StepPlan,
    StepPlanner,
    StepPlanningError,
    measure_reach,
    plan_steps,
)
from executive.scenario import loads
from executive.world.model import World, build

Status = py_trees.common.Status

# Open floor: the table (which the scenario needs) stands behind the robot, out of the way.
FLOOR = """
name: step_floor
description: Stepping on open floor, a table behind the robot.
robot: {robot}
scene:
  table: {{position: [{table_x}, 0.0], size: [0.4, 0.8, 0.04], height: {height}}}
  objects:
    - {{name: book, shape: box, size: [0.14, 0.09, 0.05], position: [{book_x}, 0.2], mass: 0.3}}
  obstacles: []
mission:
  - transfer: {{object: book, to: [{book_x}, -0.2]}}
"""


def _floor(robot: str = "humanoid", table_x: float = -0.8, height: float = 0.8) -> str:
    return FLOOR.format(robot=robot, table_x=table_x, height=height, book_x=table_x + 0.1)


@pytest.fixture(scope="module")
def humanoid() -> tuple[World, StepPlanner]:
    world = build(loads(_floor(), source="step_floor.yaml"))
    return world, StepPlanner(world)


def _execute(plan: StepPlan, scenario_yaml: str) -> dict[str, float]:
    """Tick a Step behaviour on a fresh truth world; measure from its states each control period."""
    truth = build(loads(scenario_yaml, source="step_floor.yaml"))
    robot = SimulatedRobot(truth)
    install(robot)
    step = Step("step", plan)
    tree = py_trees.trees.BehaviourTree(step)
    tree.setup()
    data, base = truth.data, truth.ids.base_body
    stance_soles = truth.ids.foot_geoms[plan.stance]
    com_margin, airborne_force = math.inf, 0.0
    while robot.time < plan.duration + 5.0:
        tree.tick()
        if step.status != Status.RUNNING:
            break
        robot.advance()
        if step.phase.name in ("swing",):  # the swing foot is off the floor: it carries nothing
            airborne_force = max(airborne_force, foot_force(robot, plan.swing)[0])
        if len(step.phase.support) == 1:
            sole = SupportPolygon.from_feet(truth.model, data, stance_soles)
            com_margin = min(com_margin, sole.margin(data.subtree_com[base]))
    assert step.status == Status.SUCCESS, step.feedback_message
    assert robot.failure is None  # the fall detector (and every other) stayed silent
    final = foothold(robot, plan.swing)
    distance, turn = final.distance(plan.target)
    out = {
        "landing_mm": step.landing_error[0] * 1000,
        "landing_deg": math.degrees(step.landing_error[1]),
        "final_mm": distance * 1000,
        "final_deg": math.degrees(turn),
        "com_margin_mm": com_margin * 1000,
        "airborne_N": airborne_force,
        "pelvis_drop_mm": (plan.phases[0].trajectory.qpos[0][2] - float(data.xpos[base][2])) * 1000,
        "sim_s": robot.time,
        "planning_s": plan.planning_s,
    }
    print(plan.swing, plan.target.describe(), {k: round(v, 3) for k, v in out.items()})
    return out


def _check_step(planner: StepPlanner, world: World, swing: str, dx: float, dy: float) -> None:
    q = world.home_qpos()
    start = planner.footholds(q)[swing]
    target = Foothold(swing, start.x + dx, start.y + dy, start.yaw)
    plan = planner.plan_step(q, swing, target)
    assert [p.name for p in plan.phases] == list(PHASES)
    assert [len(p.support) for p in plan.phases] == [2, 1, 1, 1, 2]
    # The plan keeps the CoM inside the stance sole (shrunk by its margin) while a foot is up.
    planner.footholds(q)
    sole = planner.sole_polygon((plan.stance,))
    for phase in plan.phases[1:4]:
        assert phase.support == (plan.stance,)
        margins = sole.margins(phase.trajectory.com_path)
        assert margins.min() >= planner.sole_margin(sole) - 1e-6, phase.name
    m = _execute(plan, _floor())
    assert m["landing_mm"] < 15.0 and m["landing_deg"] < 2.0, m
    assert m["final_mm"] < 20.0, m
    assert m["com_margin_mm"] > 20.0, m  # the truth CoM stayed well inside the single-support polygon
    assert m["airborne_N"] == 0.0, m
    assert abs(m["pelvis_drop_mm"]) < 30.0, m


def test_a_forward_step_in_physics(humanoid: tuple[World, StepPlanner]) -> None:
    world, planner = humanoid
    _check_step(planner, world, "right", 0.12, 0.0)


def test_a_sideways_step_in_physics(humanoid: tuple[World, StepPlanner]) -> None:
    world, planner = humanoid
    _check_step(planner, world, "left", 0.0, 0.10)


def test_an_unreachable_step_is_refused_naming_what_binds(humanoid: tuple[World, StepPlanner]) -> None:
    world, planner = humanoid
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    with pytest.raises(StepPlanningError) as info:
        planner.plan_step(q, "right", Foothold("right", start.x + 1.0, start.y, 0.0))
    message = str(info.value)
    print(message)
    assert info.value.binds, message
    assert "binding:" in message and "right foot step to" in message
    assert any(word in message for word in ("joint '", "the pelvis at its lowest", "the CoM at the"))
    # A foot onto the other foot: the soles' clearance binds.
    with pytest.raises(StepPlanningError, match=r"left_sole.*right_sole|right_sole.*left_sole"):
        planner.plan_step(q, "right", Foothold("right", start.x, start.y + 0.25, 0.0))


def test_reach_is_measured_by_ik_and_a_walk_keeps_within_it(humanoid: tuple[World, StepPlanner]) -> None:
    world, planner = humanoid
    q = world.home_qpos()
    reach = measure_reach(planner, q, "right")
    print(reach)
    assert 0.2 < reach.forward < 1.0 and 0.2 < reach.backward < 1.0
    assert 0.05 < reach.inward < reach.outward  # the feet meet before the hip's range ends
    assert "sole" in reach.binds["inward"]
    plans = plan_steps(planner, q, (0.5, 0.0, 0.0))
    swings = [p.swing for p in plans]
    assert all(a != b for a, b in itertools.pairwise(swings)), swings  # alternating
    limit = planner.config.reach_fraction * reach.forward + 1e-6
    for before, plan in zip([planner.footholds(q)] + [p.footholds for p in plans], plans, strict=False):
        stance = before[plan.stance]
        ahead = (plan.target.x - stance.x) * math.cos(stance.yaw) + (plan.target.y - stance.y) * math.sin(
            stance.yaw
        )
        assert ahead <= limit
    x, y, yaw = planner.pelvis(plans[-1].final_qpos)
    assert x == pytest.approx(0.5, abs=0.02) and abs(y) < 0.02 and abs(yaw) < 0.02


def test_stance_feed_forward(humanoid: tuple[World, StepPlanner]) -> None:
    """No stance: the old numbers; one foot: the other leg carries only its own links."""
    world, _ = humanoid
    controller = JointTargetController(world)
    q = world.home_qpos()
    default = controller.leg_loads(q[None, :])
    assert np.array_equal(controller.leg_loads(q[None, :], [None]), default)
    assert np.array_equal(controller.leg_load(q), default[0])
    single = controller.leg_load(q, ["left"])
    right_leg = [
        i for i, a in enumerate(controller.actuators) if world.model.actuator(a).name.startswith("right_")
    ]
    legs = [i for i in right_leg if controller.support[i]]
    # the right leg's torques are its own links' weight (mj_rne of a leg dof: the links below it)
    data = mujoco.MjData(world.model)
    data.qpos[:] = q
    mujoco.mj_forward(world.model, data)
    gravity = np.empty(world.model.nv)
    mujoco.mj_rne(world.model, data, 0, gravity)
    assert np.allclose(single[legs], gravity[controller.dof_adr[legs]], atol=1e-9)
    assert abs(single[controller.support]).max() > 100.0  # the stance leg carries the body
    with pytest.raises(ValueError):
        controller.leg_loads(q[None, :], [["middle"]])


def test_the_g1_plans_a_step(g1_mjcf: Path) -> None:
    """The G1 plans a step and measures its reach."""
    world = build(loads(_g1_floor(g1_mjcf), source="g1.yaml"))
    planner = StepPlanner(world)
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    plan = planner.plan_step(q, "right", Foothold("right", start.x + 0.10, start.y, 0.0))
    assert plan.target.x == pytest.approx(start.x + 0.10)
    reach = measure_reach(planner, q, "left")
    assert 0.1 < reach.forward < 1.0


def _g1_floor(g1_mjcf: Path) -> str:
    return _floor(f"{{mjcf: {g1_mjcf}, profile: unitree_g1}}", -0.65, 0.66)


@pytest.mark.parametrize(("swing", "dx", "dy"), [("right", 0.10, 0.0), ("left", 0.0, -0.08)])
def test_the_g1_steps_in_physics(g1_mjcf: Path, swing: str, dx: float, dy: float) -> None:
    """The G1 (kp 500 leg servos, a 6 cm wide sole) steps forward and sideways (inward: outward
    the lifted foot cannot stay flat within its ankle roll range), held up by the ankle balance
    feedback the Step behaviour switches on."""
    scene = _g1_floor(g1_mjcf)
    world = build(loads(scene, source="g1.yaml"))
    planner = StepPlanner(world)
    q = world.home_qpos()
    start = planner.footholds(q)[swing]
    plan = planner.plan_step(q, swing, Foothold(swing, start.x + dx, start.y + dy, start.yaw))
    m = _execute(plan, scene)  # the fall detector silent, the step a success
    assert m["landing_mm"] < 10.0 and m["landing_deg"] < 1.0, m
    assert m["final_mm"] < 10.0, m
    assert m["com_margin_mm"] > 15.0, m  # the sole's middle is about 30 mm inside its edges
    assert m["airborne_N"] == 0.0, m
    assert abs(m["pelvis_drop_mm"]) < 30.0, m


def test_the_g1_falls_without_the_balance_feedback(g1_mjcf: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Its servos alone are about as stiff as gravity's toppling stiffness on one foot: it tips
    over the sole's outer edge at the end of the weight shift."""
    scene = _g1_floor(g1_mjcf)
    world = build(loads(scene, source="g1.yaml"))
    planner = StepPlanner(world)
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    plan = planner.plan_step(q, "right", Foothold("right", start.x + 0.10, start.y, start.yaw))
    monkeypatch.setattr(SimulatedRobot, "set_balance", lambda self, *args, **kwargs: None)
    robot = SimulatedRobot(build(loads(scene, source="g1.yaml")))
    install(robot)
    step = Step("step", plan)
    tree = py_trees.trees.BehaviourTree(step)
    tree.setup()
    while robot.time < plan.duration and step.status in (Status.INVALID, Status.RUNNING):
        tree.tick()
        robot.advance()
    assert robot.failure is not None and robot.failure.mode == "fall", robot.failure
    print(robot.failure.detail)


def test_the_balance_feedback_is_opt_in(humanoid: tuple[World, StepPlanner]) -> None:
    """Off (the default, and after a hold) the servos run exactly as without it."""
    world, _ = humanoid
    com = world.data.subtree_com[world.ids.base_body].copy()
    runs = []
    for mode in ("never", "off", "held"):
        robot = SimulatedRobot(build(loads(_floor(), source="step_floor.yaml")))
        if mode == "off":
            robot.set_balance(("left",), com=com)
            robot.set_balance(None)
        elif mode == "held":
            robot.set_balance(("left", "right"), com=com, com_velocity=(0.0, 0.0))
            robot.hold()
        assert robot.balance is None
        robot.set_joint_targets(world.home_qpos())
        for _ in range(10):
            robot.advance()
        runs.append(robot.data.qpos.copy())
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])
    for bad in (["middle"], [], ["left", "right", "left"]):
        with pytest.raises(ValueError):
            robot.set_balance(bad, com=com)
    with pytest.raises(ValueError):
        robot.set_balance(["left"])  # no planned CoM


def test_a_foot_off_its_foothold_fails_with_tracking(humanoid: tuple[World, StepPlanner]) -> None:
    """A landing beyond the tolerance is the robot not following its plan: ``tracking``."""
    world, planner = humanoid
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    plan = planner.plan_step(q, "right", Foothold("right", start.x + 0.10, start.y, 0.0))
    robot = SimulatedRobot(build(loads(_floor(), source="step_floor.yaml")))
    install(robot)
    step = Step("step", plan, landing_tolerance=1e-5)
    tree = py_trees.trees.BehaviourTree(step)
    tree.setup()
    while robot.time < plan.duration + 5.0:
        tree.tick()
        if step.status != Status.RUNNING:
            break
        robot.advance()
    assert step.status == Status.FAILURE
    assert step.verdict == "tracking", step.feedback_message
    assert "from its planned foothold" in step.feedback_message
    assert robot.failure is None  # it still stands (held where it was)


def test_a_walk_in_physics(humanoid: tuple[World, StepPlanner]) -> None:
    """plan_steps' steps, one Step behaviour each in a sequence, from the planned states."""
    world, planner = humanoid
    plans = plan_steps(planner, world.home_qpos(), (0.3, 0.0, math.radians(10.0)))
    truth = build(loads(_floor(), source="step_floor.yaml"))
    robot = SimulatedRobot(truth)
    install(robot)
    steps = [Step(f"step{i}", p) for i, p in enumerate(plans)]
    root = py_trees.composites.Sequence("walk", memory=True, children=steps)
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    while robot.time < sum(p.duration for p in plans) + 5.0:
        tree.tick()
        if root.status != Status.RUNNING:
            break
        robot.advance()
    errors = [round(s.landing_error[0] * 1000, 1) for s in steps]
    print(f"{len(plans)} steps, landing errors (mm) {errors}")
    assert root.status == Status.SUCCESS, [s.feedback_message for s in steps]
    assert robot.failure is None
    base = truth.data.xpos[truth.ids.base_body]
    assert base[0] == pytest.approx(0.3, abs=0.03) and abs(base[1]) < 0.03
