"""Behaviours ticked as a host would tick them: non-blocking updates, honest statuses."""

from __future__ import annotations

import time

import mujoco
import numpy as np
import py_trees
import pytest

from behaviours.gripper import Grasp
from behaviours.move_hand import MoveHand
from behaviours.robot_access import install
from executive.execution.simulated import SimulatedRobot
from executive.planning.planner import HandTarget, Planner
from executive.scenario import load
from executive.world.model import World, build

Status = py_trees.common.Status


@pytest.fixture
def world() -> World:
    return build(load("book_transfer"))


def _tick_until_done(tree: py_trees.trees.BehaviourTree, robot: SimulatedRobot, limit_s: float):  # type: ignore[no-untyped-def]
    statuses: list[Status] = []
    longest = 0.0
    while robot.time < limit_s:
        t0 = time.perf_counter()
        tree.tick()
        longest = max(longest, time.perf_counter() - t0)
        statuses.append(tree.root.status)
        if tree.root.status != Status.RUNNING:
            break
        robot.advance()
    return statuses, longest


def test_move_hand_runs_then_succeeds_and_never_blocks(world: World) -> None:
    """A 5 cm lift of the left hand, planned on the estimate, ticked against physics."""
    site = world.ids.hand_sites["left"]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, world.data.site_xmat[site])
    goal = HandTarget("left", world.data.site_xpos[site] + [0.0, 0.0, 0.05], quat)
    trajectory = Planner(world).move(world.home_qpos(), [goal], name="left.up")

    truth = build(world.scenario)
    robot = SimulatedRobot(truth, control_dt=0.02)
    install(robot)
    behaviour = MoveHand("left.up", trajectory)
    tree = py_trees.trees.BehaviourTree(behaviour)
    tree.setup()
    statuses, longest = _tick_until_done(tree, robot, trajectory.duration + 2.0)

    # RUNNING for every control period of the trajectory, then SUCCESS, nothing else.
    assert statuses[-1] == Status.SUCCESS, behaviour.feedback_message
    assert set(statuses[:-1]) == {Status.RUNNING}
    assert len(statuses) >= trajectory.duration / robot.control_dt
    # update() only samples the plan and writes targets: far below one 20 ms control period.
    assert longest < robot.control_dt, longest
    # The hand really rose by the planned 5 cm in physics (independent of the planner's records).
    assert truth.data.site_xpos[site][2] == pytest.approx(goal.position[2], abs=0.01)
    assert robot.failure is None


def test_grasp_on_empty_air_fails_naming_the_missing_hold(world: World) -> None:
    robot = SimulatedRobot(world, control_dt=0.02)
    install(robot)
    grasp = Grasp("left.grasp", "left", "book", timeout_s=1.0)
    tree = py_trees.trees.BehaviourTree(grasp)
    tree.setup()
    statuses, longest = _tick_until_done(tree, robot, 3.0)
    assert statuses[-1] == Status.FAILURE
    assert "does not hold book" in grasp.feedback_message
    assert robot.time == pytest.approx(1.0, abs=0.05)  # gave up at its timeout, not earlier
    assert longest < robot.control_dt
    # the jaws really closed (physics), they just found nothing
    assert robot.gripper_opening("left") < 0.005


def test_move_hand_streams_the_sampled_targets(world: World) -> None:
    """Each tick's target is the trajectory sampled at that tick's time, its rate the difference
    to the next tick's target, whether the clock advances one period per tick (targets sampled
    ahead) or jumps (sampled afresh at its own time); the legs' feed-forward load, computed in
    batches ahead, is the static load of that very target (leg_load, one target at a time)."""
    site = world.ids.hand_sites["right"]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, world.data.site_xmat[site])
    goal = HandTarget("right", world.data.site_xpos[site] + [0.10, -0.05, 0.15], quat)
    trajectory = Planner(world).move(world.home_qpos(), [goal], name="right.reach")

    robot = SimulatedRobot(build(world.scenario), control_dt=0.02)
    install(robot)
    behaviour = MoveHand("right.reach", trajectory)
    behaviour.initialise()
    dt, ticks = robot.control_dt, 0
    start = robot.time
    while robot.time - start < trajectory.duration:
        t = robot.time - start
        assert behaviour.update() == Status.RUNNING
        assert np.allclose(robot.q_target, trajectory.sample(t), atol=1e-12)
        rate = (trajectory.sample(t + dt) - trajectory.sample(t)) / dt
        assert np.allclose(robot.qvel_target, rate, atol=1e-9)
        exact = robot.controller.leg_load(robot.q_target)
        assert np.abs(exact).max() > 10.0  # N m: the legs carry the body
        assert np.allclose(robot._leg_load, exact, rtol=0.0, atol=1e-9)
        ticks += 1
        # The clock as the physics leaves it (MuJoCo adds the timestep per step); once, a jump.
        for _ in range(robot.substeps * (3 if ticks == 40 else 1)):
            robot.data.time += robot.model.opt.timestep
    assert ticks > 50
