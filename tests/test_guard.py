"""Live risk guards (behaviours/guard.py, executive/monitoring/live_risk.py) in real physics.

The reference for "before a collision happens" is the physics itself: the same
disturbance without the guard ends in a contact the collision detector reports,
and with the guard no robot or book geom ever touches the stack.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import py_trees
import pytest

from behaviours.guard import RiskGuard, install_monitor
from behaviours.robot_access import install
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.detectors import FailureDetector
from executive.monitoring.live_risk import LiveRiskMonitor
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner
from executive.scenario import load
from executive.tasks.steps import build_subtree, plan_alternative
from executive.world.model import World, build

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


# --- the cost of a live check: memoised planned knots, the CoM margin in plain floats ---------


def _window_reference(
    estimate: World,
    traj: object,
    measured: np.ndarray,
    t: float,
    allow: frozenset[tuple[str, str]],
    model: object = None,
) -> float:
    """The least distance now and over the look-ahead, every knot computed afresh by a collision
    model of the estimate as it is now (a new one unless given; no memo anywhere)."""
    from executive.risk.collision import CollisionModel

    model = model or CollisionModel(estimate, estimate.scenario.risk)
    times, qpos = traj.times, traj.qpos  # type: ignore[attr-defined]
    carried = traj.carried[1] if traj.carried else None  # type: ignore[attr-defined]
    lookahead = estimate.scenario.risk.guard.lookahead_s
    k_now = min(int(np.searchsorted(times, t)), len(times) - 1)
    now = measured.copy()
    for adr in estimate.ids.object_qpos.values():
        now[adr : adr + 7] = qpos[k_now][adr : adr + 7]
    best = model.knot(now, carried=carried, allow=allow).distance  # type: ignore[attr-defined]
    for k in np.nonzero((times > t) & (times <= t + lookahead))[0]:
        best = min(best, model.knot(qpos[k], carried=carried, allow=allow).distance)  # type: ignore[attr-defined]
    return float(best)


def test_memoised_look_ahead_equals_a_fresh_computation_and_follows_a_moved_obstacle(
    plan: AlternativePlan,
) -> None:
    scenario = load("book_transfer")
    estimate = build(scenario)
    monitor = LiveRiskMonitor(estimate, scenario.risk.guard)
    traj = plan.trajectories["left.transfer"]
    carried = traj.carried[1] if traj.carried else None
    allow = monitor.collision.step_allow("left", "carry", "book", (), traj.carried)
    monitor.prepare(traj.qpos, carried=carried, allow=allow)
    prepared = monitor.knots_computed
    assert prepared == len(traj.times)
    rng = np.random.default_rng(0)
    for t in np.linspace(0.0, traj.duration, 7):
        measured = traj.sample(t)
        measured[7:] += rng.normal(0.0, 0.01, len(measured) - 7)  # tracking error of the joints
        d = monitor.clearance(measured, traj.qpos, traj.times, t, carried=carried, allow=allow)[0]
        assert d == pytest.approx(_window_reference(estimate, traj, measured, t, allow), abs=1e-9)
    assert monitor.knots_computed == prepared  # the look-ahead came from the memo
    # The estimate changes: the stack slides into the carry lane. The next check sees it.
    t = 0.5 * traj.duration
    measured = traj.sample(t)
    before = monitor.clearance(measured, traj.qpos, traj.times, t, carried=carried, allow=allow)[0]
    _move_stack(estimate, SHIFT)
    d, _, _, env = monitor.clearance(measured, traj.qpos, traj.times, t, carried=carried, allow=allow)
    assert monitor.knots_computed > prepared  # recomputed against the moved stack
    assert d == pytest.approx(_window_reference(estimate, traj, measured, t, allow), abs=1e-9)
    print(f"look-ahead clearance {before * 1000:.1f} mm, {d * 1000:.1f} mm to {env} after the move")
    assert env == "book_stack" and d < before


def test_a_bounded_distance_now_decides_as_the_exact_one(plan: AlternativePlan) -> None:
    """Along the carry, with tracking error, and with the stack moved into the lane halfway: each
    check's clearance is the exact one, or a lower bound of it that clears the limit; so the
    verdicts are those of the exact distance. Most checks away from the stack need no exact
    distance now."""
    from executive.risk.collision import CollisionModel

    scenario = load("book_transfer")
    estimate = build(scenario)
    limit = scenario.risk.guard.min_distance
    monitor = LiveRiskMonitor(estimate, scenario.risk.guard)
    traj = plan.trajectories["left.transfer"]
    carried = traj.carried[1] if traj.carried else None
    allow = monitor.collision.step_allow("left", "carry", "book", (), traj.carried)
    reference = CollisionModel(estimate, scenario.risk)
    rng = np.random.default_rng(1)
    error = np.zeros(estimate.model.nq)
    bounded = exact_trips = 0
    for i, t in enumerate(np.arange(0.0, traj.duration, 0.02)):
        if i == 40:
            _move_stack(estimate, SHIFT)
            reference = CollisionModel(estimate, scenario.risk)
        error[7:] = 0.9 * error[7:] + rng.normal(0.0, 0.002, len(error) - 7)  # smooth tracking error
        measured = traj.sample(t) + error
        before = monitor.now_bounded
        d = monitor.clearance(
            measured, traj.qpos, traj.times, t, carried=carried, allow=allow, at_least=limit
        )[0]
        exact = _window_reference(estimate, traj, measured, t, allow, reference)
        if monitor.now_bounded > before:
            bounded += 1
            # never above the exact value; below it only where both clear the limit
            assert d <= exact + 1e-12
            assert d == pytest.approx(exact, abs=1e-9) or d >= limit
        else:
            assert d == pytest.approx(exact, abs=1e-9)
        assert (d < limit) == (exact < limit)
        exact_trips += exact < limit
    print(f"{bounded} of {i + 1} checks bounded, {monitor.now_exact} exact; {exact_trips} below the limit")
    assert bounded > (i + 1) // 2
    assert exact_trips > 0  # the moved stack does come within the limit


def test_interior_margin_equals_the_polygon_modules_margin() -> None:
    """Without building the hull, the same margin as ``signed_margin(convex_hull(...))`` wherever
    it answers, and it answers for every point clearly inside; random point sets, repeated
    points, collinear sets, and ulp-jittered rectangles (two soles' contact corners)."""
    from executive.monitoring.live_risk import interior_margin
    from executive.world.polygon import convex_hull, signed_margin

    rng = np.random.default_rng(7)
    answered = inside = 0
    sets = []
    for n in (3, 4, 8, 16):
        for _ in range(80):
            pts = rng.uniform(-0.2, 0.2, (n, 2))
            if rng.random() < 0.3:
                pts = np.vstack([pts, pts[:2]])
            sets.append(pts)
    soles = np.array([[x, y] for x in (-0.126, 0.134) for y in (-0.21, -0.06, 0.06, 0.21)])
    for _ in range(80):
        sets.append(soles * (1.0 + rng.normal(0.0, 1e-15, soles.shape)))
    sets.append(np.column_stack([np.linspace(0, 1, 6), 0.5 * np.linspace(0, 1, 6)]))  # collinear
    for pts in sets:
        hull = convex_hull(pts)
        for x in rng.uniform(-0.3, 0.3, (5, 2)):
            got = interior_margin(pts, x)
            reference = signed_margin(hull, x) if len(hull) >= 3 else None
            if got is not None:
                answered += 1
                assert reference is not None and got == pytest.approx(reference, abs=1e-12)
            if reference is not None and reference > 1e-8:
                inside += 1
                assert got is not None
    print(f"{answered} margins answered, {inside} points clearly inside")
    assert answered > 300


def test_com_margin_equals_the_fall_models_polygon_on_real_contacts() -> None:
    """The guard's CoM margin against ``support_polygon`` of the fall model, on the contacts of a
    robot that leans forward until its support breaks up (then both say: no polygon)."""
    from executive.risk.fall import support_polygon
    from executive.world.polygon import signed_margin

    scenario = load("book_transfer")
    truth, estimate = build(scenario), build(scenario)
    monitor = LiveRiskMonitor(estimate, scenario.risk.guard)
    # A limit the leaning robot's margins cross (they stay above the scenario's 20 mm while a
    # polygon exists), so the bound is tested on both sides of it.
    limit = 0.10
    guard_monitor = LiveRiskMonitor(estimate, replace(scenario.risk.guard, min_com_margin=limit))
    below = 0  # states whose margin is under the guard's limit
    robot = SimulatedRobot(truth)
    target = truth.home_qpos()
    target[truth.model.jnt_qposadr[truth.model.joint("waist_pitch").id]] += 0.3  # lean forward
    robot.set_joint_targets(target)
    margins, none = 0, 0
    for _ in range(40):
        robot.advance()
        try:
            polygon = support_polygon(truth, truth.data, from_contacts=True)
        except ValueError:
            assert monitor.com_margin(truth, truth.data) is None
            none += 1
            continue
        reference = signed_margin(polygon, truth.data.subtree_com[truth.ids.base_body][:2])
        assert monitor.com_margin(truth, truth.data) == pytest.approx(reference, abs=1e-12)
        # The guard's form: a certified lower bound when it clears the limit, else exact; a
        # test against the limit decides as the exact margin does.
        got = guard_monitor.com_margin(truth, truth.data, at_least=limit)
        assert got is not None and got <= reference + 1e-12
        assert (got >= limit) == (reference >= limit)
        if got < limit:
            assert got == pytest.approx(reference, abs=1e-12)
        below += reference < limit
        margins += 1
    print(
        f"{margins} margins compared, {none} states without a polygon, "
        f"{guard_monitor.com_bounded} answered by the bound, {below} under the limit"
    )
    assert margins >= 3
    assert guard_monitor.com_bounded >= 3 and below >= 3


def test_the_bound_now_holds_when_the_carried_object_and_the_arm_move_apart(plan: AlternativePlan) -> None:
    """The certified bound against exact distances when the measured robot and the planned pose
    of the carried object both move, each its own way (the carried object is checked against the
    robot's own geoms too, a pair whose two ends move, so the bound takes the object's move on
    both sides). Random joint offsets up to 0.02 rad and object shifts up to 1.5 cm about carry
    knots; the limit at 0 so the bound answers whenever it can. Reference: a fresh collision
    model's exact distance. (In these draws the nearest pair is rarely the object against the
    robot, so this does not single out that term; it checks the bound as a whole.)"""
    from executive.risk.collision import CollisionModel

    scenario = load("book_transfer")
    estimate = build(scenario)
    monitor = LiveRiskMonitor(estimate, scenario.risk.guard)
    reference = CollisionModel(estimate, scenario.risk)
    traj = plan.trajectories["left.transfer"]
    carried = traj.carried[1] if traj.carried else None
    assert carried is not None
    allow = monitor.collision.step_allow("left", "carry", "book", (), traj.carried)
    adr = estimate.ids.object_qpos[carried]
    rng = np.random.default_rng(7)
    bounded = 0
    for k in range(0, len(traj.qpos), max(1, len(traj.qpos) // 12)):
        base = traj.qpos[k]
        knot = traj.qpos[k : k + 1]
        monitor.clearance(base, knot, np.zeros(1), 0.0, carried=carried, allow=allow, at_least=0.0)
        for _ in range(15):
            measured = base.copy()
            measured[7:] += rng.uniform(-0.02, 0.02, len(base) - 7)
            planned = base.copy()
            planned[adr : adr + 3] += rng.uniform(-0.015, 0.015, 3)
            for a in estimate.ids.object_qpos.values():
                measured[a : a + 7] = planned[a : a + 7]
            before = monitor.now_bounded
            d = monitor.clearance(
                measured, planned[None, :], np.zeros(1), 0.0, carried=carried, allow=allow, at_least=0.0
            )[0]
            exact = reference.knot(measured, carried=carried, allow=allow).distance
            assert d <= exact + 1e-12
            assert (d < 0.0) == (exact < 0.0)
            bounded += monitor.now_bounded > before
    print(f"{bounded} bounded answers, all at or below the exact distance")
    assert bounded > 20
