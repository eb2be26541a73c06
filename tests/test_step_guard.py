"""Live risk guards on footsteps (behaviours/guard.py around behaviours/step.py) in physics.

The references are physics and the fall model's own polygon: the guard must trip on the first
state whose CoM margin over the measured foot contacts (``support_polygon(from_contacts=True)``
of the fall model; no polygon on one foot counts as outside) is under its limit, never on a
normal step or walk at exact truth, and after a trip the robot must stand on both feet where the
same push without the guard (or with another hold) makes it fall. Numbers are printed (pytest -s -n 0)
and recorded in docs/stepping.md and docs/live_guards.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import py_trees
import pytest

from behaviours.guard import RiskGuard, install_monitor
from behaviours.robot_access import install
from behaviours.step import Step, foot_force
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.live_risk import LiveRiskMonitor, edge_margin
from executive.planning.stepping import Foothold, StepPlan, StepPlanner
from executive.planning.stepping_hold import back_to_both_feet, on_to_both_feet, single_support_left
from executive.risk.fall import support_polygon
from executive.scenario import load, loads
from executive.schema.types import Scenario
from executive.tasks.steps import build_subtree, plan_alternative
from executive.world.model import World, build
from executive.world.polygon import signed_margin
from tests.conftest import g1_floor_yaml

Status = py_trees.common.Status
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.fixture(scope="module")
def fall_steps() -> Scenario:
    return load(SCENARIOS / "fall_steps.yaml")


@pytest.fixture(scope="module")
def forward(fall_steps: Scenario) -> tuple[World, StepPlan]:
    """The humanoid's right foot 12 cm forward, planned on fall_steps' estimate (open floor)."""
    world = build(fall_steps)
    planner = StepPlanner(world)
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    return world, planner.plan_step(q, "right", Foothold("right", start.x + 0.12, start.y, start.yaw))


def _reference_margin(world: World, data: object) -> float | None:
    """The fall model's CoM margin over the measured foot contacts (None: they span no polygon)."""
    try:
        polygon = support_polygon(world, data, from_contacts=True)  # type: ignore[arg-type]
    except ValueError:
        return None
    return float(signed_margin(polygon, data.subtree_com[world.ids.base_body][:2]))  # type: ignore[attr-defined]


@dataclass
class Run:
    """A step run in physics: how the guard ended and what the robot did."""

    status: Status
    message: str
    verdict: str
    fell: str | None
    loads: tuple[float, float]  # N on the left and right foot at the end
    weight: float  # N
    trip_tick: int = -1  # the tick the guard tripped (-1: never)
    tripped_margin: float | None = None
    # per tick from the second: the reference margin of the state it checked (None: no polygon)
    # and whether the plan had one foot on the floor
    margins: list[tuple[float | None, bool]] = field(default_factory=list)


def _run(
    scenario: Scenario,
    plan: StepPlan,
    *,
    guarded: bool,
    push: tuple[float, float, float] = (0.0, 0.0, 0.0),
    at: float = 0.0,
    hold: str = "auto",
    truth: World | None = None,
) -> Run:
    """One guarded (or unguarded) step on a fresh exact truth; a 0.2 s push on the pelvis from
    ``at`` (s); then 5 s more of physics (holding) to see the robot stand or fall."""
    truth = truth if truth is not None else build(scenario)
    robot = SimulatedRobot(truth)
    install(robot)
    install_monitor(LiveRiskMonitor(build(scenario), scenario.risk.guard) if guarded else None)
    step = Step("step", plan, hold=hold)
    guard = RiskGuard(step, side=plan.swing, kind="step", obj="")
    tree = py_trees.trees.BehaviourTree(guard)
    tree.setup()
    base, data = truth.ids.base_body, truth.data
    checked: list[tuple[float | None, bool]] = []  # per tick: the state it checked, one foot or two
    state: float | None = None
    tick, tripped_at, ended = 0, -1, -1.0
    while robot.time < (plan.duration + 3.0 if ended < 0 else ended + 5.0):
        data.xfrc_applied[base, :3] = push if at <= robot.time < at + 0.2 else (0.0, 0.0, 0.0)
        if ended < 0:
            tree.tick()
            if tick:
                checked.append((state, step.support_required))
            if guard.tripped is not None and tripped_at < 0:
                tripped_at = tick
            if guard.status != Status.RUNNING:
                ended, end = robot.time, (guard.status, guard.feedback_message)
            tick += 1
        if robot.advance() is not None:  # a detector's failure: the step sees it on its next tick
            if ended < 0:
                tree.tick()
                ended, end = robot.time, (guard.status, guard.feedback_message)
            break
        state = _reference_margin(truth, data)
    assert ended >= 0, "the step did not end"
    weight = truth.robot_mass * float(np.linalg.norm(truth.model.opt.gravity))
    left, right = (foot_force(robot, side)[0] for side in ("left", "right"))
    tripped = guard.tripped
    return Run(
        status=end[0],
        message=end[1],
        verdict=guard.verdict,
        fell=robot.failure.detail if robot.failure is not None else None,
        loads=(left, right),
        weight=weight,
        trip_tick=tripped_at,
        tripped_margin=tripped.com_margin if tripped is not None else None,
        margins=checked,
    )


def _crossed(margin: float | None, one_foot: bool, limit: float) -> bool:
    """Whether a state's reference margin is under the limit (no polygon on one foot: outside)."""
    return (margin is None and one_foot) or (margin is not None and margin < limit)


def _check_tripped_at_the_crossing(run: Run, limit: float) -> None:
    """The guard failed on the tick that checked the first state whose margin crossed the limit."""
    assert run.trip_tick >= 1, run.message
    states = run.margins[: run.trip_tick]  # the states the guards checked, the last its trip's
    assert _crossed(*states[-1], limit), states[-3:]
    assert not any(_crossed(m, one, limit) for m, one in states[:-1]), "a crossing the guard missed"
    reference = states[-1][0]
    if reference is not None:
        assert run.tripped_margin == pytest.approx(reference, abs=1e-9)
    else:  # a foot on its edge: minus the CoM's distance to the contacts
        assert run.tripped_margin is not None and run.tripped_margin <= 0.0


def _on_both_feet(run: Run) -> bool:
    """Standing, each foot carrying at least 5 % of the weight (benchmarks/bench_step_hold.py)."""
    return run.fell is None and min(run.loads) >= 0.05 * run.weight


def test_edge_margin_is_minus_the_distance_to_the_contacts() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        a, b = rng.normal(size=2), rng.normal(size=2)
        points = np.array([a, a + 0.3 * (b - a), b])[rng.permutation(3)]  # in a line
        x = rng.normal(size=2)
        dense = a + np.linspace(0.0, 1.0, 20001)[:, None] * (b - a)
        reference = -float(np.hypot(*(dense - x).T).min())
        assert edge_margin(points, x) == pytest.approx(reference, abs=1e-4)
        assert edge_margin(points[:1], x) == pytest.approx(-float(np.hypot(*(points[0] - x))))
    assert edge_margin(np.zeros((0, 2)), np.zeros(2)) == -math.inf


def test_the_set_down_follows_the_plans_own_knots(forward: tuple[World, StepPlan]) -> None:
    """Back: the step's knots backwards to its start; on: forwards to its end; each from where it is."""
    _, plan = forward
    swing = plan.phases[2].trajectory
    t = 0.4 * swing.duration
    back_s, on_s = single_support_left(plan, 2, t)
    assert back_s == pytest.approx(plan.phases[1].trajectory.duration + t)
    assert on_s == pytest.approx(swing.duration - t + plan.phases[3].trajectory.duration)
    back = back_to_both_feet(plan, 2, t)
    assert [(p.name, p.support) for p in back] == [("set_down", ("left",)), ("shift_home", ("left", "right"))]
    assert np.allclose(back[0].trajectory.qpos[0], swing.sample(t))
    assert np.allclose(back[-1].trajectory.qpos[-1], plan.phases[0].trajectory.qpos[0])  # as it stood
    assert back[0].trajectory.duration == pytest.approx(back_s)
    on = on_to_both_feet(plan, 2, t)
    assert [p.name for p in on] == ["set_down", "shift_back"]
    assert np.allclose(on[0].trajectory.qpos[0], swing.sample(t))
    assert np.allclose(on[-1].trajectory.qpos[-1], plan.final_qpos)
    assert on[0].trajectory.duration == pytest.approx(on_s)
    assert [p.name for p in back_to_both_feet(plan, 0, 1.0)] == ["shift_home"]  # a weight shift undone
    assert on_to_both_feet(plan, 0, 1.0) == () and back_to_both_feet(plan, 4, 1.0) == ()


def test_a_normal_step_does_not_trip(fall_steps: Scenario, forward: tuple[World, StepPlan]) -> None:
    _, plan = forward
    run = _run(fall_steps, plan, guarded=True)
    one_foot = [m for m, one in run.margins if one]
    print(f"least CoM margin on one foot {min(m for m in one_foot if m is not None) * 1000:.1f} mm")
    assert run.status == Status.SUCCESS, run.message
    assert None not in one_foot  # the stance sole spans a polygon all the while
    assert run.fell is None


def test_a_push_towards_the_swing_foot_trips_and_the_foot_is_put_down(
    fall_steps: Scenario, forward: tuple[World, StepPlan]
) -> None:
    """250 N for 0.2 s on the pelvis mid-swing, towards the lifted foot: unguarded the robot
    lands off its foothold and falls; the guard trips the moment the stance foot rolls onto its
    edge, and the robot, tipping towards the lifted foot, is let onto it (the plain hold). Played
    along the plan instead, the foot comes down too late."""
    _, plan = forward
    at = sum(p.trajectory.duration for p in plan.phases[:2]) + 0.5 * plan.phases[2].trajectory.duration
    push = (0.0, -250.0, 0.0)
    unguarded = _run(fall_steps, plan, guarded=False, push=push, at=at)
    print(f"unguarded: {unguarded.message}; {unguarded.fell}")
    assert unguarded.fell is not None and unguarded.fell.startswith("fall")
    run = _run(fall_steps, plan, guarded=True, push=push, at=at)
    print(f"guarded: {run.message}; feet carry {run.loads[0]:.0f} N, {run.loads[1]:.0f} N")
    _check_tripped_at_the_crossing(run, fall_steps.risk.guard.min_com_margin)
    assert run.status == Status.FAILURE and run.verdict == "guard"
    assert run.message.startswith("guard: ") and "right foot put down where it is" in run.message
    assert _on_both_feet(run), run
    along = _run(fall_steps, plan, guarded=True, push=push, at=at, hold="plan")
    print(f"along the plan: {along.message}; {along.fell}")
    assert along.fell is not None


def test_a_push_backwards_trips_and_the_step_is_set_down_along_its_plan(
    fall_steps: Scenario, forward: tuple[World, StepPlan]
) -> None:
    """250 N backwards mid-swing: the robot does not tip towards the lifted foot, so the step's
    own knots set it down (the shorter way: on to its foothold) and shift the weight onto both."""
    _, plan = forward
    at = sum(p.trajectory.duration for p in plan.phases[:2]) + 0.5 * plan.phases[2].trajectory.duration
    run = _run(fall_steps, plan, guarded=True, push=(-250.0, 0.0, 0.0), at=at)
    print(f"guarded: {run.message}; feet carry {run.loads[0]:.0f} N, {run.loads[1]:.0f} N")
    _check_tripped_at_the_crossing(run, fall_steps.risk.guard.min_com_margin)
    assert run.verdict == "guard" and "right foot set down on its foothold" in run.message
    assert _on_both_feet(run), run


@pytest.mark.parametrize(
    ("mission", "sides"),
    [("walk_to_table", ("left_first",)), ("fall_steps", ("right_first",))],
)
def test_walks_at_exact_truth_do_not_trip(mission: str, sides: tuple[str, ...]) -> None:
    """The bundled walks, every footstep guarded, on the exact truth: no trip; the least CoM
    margin and clearance the guards saw are printed."""
    from executive.planning.planner import Planner

    scenario = load(SCENARIOS / f"{mission}.yaml")
    estimate, truth = build(scenario), build(scenario)
    plan = plan_alternative(Planner(estimate), estimate, scenario.mission[0], sides[0])
    robot = SimulatedRobot(truth)
    install(robot)
    install_monitor(LiveRiskMonitor(estimate, scenario.risk.guard))
    root = build_subtree(plan, guard=True)
    guards = [n for n in root.iterate() if isinstance(n, RiskGuard)]
    assert len(guards) == len(plan.walks[plan.steps[0].name]) >= 2
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    clearance, margin = math.inf, math.inf
    while robot.time < plan.duration + 10.0:
        tree.tick()
        for guard in guards:
            verdict = guard.last_verdict
            if guard.status == Status.RUNNING and verdict is not None:
                clearance = min(clearance, verdict.min_distance)
                margin = min(margin, verdict.com_margin if verdict.com_margin is not None else math.inf)
        if root.status != Status.RUNNING:
            break
        robot.advance()
    least = f"least clearance {clearance * 1000:.0f} mm, CoM margin {margin * 1000:.1f} mm"
    print(f"{mission}: {len(guards)} footsteps, {least}")
    assert root.status == Status.SUCCESS, [g.feedback_message for g in guards]
    assert all(g.tripped is None for g in guards)
    assert robot.failure is None


def test_a_walk_carrying_an_object_is_guarded_with_it_in_hand(fall_steps: Scenario) -> None:
    """A walk whose step carries an object (a side-step holding a book): its footsteps' guards
    take the object as carried (on the robot's side, the hand allowed to touch it), on the walk's
    very knots (the memo's key)."""
    from dataclasses import replace

    from executive.planning.planner import Planner

    estimate = build(fall_steps)
    plan = plan_alternative(Planner(estimate), estimate, fall_steps.mission[0], "right_first")
    walk = plan.steps[0]
    carrying = replace(plan, steps=(replace(walk, carried=("left", "book")),))
    guards = [n for n in build_subtree(carrying, guard=True).iterate() if isinstance(n, RiskGuard)]
    assert guards and all(g.motion.trajectory.carried == ("left", "book") for g in guards)
    assert all(g.motion.trajectory.qpos is plan.trajectories[walk.name].qpos for g in guards)
    monitor = LiveRiskMonitor(estimate, fall_steps.risk.guard)
    allowed = guards[0].allow(monitor)
    assert allowed and all("book" in pair for pair in allowed)  # the hand's pairs with the book
    plain = [n for n in build_subtree(plan, guard=True).iterate() if isinstance(n, RiskGuard)]
    assert plain[0].motion.trajectory.carried is None and plain[0].allow(monitor) == frozenset()


def _g1_plan(g1_mjcf: Path) -> tuple[Scenario, StepPlan]:
    scene = g1_floor_yaml(g1_mjcf)
    scenario = loads(scene, source="g1_floor.yaml")
    world = build(scenario)
    planner = StepPlanner(world)
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    return scenario, planner.plan_step(q, "right", Foothold("right", start.x + 0.10, start.y, start.yaw))


@pytest.mark.parametrize(
    ("push", "other"),
    [((0.0, -40.0, 0.0), "plan"), ((-70.0, 0.0, 0.0), "freeze")],
    ids=["towards the swing foot", "backwards"],
)
def test_the_g1_stands_where_the_other_hold_falls(
    g1_mjcf: Path, push: tuple[float, float, float], other: str
) -> None:
    """The G1 (soft servos, a 6 cm sole) pushed mid-swing: the rule keeps it on both feet where
    the other hold lets it fall (along the plan when it tips towards the lifted foot, the plain
    hold when it does not: on one foot its servos alone do not hold it up). The guard's CoM limit
    there is the sole's (13 mm), not ``min_com_margin`` (20 mm), which a 1.5 cm CoM error crosses
    on a step that succeeds (docs/stepping.md)."""
    scenario, plan = _g1_plan(g1_mjcf)
    assert plan.sole_margin < scenario.risk.guard.min_com_margin
    at = sum(p.trajectory.duration for p in plan.phases[:2]) + 0.5 * plan.phases[2].trajectory.duration
    run = _run(scenario, plan, guarded=True, push=push, at=at)
    print(f"auto: {run.message}; {run.fell}")
    _check_tripped_at_the_crossing(run, plan.sole_margin)
    assert run.verdict == "guard" and _on_both_feet(run), run
    worse = _run(scenario, plan, guarded=True, push=push, at=at, hold=other)
    print(f"{other}: {worse.message}; {worse.fell}")
    assert worse.fell is not None
