"""What a step leaves the balance and what the balance measures (the Unitree G1, when its model is there).

* The step planner keeps the support feet's ankle hinges inside their range by a balance reserve
  (executive/planning/stepping_ankles.py) and leans the torso where that leaves the CoM short; a
  G1 step then stands a 2 cm CoM error towards the swing foot, on which it fell before.
* The balance measures the CoM as a robot can: its own model's CoM plus the error its feet's
  force sensors show (executive/execution/com_estimate.py), and drives the stance foot's measured
  CoP to the commanded one (executive/execution/cop_tracking.py).
* The step task reads the stance from the feet, not from the pelvis the balance shifts.

Numbers in docs/stepping.md ("The balance reserve", "What the balance measures").
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import py_trees
import pytest

from behaviours.robot_access import install
from behaviours.step import Step
from executive.execution.com_estimate import CoMEstimate, foot_pressure
from executive.execution.cop_tracking import CoPTracking
from executive.execution.simulated import SimulatedRobot
from executive.planning.limits import SupportPolygon
from executive.planning.stepping import Foothold, StepPlan, StepPlanner
from executive.planning.stepping_geometry import stance_footholds, stance_of
from executive.scenario import loads
from executive.tasks.step import feet_stance
from executive.world.model import Perturbation, World, build
from tests.conftest import G1_MJCF, g1_floor_yaml

Status = py_trees.common.Status


@pytest.fixture(scope="module")
def g1() -> tuple[str, World, StepPlanner]:
    if not G1_MJCF.is_file():
        pytest.skip(f"the shared Unitree G1 model is not at {G1_MJCF}")
    scene = g1_floor_yaml(G1_MJCF, com=0.01)
    world = build(loads(scene, source="g1_floor.yaml"))
    return scene, world, StepPlanner(world)


def _right_step(world: World, planner: StepPlanner, dx: float = 0.10) -> StepPlan:
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    return planner.plan_step(q, "right", Foothold("right", start.x + dx, start.y, start.yaw))


def test_the_stance_ankles_keep_their_balance_reserve(g1: tuple[str, World, StepPlanner]) -> None:
    """In every knot of a planned G1 step each held foot's ankle hinges stay inside their range by
    their reserve; the roll's is about what a 2-sigma pelvis shift over a 0.72 m leg and the CoP
    at the sole's 3 cm edge under 34 kg on a kp 500 servo take (by hand 1.6 + 1.2 deg); the torso
    leans instead of the legs and comes back upright."""
    _, world, planner = g1
    limit = planner.ik.ankle_limit
    assert limit is not None
    roll = next(h for h in limit.ankles["left"] if "roll" in h.joint)
    by_hand = 2 * 0.01 / 0.72 + world.robot_mass * 9.81 * 0.03 / 500.0
    assert limit.reserves[roll.joint_id] == pytest.approx(by_hand, rel=0.2)
    plan = _right_step(world, planner)
    for phase in plan.phases:
        for side in phase.support:
            for hinge in limit.ankles[side]:
                lower, upper = limit.bounds(hinge)
                angles = phase.trajectory.qpos[:, hinge.qadr]
                assert angles.min() >= lower - 2e-3 and angles.max() <= upper + 2e-3, (
                    phase.name,
                    hinge.joint,
                )
    waist = world.model.joint("waist_roll_joint")
    adr = int(world.model.jnt_qposadr[waist.id])
    lift = plan.phase("lift").trajectory
    assert abs(math.degrees(lift.qpos[-1, adr])) > 3.0  # leaning over the stance foot
    assert abs(math.degrees(plan.phase("shift_back").trajectory.qpos[-1, adr])) < 0.5  # upright again
    planner.footholds(world.home_qpos())  # the planner's configuration at the start: the sole there
    middle = planner.sole_polygon(("left",)).centre
    assert np.linalg.norm(lift.com_path[-1, :2] - middle) < 0.006  # the CoM over the sole's middle


def test_a_g1_step_stands_a_2cm_com_error_towards_the_swing_foot(g1: tuple[str, World, StepPlanner]) -> None:
    """The truth's CoM 2 cm towards the swing foot (two sigma): the step succeeds, the CoM well
    inside the stance sole while the foot is up (before the reserve it fell in the swing)."""
    scene, world, planner = g1
    plan = _right_step(world, planner)
    truth = build(loads(scene, source="g1_floor.yaml"), Perturbation(com_offset=(0.0, -0.02)), kind="truth")
    robot = SimulatedRobot(truth)
    install(robot)
    step = Step("step", plan)
    tree = py_trees.trees.BehaviourTree(step)
    tree.setup()
    while robot.time < plan.duration + 5.0:
        tree.tick()
        if step.status != Status.RUNNING:
            break
        robot.advance()
    assert step.status == Status.SUCCESS, (step.feedback_message, robot.failure)
    assert step.min_com_margin > 0.015, step.min_com_margin  # the sole's middle is 32 mm inside
    assert step.landing_error[0] < 0.01


def test_the_com_estimate_finds_the_model_error_from_the_feet(g1: tuple[str, World, StepPlanner]) -> None:
    """Standing on its servos, the robot's estimate of its CoM error (from its model's CoM and the
    feet's CoP) converges on the truth's CoM offset, which it is not told."""
    scene, _, _ = g1
    offset = (0.012, -0.015)
    truth = build(loads(scene, source="g1_floor.yaml"), Perturbation(com_offset=offset), kind="truth")
    robot = SimulatedRobot(truth)
    estimate = CoMEstimate(truth)
    omega = math.sqrt(9.81 / float(truth.data.subtree_com[truth.ids.base_body][2]))
    com, _ = estimate.update(truth.data, omega)
    assert np.allclose(estimate.bias, 0.0)  # the model's CoM until the feet show otherwise
    own = estimate.model
    assert own is not truth.model
    assert np.linalg.norm(com[:2] - truth.data.subtree_com[truth.ids.base_body][:2] + offset) < 0.002
    while robot.time < 1.5:
        robot.advance()
        com, _ = estimate.update(truth.data, omega)
    assert np.linalg.norm(estimate.bias - offset) < 0.002, estimate.bias
    assert np.linalg.norm(com[:2] - truth.data.subtree_com[truth.ids.base_body][:2]) < 0.002


def test_the_cop_tracking_moves_the_measured_cop_to_the_command(g1: tuple[str, World, StepPlanner]) -> None:
    """The left ankle roll's tracking (its servo's target offset integrating the measured moment
    error, as on one foot) brings the left foot's measured CoP 10 mm inside its sole's middle while
    the right foot holds the body up; a command beyond the sole is held at the sole's edge."""
    scene, _, _ = g1
    truth = build(loads(scene, source="g1_floor.yaml"))
    robot = SimulatedRobot(truth)
    controller = robot.controller
    model, data, floor = truth.model, truth.data, truth.ids.floor_geom
    roll = int(model.joint("left_ankle_roll_joint").id)
    index = int(np.flatnonzero(model.actuator_trnid[controller.actuators, 0] == roll)[0])
    tracking = CoPTracking(truth, {"left": [(index, roll)]}, controller.kp, rate=1.0)
    soles = list(truth.ids.foot_geoms["left"])
    sole = SupportPolygon.from_feet(model, data, soles)
    omega = math.sqrt(9.81 / 0.69)
    _, start = foot_pressure(model, data, set(soles), floor)
    inside = math.inf
    for shift in (-0.010, -0.2):
        command = np.array([start[0], sole.centre[1] + shift])
        for _ in range(150):  # 3 s
            ctrl = controller.joint_ctrl(truth.home_qpos(), data)
            offsets = tracking.update(data, "left", command, omega, robot.control_dt)
            data.ctrl[controller.actuators] = np.clip(
                ctrl + offsets, controller.ctrl_low, controller.ctrl_high
            )
            for _ in range(robot.substeps):
                mujoco.mj_step(model, data)
        _, cop = foot_pressure(model, data, set(soles), floor)
        edge = SupportPolygon.from_feet(model, data, soles)
        if shift > -0.05:
            assert abs(cop[1] - command[1]) < 0.002, (cop, command)
            inside = cop[1]
        else:  # beyond the sole: the CoP out to the inner contacts' line (the spheres' footprint
            # reaches their radius further), never past the sole
            assert cop[1] < inside - 0.005 and 0.0 <= edge.margin(cop) < 0.015, (cop, edge.margin(cop))
    assert abs(offsets[index]) <= tracking.bound[roll] + 1e-12


def test_the_stance_is_read_from_the_feet(g1: tuple[str, World, StepPlanner]) -> None:
    """``stance_of`` inverts ``stance_footholds``; the step task's stance of the standing robot is
    its pelvis's place, and it stays with the feet when the pelvis leans over them."""
    _, world, planner = g1
    feet = planner.footholds(world.home_qpos())
    offsets = {side: Foothold(side, 0.01 * i, 0.12 * (1 - 2 * i), 0.05 * i) for i, side in enumerate(feet)}
    for x, y, yaw in ((0.0, 0.0, 0.0), (0.4, -0.2, 0.7), (-1.0, 2.0, -3.0)):
        got = stance_of(stance_footholds(x, y, yaw, offsets), offsets)
        assert got[0] == pytest.approx(x) and got[1] == pytest.approx(y)
        assert math.remainder(got[2] - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    assert feet_stance(world) == pytest.approx((0.0, 0.0), abs=1e-3)
    plan = _right_step(world, planner)
    lean = build(world.scenario)
    lean.data.qpos[:] = plan.phase("lift").trajectory.qpos[-1]  # the pelvis over the left foot
    mujoco.mj_kinematics(lean.model, lean.data)
    left = planner.footholds(world.home_qpos())["left"]
    assert abs(float(lean.data.xpos[world.ids.base_body][1]) - left.y) < 0.05  # the pelvis is off ...
    x, y = feet_stance(lean)  # ... but the stance is where the feet stand: the right foot lifted 5 cm
    assert abs(y) < 0.005 and abs(x) < 0.005, (x, y)
