"""Live risk guards (behaviours/guard.py, executive/live_risk.py) in real physics.

The reference for "before a collision happens" is the physics itself: the same
disturbance without the guard ends in a contact the collision detector reports,
and with the guard no robot or book geom ever touches the stack.
"""

from __future__ import annotations

import mujoco
import numpy as np
import py_trees
import pytest

from behaviours.guard import RiskGuard, install_monitor
from behaviours.robot_access import install
from executive.composition import AlternativePlan, build_subtree, plan_alternative
from executive.detectors import FailureDetector
from executive.execution import SimulatedRobot
from executive.live_risk import LiveRiskMonitor
from executive.planning import Planner
from executive.scenario import load
from executive.world import World, build

Status = py_trees.common.Status
SHIFT = (-0.10, 0.0)  # the stack slides 10 cm towards the robot, into the carry lane


@pytest.fixture(scope="module")
def plan() -> AlternativePlan:
    scenario = load("book_transfer")
    estimate = build(scenario)
    return plan_alternative(Planner(estimate), estimate, scenario.mission[0], "left")


def _move_stack(world: World, shift: tuple[float, float]) -> None:
    body = world.model.geom_bodyid[world.ids.obstacle_geoms["book_stack"]]
    world.model.body_pos[body][:2] += shift
    mujoco.mj_kinematics(world.model, world.data)


def _stack_contacts(world: World) -> int:
    """Contacts between the stack and anything but the table (robot or book)."""
    stack = world.ids.obstacle_geoms["book_stack"]
    table = set(world.ids.table_geoms)
    n = 0
    for c in world.data.contact[: world.data.ncon]:
        pair = {int(c.geom1), int(c.geom2)}
        if stack in pair and not (pair - {stack}) <= table:
            n += 1
    return n


def _guarded_tree(
    plan: AlternativePlan, guarded: bool
) -> tuple[World, World, SimulatedRobot, py_trees.behaviour.Behaviour, py_trees.trees.BehaviourTree]:
    """Truth and estimate of book_transfer, the robot, and the plan's subtree with guards (a monitor
    on the blackboard when ``guarded``, else none: the guards only pass their child through)."""
    scenario = load("book_transfer")
    truth, estimate = build(scenario), build(scenario)
    robot = SimulatedRobot(truth, detector=FailureDetector(truth))
    install(robot)
    install_monitor(LiveRiskMonitor(estimate, scenario.risk.guard) if guarded else None)
    root = build_subtree(plan, guard=True)
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    return truth, estimate, robot, root, tree


def _run(plan: AlternativePlan, guarded: bool, shift_at: str) -> tuple[Status, SimulatedRobot, str, int]:
    """Execute ``plan``; when step ``shift_at`` starts, the stack moves in the truth and the estimate."""
    truth, estimate, robot, root, tree = _guarded_tree(plan, guarded)
    moved = False
    touches = 0
    message = ""
    while truth.data.time < plan.duration + 5.0:
        tree.tick()
        tip = root.tip()
        if not moved and tip is not None and tip.name == shift_at:
            _move_stack(truth, SHIFT)
            _move_stack(estimate, SHIFT)
            moved = True
        if root.status != Status.RUNNING:
            message = tip.feedback_message if tip is not None else ""
            break
        robot.advance()
        touches += _stack_contacts(truth)
    # After a trip the robot holds: a second of holding must not end in the stack either.
    for _ in range(50):
        robot.advance()
        touches += _stack_contacts(truth)
    assert moved
    return root.status, robot, message, touches


@pytest.mark.slow
def test_obstacle_moved_into_the_path_trips_the_guard_before_any_contact(plan: AlternativePlan) -> None:
    # Reference: unguarded, the same disturbance ends in a collision with the stack.
    status, robot, message, touches = _run(plan, guarded=False, shift_at="left.transfer")
    print(f"unguarded: {status.name}: {message}; stack contacts {touches}")
    assert status == Status.FAILURE
    assert robot.failure is not None and robot.failure.mode == "collision"
    assert "book_stack" in robot.failure.detail

    status, robot, message, touches = _run(plan, guarded=True, shift_at="left.transfer")
    print(f"guarded: {status.name}: {message}; stack contacts {touches}")
    assert status == Status.FAILURE
    assert message.startswith("guard:") and "book_stack" in message
    assert robot.failure is None  # no detector fired: nothing touched anything it should not
    assert touches == 0


@pytest.mark.slow
def test_guard_stays_quiet_on_an_undisturbed_run(plan: AlternativePlan) -> None:
    scenario = load("book_transfer")
    truth, _, robot, root, tree = _guarded_tree(plan, guarded=True)
    least = np.inf
    margins = []
    while truth.data.time < plan.duration + 5.0:
        tree.tick()
        for node in root.iterate():
            if isinstance(node, RiskGuard) and node.status == Status.RUNNING and node.last_verdict:
                least = min(least, node.last_verdict.min_distance)
                if node.last_verdict.com_margin is not None:
                    margins.append(node.last_verdict.com_margin)
        if root.status != Status.RUNNING:
            break
        robot.advance()
    print(f"least guarded clearance {least * 1000:.1f} mm; CoM margin {min(margins) * 1000:.1f} mm")
    assert root.status == Status.SUCCESS
    assert least >= scenario.risk.guard.min_distance
    assert min(margins) >= scenario.risk.guard.min_com_margin
