"""The safe posture (executive/robot/posture.py) in the planner, the fall detector and the fall model.

References: the pelvis heights of the plans themselves (read from their qpos), MuJoCo physics
(a servoed squat, the turned-book alternatives executed with truth = estimate), a closed-form
Gaussian tail and Monte Carlo for the fall model's posture term.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import mink
import mujoco
import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.stats import norm

from executive.decision.assessment import concatenate
from executive.errors import RobotProfileError
from executive.execution.runner import execute_plan
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.detectors import FailureDetector
from executive.planning.limits import PelvisHeightLimit
from executive.planning.planner import HandTarget, Planner, PlanningError
from executive.planning.timing import Trajectory
from executive.risk.fall import assess_fall, support_polygon
from executive.robot.posture import SafePosture, standing_pelvis_height
from executive.robot.profile import loads_profile
from executive.scenario import load, loads
from executive.schema.types import RiskConfig, Uncertainty
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build
from executive.world.polygon import signed_margin

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"


def _turned_book(yaw_deg: float = 30.0) -> str:
    text = (SCENARIOS / "book_transfer.yaml").read_text()
    assert "orientation: 0 " in text
    return text.replace("orientation: 0 ", f"orientation: {yaw_deg:g} ")


def _with_posture(world: World, **limits: float) -> World:
    """The same world, its robot's safe posture replaced (the planner and the models read it)."""
    profile = dataclasses.replace(world.profile, safe_posture=SafePosture(**limits))
    return dataclasses.replace(world, profile=profile)


def _pelvis(plan_trajectories: list[Trajectory], world: World) -> np.ndarray:
    adr = int(world.model.jnt_qposadr[world.model.body_jntadr[world.ids.base_body]]) + 2
    return np.concatenate([t.qpos[:, adr] for t in plan_trajectories])


@pytest.fixture(scope="module")
def turned() -> World:
    return build(loads(_turned_book(), source="turned_book.yaml", base_dir=SCENARIOS))


# --- planner ----------------------------------------------------------------------------------


def test_turned_book_left_is_refused_with_the_posture_reason_and_the_free_plan_falls(turned: World) -> None:
    """The left carry of the turned book needs a squat; the reason names its depth.

    The depth is checked against the plan the planner makes without the limit (a robot whose
    posture allows 1 m): its lowest pelvis height, read from its qpos. That plan, executed
    with truth = estimate, is a fall for the detector, and the fall model predicts it.
    """
    task = turned.scenario.mission[0]
    strict = _with_posture(turned, max_pelvis_drop=0.05)  # a robot allowed a 5 cm squat
    posture = strict.profile.safe_posture
    with pytest.raises(PlanningError) as info:
        plan_alternative(Planner(strict), strict, task, "left")
    message = str(info.value)
    print(message)
    free_world = _with_posture(turned, max_pelvis_drop=1.0)
    free = plan_alternative(Planner(free_world), free_world, task, "left")
    standing = standing_pelvis_height(turned.model, turned.ids.keyframe, turned.ids.base_body)
    depth = standing - float(np.min(_pelvis(free.ordered_trajectories(), turned)))
    assert depth > posture.fall_pelvis_drop  # deeper than the detector allows, not just the planner
    assert "needs the pelvis lower than the safe posture allows" in message
    assert f"takes the pelvis {depth * 100:.0f} cm below standing" in message
    assert f"the safe posture allows {posture.max_pelvis_drop * 100:.0f} cm" in message
    assert "'left.transfer'" in message
    # The fall model on the estimate (the default posture) sees the free plan cross the floor.
    whole = concatenate(free.ordered_trajectories(), "left")
    fall = assess_fall(strict, whole, turned.scenario.risk, turned.scenario.uncertainty)
    sigma = turned.scenario.uncertainty.com
    floor = standing - posture.fall_pelvis_drop
    expected = norm.cdf((floor - (standing - depth)) / sigma)
    print(f"free plan: depth {depth:.3f} m, P(fall) {fall.probability:.4f} (pelvis term {expected:.4f})")
    assert fall.details["probability_pelvis"] == pytest.approx(expected, rel=1e-9)
    assert fall.probability >= expected > 0.5
    # Physics, truth = estimate: the detector calls the free plan's squat a fall.
    result = execute_plan(free, build(turned.scenario), task)
    print(result.outcome, result.message)
    assert result.failure is not None and result.failure.mode == "fall"
    assert "pelvis dropped" in result.failure.detail


def test_posture_limit_caps_the_pelvis_in_the_plan(turned: World) -> None:
    """With a 10 cm posture the same carry plans, every knot's pelvis inside the posture."""
    world = _with_posture(turned, max_pelvis_drop=0.10)
    planner = Planner(world)
    plan = plan_alternative(planner, world, world.scenario.mission[0], "left")
    heights = _pelvis(plan.ordered_trajectories(), world)
    standing = standing_pelvis_height(world.model, world.ids.keyframe, world.ids.base_body)
    print(f"capped plan: lowest pelvis {heights.min():.4f} m, standing {standing:.4f} m")
    assert heights.min() >= standing - 0.10
    assert heights.min() < standing - 0.05  # the limit is what holds it (the 5 cm posture refuses it)


def test_pelvis_limit_row_against_finite_differences() -> None:
    """-G dq is the pelvis's rise for a small step dq (mj_integratePos), h the damped gap."""
    world = build(load("book_transfer"))
    model = world.model
    q = world.home_qpos()
    configuration = mink.Configuration(model)
    configuration.update(q)
    z = float(configuration.data.xpos[world.ids.base_body][2])
    limit = PelvisHeightLimit(model, world.ids.base_body, z - 0.03, gain=0.5, recovery=0.002)
    constraint = limit.compute_qp_inequalities(configuration, 0.025)
    assert constraint.G is not None and constraint.h is not None
    rng = np.random.default_rng(1)
    for _ in range(5):
        dq = rng.normal(0.0, 1.0, model.nv)
        eps = 1e-6
        moved = q.copy()
        mujoco.mj_integratePos(model, moved, dq, eps)
        configuration.update(moved)
        rise = (float(configuration.data.xpos[world.ids.base_body][2]) - z) / eps
        assert float(-(constraint.G @ dq)[0]) == pytest.approx(rise, rel=1e-4, abs=1e-6)
    assert constraint.h[0] == pytest.approx(0.5 * 0.03)
    # Below its floor: it must rise, by at most the recovery per step.
    configuration.update(q)
    below = PelvisHeightLimit(model, world.ids.base_body, z + 0.01, gain=0.5, recovery=0.002)
    assert below.compute_qp_inequalities(configuration, 0.025).h[0] == pytest.approx(-0.002)


def test_a_move_that_starts_squatted_below_the_posture_goes_no_lower() -> None:
    """A start below the floor (a measured squat, say) is not refused: the pelvis rises from it."""
    world = _with_posture(build(load("book_transfer")), max_pelvis_drop=0.05)
    posture = world.profile.safe_posture
    standing = standing_pelvis_height(world.model, world.ids.keyframe, world.ids.base_body)
    q = _squat(world, posture.max_pelvis_drop + 0.02)
    q[2] -= posture.max_pelvis_drop + 0.02  # the feet back on the floor
    planner = Planner(world)
    data = mujoco.MjData(world.model)
    data.qpos[:] = q
    mujoco.mj_kinematics(world.model, data)
    site = world.ids.hand_sites["left"]
    start = data.site_xpos[site].copy()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, data.site_xmat[site])
    target = HandTarget("left", start + np.array([0.05, 0.0, 0.0]), quat)
    trajectory = planner.move(q, [target], name="left.nudge")
    heights = trajectory.qpos[:, 2]
    print(f"start {standing - heights[0]:.4f} m down, lowest {standing - heights.min():.4f} m down")
    assert heights[0] == pytest.approx(standing - posture.max_pelvis_drop - 0.02, abs=1e-3)
    assert heights.min() >= heights[0] - 1e-9


@pytest.mark.parametrize("alternative", ["left", "right", "left_to_right"])
def test_turned_book_plans_succeed_in_physics_or_are_refused_for_posture(
    turned: World, alternative: str
) -> None:
    task = turned.scenario.mission[0]
    try:
        plan = plan_alternative(Planner(turned), turned, task, alternative)
    except PlanningError as exc:
        assert "needs the pelvis lower than the safe posture allows" in str(exc)
        return
    result = execute_plan(plan, build(turned.scenario), task)
    print(alternative, result.outcome, result.message)
    assert result.success, result.message


# --- detector: a planned squat against the safe posture -----------------------------------------


def _squat(world: World, drop: float) -> np.ndarray:
    """Leg angles of a squat that keeps the feet flat under the hips and lowers the pelvis by ``drop``.

    Knee bent further, hip and ankle pitch turned so the foot keeps its place and its
    orientation (the three pitch angles' sum unchanged); forward kinematics with the pelvis
    fixed, the foot's rise is the pelvis's drop once the feet stand on the floor.
    """
    model = world.model
    q0 = world.home_qpos()
    data = mujoco.MjData(model)
    foot = model.body(world.profile.feet["left"].body).id

    def adr(side: str, joint: str) -> int:
        return int(model.jnt_qposadr[model.joint(f"{side}_{joint}").id])

    def pose(knee: float, hip: float) -> np.ndarray:
        q = q0.copy()
        for side in ("left", "right"):
            q[adr(side, "knee")] += knee
            q[adr(side, "hip_pitch")] += hip
            q[adr(side, "ankle_pitch")] -= hip + knee
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        return q

    pose(0.0, 0.0)
    ref = data.xpos[foot].copy()

    def settle(knee: float) -> tuple[np.ndarray, float]:
        def dx(hip: float) -> float:
            pose(knee, hip)
            return float(data.xpos[foot][0] - ref[0])

        q = pose(knee, brentq(dx, -1.5, 0.5))
        return q, float(data.xpos[foot][2] - ref[2])

    knee = brentq(lambda k: settle(k)[1] - drop, 0.0, 1.5)
    return settle(knee)[0]


def _hold_squat(world: World, drop: float) -> tuple[FailureDetector, float, float]:
    """Servo from standing into the squat (1.5 s ramp), hold 1.5 s; (detector, lowest pelvis,
    smallest CoM margin in the contacts' support polygon)."""
    world.reset()
    detector = FailureDetector(world)
    robot = SimulatedRobot(world, control_dt=0.02, detector=detector)
    q0, q1 = world.home_qpos(), _squat(world, drop)
    lowest, margin = math.inf, math.inf
    for k in range(150):
        s = min(1.0, (k + 1) / 75.0)
        robot.set_joint_targets((1.0 - s) * q0 + s * q1)
        if robot.advance() is not None:
            break
        data = world.data
        lowest = min(lowest, float(data.xpos[world.ids.base_body][2]))
        com = data.subtree_com[world.ids.base_body][:2]
        margin = min(margin, signed_margin(support_polygon(world, data, True), com))
    return detector, lowest, margin


def test_a_squat_within_the_posture_is_not_a_fall_and_one_beyond_its_tolerance_is() -> None:
    # A 5 cm posture: a squat past its 10 cm fall floor keeps the hands above the table.
    world = _with_posture(build(load("book_transfer")), max_pelvis_drop=0.05)
    posture = world.profile.safe_posture
    standing = standing_pelvis_height(world.model, world.ids.keyframe, world.ids.base_body)
    within, low_in, margin_in = _hold_squat(world, 0.9 * posture.max_pelvis_drop)
    print(
        f"squat {0.9 * posture.max_pelvis_drop:.3f} m: pelvis {standing - low_in:.4f} m down, "
        f"CoM margin {margin_in:.3f} m"
    )
    assert within.failure is None
    assert standing - low_in == pytest.approx(0.9 * posture.max_pelvis_drop, abs=0.01)  # a real squat
    deep = posture.fall_pelvis_drop + 0.02
    beyond, _, margin_out = _hold_squat(world, deep)
    print(f"squat {deep:.3f} m: {beyond.failure}; CoM margin {margin_out:.3f} m")
    assert beyond.failure is not None and beyond.failure.mode == "fall"
    assert "pelvis dropped" in beyond.failure.detail
    # Below the deepest posture the planner allows by more than the tolerance: measured, not assumed.
    assert world.data.xpos[world.ids.base_body][2] < standing - posture.fall_pelvis_drop
    assert margin_out > 0.05  # balanced all the same: the detector's floor is the posture's, not a collapse


# --- fall model -------------------------------------------------------------------------------


def test_fall_model_posture_term_against_monte_carlo() -> None:
    """A knot whose pelvis is 1.5 sigma above the detector's floor: P by closed form and by sampling."""
    world = build(load("book_transfer"))
    posture = world.profile.safe_posture
    sigma = 0.01
    standing = standing_pelvis_height(world.model, world.ids.keyframe, world.ids.base_body)
    floor = standing - posture.fall_pelvis_drop
    q = np.tile(world.home_qpos(), (3, 1))
    adr = int(world.model.jnt_qposadr[world.model.body_jntadr[world.ids.base_body]]) + 2
    q[1, adr] = floor + 1.5 * sigma  # the whole robot lower: the support polygon and CoM xy unchanged
    times = np.array([0.0, 0.5, 1.0])
    traj = Trajectory(
        name="sink", times=times, qpos=q, hand_paths={}, com_path=np.zeros((3, 3)), carried=None
    )
    report = assess_fall(world, traj, RiskConfig(), Uncertainty(com=sigma))
    rng = np.random.default_rng(0)
    samples = 400_000
    lowest = float(np.min(q[:, adr])) + rng.normal(0.0, sigma, samples)
    mc = float(np.mean(lowest < floor))
    se = math.sqrt(mc * (1.0 - mc) / samples)
    print(f"posture term {report.details['probability_pelvis']:.5f}, MC {mc:.5f} +- {se:.5f}")
    assert report.details["probability_pelvis"] == pytest.approx(norm.cdf(-1.5), rel=1e-9)
    assert abs(report.details["probability_pelvis"] - mc) < 4.0 * se
    support = report.details["probability_support"]
    assert report.probability == pytest.approx(1.0 - (1.0 - support) * (1.0 - mc), abs=4.0 * se)


def test_profile_sets_the_safe_posture_and_rejects_a_bad_one() -> None:
    text = (SCENARIOS / "robots" / "humanoid" / "profile.yaml").read_text()
    base = loads_profile(text, base_dir=SCENARIOS / "robots" / "humanoid")
    assert base.safe_posture == SafePosture(0.10, 20.0, 0.05, 10.0)
    lines = [line for line in text.splitlines() if not line.startswith("safe_posture:")]
    custom = "\n".join([*lines, "safe_posture: {max_pelvis_drop: 0.08, tilt_tolerance_deg: 5}"])
    profile = loads_profile(custom, base_dir=SCENARIOS / "robots" / "humanoid")
    assert profile.safe_posture.max_pelvis_drop == 0.08 and profile.safe_posture.fall_tilt_deg == 25.0
    with pytest.raises(RobotProfileError, match="max_pelvis_drop"):
        loads_profile(
            "\n".join([*lines, "safe_posture: {max_pelvis_drop: -0.1}"]),
            base_dir=SCENARIOS / "robots" / "humanoid",
        )
    with pytest.raises(RobotProfileError, match="pelvis_drop"):
        loads_profile(
            "\n".join([*lines, "safe_posture: {pelvis_drop: 0.1}"]),
            base_dir=SCENARIOS / "robots" / "humanoid",
        )
