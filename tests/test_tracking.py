"""The tracking mode's model against MuJoCo: the servos' static error under a known load, the stall
beyond a servo's limit, and the probability against a Monte Carlo of its own assumptions."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import yaml

from executive.execution.simulated import SimulatedRobot
from executive.planning.plan import MOVE_TOLERANCE, AlternativePlan, Step
from executive.planning.timing import Trajectory
from executive.risk.fall_force import force_scale_distribution
from executive.risk.servo import ServoSet
from executive.risk.tracking import (
    MEASURED_SIGMA,
    RESIDUAL_SCALE,
    HandEnd,
    MoveEnd,
    TrackingPrediction,
    predict_tracking,
    tracking_report,
)
from executive.scenario import from_dict, load
from executive.world.model import World, build


def _posture(world: World, joints: dict[str, float]) -> np.ndarray:
    """The world's home pose with ``joints`` set (radians)."""
    q = world.data.qpos.copy()
    for name, value in joints.items():
        q[world.model.jnt_qposadr[world.model.joint(name).id]] = value
    return q


def _held(world: World, q: np.ndarray, side: str, force: np.ndarray, seconds: float = 3.0) -> np.ndarray:
    """Where the ``side`` hand site settles (world, m) when the robot's servos hold ``q`` and
    ``force`` (N, world) pushes on that site: MuJoCo's contact dynamics, the bundled servos."""
    model, data = world.model, world.data
    mujoco.mj_resetData(model, data)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    robot = SimulatedRobot(world)
    robot.set_joint_targets(q)
    palm = int(model.body(world.profile.arms[side].hand_body).id)
    site = world.ids.hand_sites[side]
    while data.time < seconds:
        data.xfrc_applied[palm, :3] = force  # at the site: the force and its moment about the palm's CoM
        data.xfrc_applied[palm, 3:] = np.cross(data.site_xpos[site] - data.xipos[palm], force)
        robot.advance()
        if robot.failure is not None:
            break
    return np.asarray(data.site_xpos[site], dtype=float).copy()


def _predicted(world: World, q: np.ndarray, side: str, force: np.ndarray) -> tuple[np.ndarray, float]:
    """The servo statics' hand displacement under ``force`` at the site (m) and the largest
    |torque| / limit of a servo holding it."""
    model = world.model
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, world.ids.hand_sites[side])
    servos = ServoSet.of(world)
    hold = servos.hold(model, q, (jac.T @ force)[None, :])
    dq = hold.total(servos.dofs, np.array([1.0]))
    return jac @ dq, float(np.max(np.abs(hold.torque[0] + hold.torque[1]) / hold.limit))


def _against_mujoco(
    world: World, q: np.ndarray, side: str, force: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(predicted, observed) hand displacement of ``force``: the observed one less the unloaded
    hold's (the soft floor contact sinks the feet a little whatever the load)."""
    loaded = _held(world, q, side, force)
    unloaded = _held(world, q, side, np.zeros(3))
    return _predicted(world, q, side, force)[0], loaded - unloaded


def test_the_statics_predict_the_humanoid_s_hand_under_a_known_load() -> None:
    """The left arm held forward, 50 N down at the hand: the standing humanoid's hand sinks as the
    servos' stiffness, the legs' and the base's give predict (within 20 % and 1.5 mm)."""
    world = build(load("book_transfer"))
    q = _posture(world, {"left_shoulder_pitch": -1.3, "left_elbow": -0.3, "left_shoulder_roll": 0.2})
    predicted, observed = _against_mujoco(world, q, "left", np.array([0.0, 0.0, -50.0]))
    print(f"predicted {np.round(predicted * 1000, 2)} mm, MuJoCo {np.round(observed * 1000, 2)} mm")
    assert observed[2] < -0.02  # a load the tracking tolerance feels (26-28 mm)
    assert np.linalg.norm(predicted - observed) < 0.2 * np.linalg.norm(observed) + 0.0015


def test_a_target_clipped_at_its_range_leaves_its_feed_forward_short() -> None:
    """The wrist planned at its range's end: the servo cannot be given the target plus its gravity
    feed-forward, and the joint sags by what was clipped (no load at all)."""
    world = build(load("book_transfer"))
    joints = {
        "left_shoulder_pitch": -1.3,
        "left_elbow": -0.3,
        "left_shoulder_roll": 0.2,
        "left_wrist_pitch": -0.6,
    }
    q = _posture(world, joints)
    free = _posture(world, {**joints, "left_wrist_pitch": -0.3})
    servos = ServoSet.of(world)
    none = np.zeros((0, world.model.nv))
    assert np.abs(servos.hold(world.model, free, none).deflection[0]).max() < 1e-9  # fed forward in full
    model, data = world.model, mujoco.MjData(world.model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, world.ids.hand_sites["left"])
    predicted = jac @ servos.hold(model, q, none).deflection[0]
    planned = data.site_xpos[world.ids.hand_sites["left"]].copy()
    observed = _held(world, q, "left", np.zeros(3)) - planned
    sink = _held(world, free, "left", np.zeros(3)) - _site(world, free, "left")  # the feet's contact
    print(f"predicted {np.round(predicted * 1000, 2)} mm, MuJoCo {np.round((observed - sink) * 1000, 2)} mm")
    assert np.linalg.norm(predicted) > 0.0003
    assert np.linalg.norm(predicted - (observed - sink)) < 0.3 * np.linalg.norm(predicted) + 0.0003


def _site(world: World, q: np.ndarray, side: str) -> np.ndarray:
    data = mujoco.MjData(world.model)
    data.qpos[:] = q
    mujoco.mj_kinematics(world.model, data)
    return np.asarray(data.site_xpos[world.ids.hand_sites[side]], dtype=float).copy()


def test_a_load_beyond_a_servo_s_limit_stalls_the_hand() -> None:
    """200 N at the forward hand needs more than a servo gives: predicted saturated, and in MuJoCo the
    hand does not hold (it ends far beyond the move's tolerance)."""
    world = build(load("book_transfer"))
    q = _posture(world, {"left_shoulder_pitch": -1.3, "left_elbow": -0.3, "left_shoulder_roll": 0.2})
    force = np.array([0.0, 0.0, -200.0])
    _, ratio = _predicted(world, q, "left", force)
    moved = np.linalg.norm(_held(world, q, "left", force, seconds=1.5) - _site(world, q, "left"))
    print(f"predicted |torque| / limit {ratio:.2f}; MuJoCo: the hand {moved * 1000:.0f} mm off")
    assert ratio > 1.0 and moved > MOVE_TOLERANCE


def test_the_g1_s_hand_under_a_known_load(g1_scenario_yaml: str) -> None:
    """The same check on the Unitree G1 (kp 500 servos, its own force limits): 10 N at the forward hand."""
    world = build(from_dict(yaml.safe_load(g1_scenario_yaml), "g1"))
    q = _posture(world, {"left_shoulder_pitch_joint": -0.9, "left_elbow_joint": 0.3})
    predicted, observed = _against_mujoco(world, q, "left", np.array([0.0, 0.0, -10.0]))
    print(f"G1: predicted {np.round(predicted * 1000, 2)} mm, MuJoCo {np.round(observed * 1000, 2)} mm")
    assert np.linalg.norm(observed) > 0.003
    assert np.linalg.norm(predicted - observed) < 0.25 * np.linalg.norm(observed) + 0.0015


def _synthetic() -> TrackingPrediction:
    """Two moves, two hands: one near its tolerance, measured (a residual that varies), with a load."""
    near = HandEnd(
        "right", np.array([0.0, -0.024, 0.002]), np.array([0.0, -0.004, -0.003]), np.array([0.0, -0.02, 0.0])
    )
    far = HandEnd("left", np.array([0.004, 0.002, -0.001]), np.zeros(3), np.array([0.003, 0.0, 0.0]))
    first = MoveEnd("carry", MOVE_TOLERANCE, (near, far), (-np.inf, 1.1), 0.5, measured=True)
    second = MoveEnd(
        "place",
        MOVE_TOLERANCE,
        (HandEnd("right", near.error * 0.9, near.per_kg, near.residual),),
        (-np.inf, np.inf),
        0.4,
        measured=True,
    )
    return TrackingPrediction((first, second), 0.8, 0.16)


def test_the_probability_is_the_monte_carlo_of_its_own_assumptions() -> None:
    """P(some move ends beyond its tolerance) by quadrature against sampling the same model: the
    mass (the sampler's clipped factor), the shared residual factor, each hand's noise."""
    prediction = _synthetic()
    p, each = prediction.probabilities()
    rng = np.random.default_rng(3)
    n = 400_000
    mass = 0.8 * np.maximum(0.2, 1.0 + 0.2 * rng.normal(size=n))
    shared = rng.normal(size=n)
    failed = np.zeros(n, dtype=bool)
    for move in prediction.moves:
        failed |= (mass < move.mass_range[0]) | (mass > move.mass_range[1])
        for hand in move.hands:
            e = (
                hand.error
                + (mass - 0.8)[:, None] * hand.per_kg
                + RESIDUAL_SCALE * shared[:, None] * hand.residual
                + rng.normal(0.0, MEASURED_SIGMA, (n, 3))
            )
            failed |= np.linalg.norm(e, axis=1) > move.tolerance
    expected = float(failed.mean())
    print(f"quadrature {p:.4f}, Monte Carlo {expected:.4f}; per move {np.round(each, 4)}")
    assert 0.05 < expected < 0.5
    assert p == pytest.approx(expected, abs=4 * np.sqrt(expected * (1 - expected) / n) + 0.002)
    report = tracking_report(prediction, 1.0)
    assert report.probability == pytest.approx(p) and report.probability_bounds[0] == pytest.approx(
        each.max()
    )


def test_a_dry_run_s_measurement_replaces_the_statics() -> None:
    """Measured 10 mm off where the statics said 1 mm: the measurement is the mean, its difference
    the residual that varies; a move the run did not end keeps the statics'."""
    hand = HandEnd("left", np.array([0.001, 0.0, 0.0]), np.zeros(3), np.zeros(3))
    prediction = TrackingPrediction(
        (MoveEnd("carry", MOVE_TOLERANCE, (hand,), (-np.inf, np.inf), 0.2),), 0.5, 0.05
    )
    assert prediction.probabilities()[0] < 1e-12  # the statics: far inside the tolerance
    measured = prediction.measured({"carry": {"left": [0.028, 0.0, 0.0]}})
    moved = measured.moves[0].hands[0]
    assert measured.moves[0].measured and np.allclose(moved.residual, [0.027, 0.0, 0.0])
    assert 0.2 < measured.probabilities()[0] < 0.5  # 2 mm inside, the residual's 16 % spread: 4.3 mm
    assert prediction.measured({"other": {"left": [0.1, 0, 0]}}).moves[0] == prediction.moves[0]


def test_the_tables_show_what_the_dry_run_refined() -> None:
    """A mode the dry run refines shows analytic -> dry run (-> fused): in `executive plan`'s line
    and the console's physics table, with rollouts and without."""
    from executive.console.risk_table import physics_table
    from executive.report.plots import _fused_text

    dry = {"analytic": 0.0, "measured": 0.021}
    without = {"dry_run": {"outcome": "success"}, "rollouts": 0, "outcomes": {}, "modes": {"tracking": dry}}
    assert _fused_text(without) == "; analytic->dry run tracking 0.000->0.021"
    fused = {**dry, "fused": 0.015, "interval": [0.0, 0.11], "failures": 0}
    modes = {"collision": {"analytic": 0.05, "fused": 0.04, "interval": [0.0, 0.2]}, "tracking": fused}
    rolled = {"dry_run": {"outcome": "success"}, "rollouts": 4, "outcomes": {"success": 4}, "modes": modes}
    assert _fused_text(rolled).endswith("tracking 0.000->0.021->0.015 [0.000, 0.110]")
    row = {"name": "left", "feasible": True, "value": 0.3, "risk": {"combined": 0.1}, "physics": without}
    assert "→ 0.021 |" in physics_table([row])
    assert "≈0 → 0.021 → 0.015 [≈0, 0.11] |" in physics_table([{**row, "physics": rolled}])


def _push_plan(world: World, q: np.ndarray, side: str, force: np.ndarray) -> AlternativePlan:
    """A one-knot push of the scene's block by ``side``'s hand in pose ``q`` with ``force`` (N)."""
    task = world.scenario.mission[-1]
    step = Step("push", f"{side}.push", side, (), carried=(side, "block"), force=tuple(force))
    traj = Trajectory(
        step.name, np.zeros(1), q[None, :], {side: _site(world, q, side)[None, :]}, np.zeros((1, 3)), None
    )
    return AlternativePlan("push", task, (step,), {step.name: traj})


def test_a_push_s_sliding_friction_holds_the_hand_back_as_the_statics_predict() -> None:
    """The left arm forward pushing along +x against a block's sliding friction (20 N): the statics
    of the push's reaction at the hand site against MuJoCo's hold of that force (within 20 %, 1.5 mm);
    a push the servos cannot give (400 N) stalls at the nominal mass."""
    world = build(load("pick_place_push"))
    q = _posture(world, {"left_shoulder_pitch": -1.3, "left_elbow": -0.3, "left_shoulder_roll": 0.2})
    push = np.array([20.0, 0.0, 0.0])
    move = predict_tracking(world, _push_plan(world, q, "left", push)).moves[0]
    mass = float(world.model.body_mass[world.ids.object_bodies["block"]])
    assert move.push_mass == pytest.approx(mass)
    observed = _held(world, q, "left", -push) - _held(world, q, "left", np.zeros(3))
    predicted = move.hands[0].error
    print(f"predicted {np.round(predicted * 1000, 2)} mm, MuJoCo {np.round(observed * 1000, 2)} mm")
    assert observed[0] < -0.003  # held back against the push
    assert np.linalg.norm(predicted - observed) < 0.2 * np.linalg.norm(observed) + 0.0015
    assert np.allclose(move.hands[0].per_kg * mass, predicted, atol=1e-6)  # linear in the block's kg
    stalled = predict_tracking(world, _push_plan(world, q, "left", 20.0 * push)).moves[0]
    assert not stalled.mass_range[0] <= mass <= stalled.mass_range[1]
    p, _ = TrackingPrediction((stalled,), 0.0, 0.0, (0.0, 0.0)).probabilities()
    assert p == pytest.approx(1.0)


def test_a_push_s_probability_is_the_monte_carlo_of_the_block_s_mass_and_friction() -> None:
    """A push whose hand lags near its tolerance at the block's nominal mass and friction: P(fails)
    by quadrature over the push's force scale against sampling the truth sampler's mass and friction
    factors (each ``max(0.2, 1 + s z)``), the stall where the scale passes the servos' range."""
    hand = HandEnd("right", np.array([-0.021, 0.0, 0.001]), np.array([-0.02, 0.0, 0.002]), np.zeros(3))
    move = MoveEnd("right.push", MOVE_TOLERANCE, (hand,), (-np.inf, 1.6), 0.3, push_mass=1.0)
    carry = MoveEnd(
        "carry",
        MOVE_TOLERANCE,
        (HandEnd("left", np.zeros(3), np.array([0.0, 0.0, -0.01]), np.zeros(3)),),
        (-np.inf, np.inf),
        0.2,
    )
    prediction = TrackingPrediction((move, carry), 0.5, 0.05, (0.1, 0.3))
    p, each = prediction.probabilities()
    rng = np.random.default_rng(5)
    n = 400_000
    scale = np.maximum(0.2, 1.0 + 0.1 * rng.normal(size=n)) * np.maximum(0.2, 1.0 + 0.3 * rng.normal(size=n))
    e = hand.error + (scale - 1.0)[:, None] * hand.per_kg + rng.normal(0.0, 0.003, (n, 3))
    failed = (np.linalg.norm(e, axis=1) > MOVE_TOLERANCE) | (scale > 1.6)
    expected = float(failed.mean())
    print(f"quadrature {p:.4f} (push {each[0]:.4f}), Monte Carlo {expected:.4f}")
    assert 0.1 < expected < 0.6
    assert each[0] == pytest.approx(expected, abs=4 * np.sqrt(expected * (1 - expected) / n) + 0.002)
    assert p == pytest.approx(each[0], abs=1e-9) and each[1] < 1e-6  # the carry far inside
    found = prediction.hand_at("right.push", "right")
    assert found is not None
    nodes, weights = force_scale_distribution(0.1, 0.3)
    kg = float(np.sqrt(weights @ (nodes - weights @ nodes) ** 2))  # the pushed kilograms' 1-sigma
    along = kg * float(np.linalg.norm(hand.per_kg)) / np.sqrt(3.0)
    assert found[1] == pytest.approx(np.hypot(MEASURED_SIGMA, along), rel=1e-6)
