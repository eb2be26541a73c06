"""Collision risk: coal vs MuJoCo distances, the seed metric, first-order P vs Monte Carlo, broad phase.

Independent references: MuJoCo's own ``mj_geomDistance`` for the distances, hand-computed
seed values (Long et al. 2018, "Collision Risk"), the normal CDF, and Monte Carlo sampling
of the environment's pose error with exact coal distances.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import coal
import mujoco
import numpy as np
import pytest
from scipy.stats import norm

from executive.risk.collision import (
    CollisionModel,
    CollisionModelError,
    CollisionSetup,
    NearPair,
    assess_collision,
    collision_probability,
    gaussian_union_probability,
    instantaneous_risk,
    monte_carlo_collision_probability,
    report_from_profile,
    seed_collision_score,
)
from executive.risk.shapes import coal_geometry, coal_transform
from executive.scenario import load
from executive.schema.types import Body, CollisionRiskConfig, RiskConfig
from executive.world.model import World, build

FloatArray = np.ndarray


@dataclass(frozen=True)
class Path:
    """The part of a planner trajectory the collision model reads."""

    times: FloatArray
    qpos: FloatArray
    carried: tuple[str, str] | None = None


@pytest.fixture(scope="module")
def world() -> World:
    return build(load("book_transfer"))


@pytest.fixture(scope="module")
def cmodel(world: World) -> CollisionModel:
    return CollisionModel(world, world.scenario.risk)


def _set_joint(world: World, q: FloatArray, name: str, value: float) -> None:
    q[world.model.jnt_qposadr[world.model.joint(name).id]] = value


def _reach_pose(world: World) -> FloatArray:
    """Both arms forward and down: the palms a few centimetres above the table."""
    q = world.home_qpos()
    for side in ("left", "right"):
        _set_joint(world, q, f"{side}_shoulder_pitch", -0.4)
        _set_joint(world, q, f"{side}_elbow", -0.2)
    return q


def _arm_configurations(world: World, count: int, lo: float, hi: float) -> list[FloatArray]:
    """Seeded random arm poses whose closest robot-table_top distance (MuJoCo's) is in [lo, hi]."""
    m, d = world.model, mujoco.MjData(world.model)
    table = m.geom("table_top").id
    joints = [j for side in ("left", "right") for j in world.ids.arm_joints[side]]
    q0, rng, found = world.home_qpos(), np.random.default_rng(1), []
    for _ in range(3000):
        q = q0.copy()
        for j in joints:
            a = m.jnt_qposadr[j]
            q[a] = np.clip(q0[a] + rng.uniform(-0.8, 0.8), *m.jnt_range[j])
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        gap = min(mujoco.mj_geomDistance(m, d, table, g, 1.0, None) for g in world.ids.robot_geoms)
        if lo <= gap <= hi:
            found.append(q)
            if len(found) == count:
                break
    assert len(found) == count
    return found


# --- 1. coal vs MuJoCo ---------------------------------------------------------------------------


def test_coal_matches_mujoco_on_the_book_scene(world: World, cmodel: CollisionModel) -> None:
    m, d = world.model, mujoco.MjData(world.model)
    env = [m.geom("table_top").id, m.geom("book_stack").id, m.geom("book").id]
    configs = [world.home_qpos(), *_arm_configurations(world, 6, 0.0, 0.05)]
    req, worst, compared, near = coal.DistanceRequest(), 0.0, 0, 0
    for q in configs:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mj_min = np.inf
        for e in env:
            for g in world.ids.robot_geoms:
                fromto = np.zeros(6)
                ref = mujoco.mj_geomDistance(m, d, e, g, 2.0, fromto)
                got = coal.distance(
                    coal_geometry(m, e),
                    coal_transform(d.geom_xpos[e], d.geom_xmat[e]),
                    coal_geometry(m, g),
                    coal_transform(d.geom_xpos[g], d.geom_xmat[g]),
                    req,
                    coal.DistanceResult(),
                )
                worst = max(worst, abs(got - ref))
                compared += 1
                near += ref < 0.05
                mj_min = min(mj_min, ref)
        # The model's knot minimum (broad phase on) is MuJoCo's minimum over the same pairs.
        knot = cmodel.knot(q)
        assert knot.distance == pytest.approx(mj_min, abs=1e-3)
    assert compared == len(configs) * len(env) * len(world.ids.robot_geoms)
    assert near >= 6  # the perturbed poses really bring hands within 5 cm of the table
    assert worst < 1e-3, worst


def test_witness_points_and_normal(world: World, cmodel: CollisionModel) -> None:
    knot = cmodel.knot(_reach_pose(world))
    gap = knot.point_robot - knot.point_env
    assert np.linalg.norm(knot.normal) == pytest.approx(1.0, abs=1e-9)
    assert np.linalg.norm(gap) == pytest.approx(abs(knot.distance), abs=1e-6)
    # The normal points from the environment geom to the robot geom.
    assert float(gap @ knot.normal) == pytest.approx(knot.distance, abs=1e-6)
    assert knot.env_geom_name in {"table_top", "book_stack", "book"}
    assert knot.robot_body_name == world.model.body(world.model.geom_bodyid[knot.robot_geom]).name


def test_floor_is_never_a_pair_and_allow_excludes(world: World, cmodel: CollisionModel) -> None:
    assert world.ids.floor_geom not in cmodel.setup.env_geoms
    q = _reach_pose(world)
    base = cmodel.knot(q)
    skipped = cmodel.knot(q, allow={base.env_geom_name})
    assert skipped.env_geom_name != base.env_geom_name
    assert skipped.distance >= base.distance
    pair = cmodel.knot(q, allow={(base.robot_geom_name, base.env_geom_name)})
    assert (pair.robot_geom_name, pair.env_geom_name) != (base.robot_geom_name, base.env_geom_name)
    assert ("left_palm_geom", "book") in cmodel.hand_allow("left", "book")
    with pytest.raises(CollisionModelError, match="environment geoms"):
        cmodel.knot(q, allow={"no_such_thing"})


# --- 2. first-order probability vs Monte Carlo ------------------------------------------------------

_TINY = """
<mujoco>
  <worldbody>
    <geom name="table" type="box" size="0.5 0.5 0.02" pos="0 0 -0.02"/>
    <body name="obstacle" pos="0 0 0.15"><geom name="obstacle" type="box" size="0.1 0.1 0.15"/></body>
    <body name="robot">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <joint name="z" type="slide" axis="0 0 1"/>
      <geom name="ball" type="sphere" size="0.05"/>
    </body>
  </worldbody>
</mujoco>
"""
_SIGMA = 0.01


def _tiny() -> tuple[mujoco.MjModel, CollisionModel]:
    m = mujoco.MjModel.from_xml_string(_TINY)
    setup = CollisionSetup(
        robot_geoms=(m.geom("ball").id,),
        env_geoms=(m.geom("table").id, m.geom("obstacle").id),
        env_sigma={m.body("obstacle").id: _SIGMA},
    )
    return m, CollisionModel.from_setup(m, setup, RiskConfig(d_safety=0.05))


def test_gaussian_union_of_one_half_plane_is_phi() -> None:
    for b in (0.5, 1.0, 2.0, 3.5):
        got = gaussian_union_probability(np.array([[0.6, 0.8]]), np.array([b]))
        assert got == pytest.approx(norm.cdf(-b), rel=1e-6)
    # Two opposite half-planes are disjoint: the union is the sum.
    two = gaussian_union_probability(np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([1.0, 1.5]))
    assert two == pytest.approx(norm.cdf(-1.0) + norm.cdf(-1.5), rel=1e-6)


def test_first_order_matches_monte_carlo_on_two_boxes_and_a_sphere() -> None:
    _, cm = _tiny()
    # Sphere (r 5 cm) at mid-height of the obstacle (half 10 cm): past the +x face,
    # round the vertical edge, past the +y face. The table top is 10 cm below the ball.
    edge = 0.1 + (0.05 + 0.025) / np.sqrt(2.0)
    centres = [(0.17, 0.0), (0.165, 0.05), (edge, edge), (0.05, 0.17), (0.0, 0.165)]
    qpos = np.array([[x, y, 0.15] for x, y in centres])
    expected_d = np.array([0.02, 0.015, 0.025, 0.02, 0.015])
    path = Path(times=np.arange(len(qpos)) * 0.1, qpos=qpos)
    report = assess_collision(cm, path)
    np.testing.assert_allclose(report.traces["distance"], expected_d, atol=1e-9)

    mc = monte_carlo_collision_probability(cm, path, np.random.default_rng(3), samples=100_000)
    first = report.traces["probability"]
    # Past a flat face the distance is linear in the shift: first order within MC error.
    for k in (0, 1, 3, 4):
        assert first[k] == pytest.approx(norm.cdf(-expected_d[k] / _SIGMA), rel=1e-6)
        assert first[k] == pytest.approx(mc.per_knot[k], rel=0.06)
    # Round the vertical edge the collision set is a disk of radius r_ball + r_edge (5 sigma):
    # the tangent half-plane contains it, so first order is conservative, here by ~25 %
    # (exact disk probability 0.00495 vs Phi(-2.5) = 0.00621).
    assert mc.per_knot[2] <= first[2] <= 1.3 * mc.per_knot[2]
    lower, upper = report.probability_bounds
    slack = 3.0 * mc.stderr
    assert lower - slack <= mc.probability <= upper + slack
    assert lower < report.probability < upper  # the knots are neither disjoint nor identical
    assert report.probability == pytest.approx(mc.probability, rel=0.1)
    assert upper == pytest.approx(min(1.0, float(np.sum(first))))


def test_exact_environment_and_penetration() -> None:
    _, cm = _tiny()
    # Ball resting 1 cm into the table (sigma 0): certain collision, and inside d_safety.
    path = Path(times=np.array([0.0, 1.0]), qpos=np.array([[0.4, 0.4, 0.04], [0.4, 0.4, 0.2]]))
    report = assess_collision(cm, path)
    assert report.traces["distance"][0] == pytest.approx(-0.01, abs=1e-9)
    assert report.probability == 1.0
    assert report.traces["instantaneous_risk"][0] == 1.0
    pairs = [NearPair(1, 1, 2, 0.02, np.array([0.0, 0.0, 1.0]))]  # vertical normal: no horizontal error
    assert collision_probability([pairs], {1: 0.01}).probability == 0.0


# --- 3. the seed metric ------------------------------------------------------------------------------


def test_instantaneous_risk_hand_values() -> None:
    ds, b = 0.05, 2.0
    d = np.array([-0.01, 0.0, ds / 2, ds, 2 * ds])
    np.testing.assert_allclose(instantaneous_risk(d, ds, b), [1.0, 1.0, 0.25, 0.0, 0.0])
    assert float(instantaneous_risk(ds / 2, ds, 3.0)) == pytest.approx(0.125)


def test_seed_trajectory_score_hand_values() -> None:
    config = CollisionRiskConfig(exponent=2.0, peak_weight=0.7, exposure_weight=0.3)
    # 0.10 -> 0.0 -> 0.10 m over 2 s: below 0.05 m for half of each second; peak r(0) = 1.
    score = seed_collision_score(np.array([0.0, 1.0, 2.0]), np.array([0.1, 0.0, 0.1]), 0.05, config)
    assert score.peak == pytest.approx(1.0)
    assert score.exposure == pytest.approx(0.5)
    assert score.score == pytest.approx(0.7 * 1.0 + 0.3 * 0.5)
    # Closest 0.025 m (r = 0.25); within d_safety from t = 1 to t = 3 of 4 s.
    t, d = np.arange(5.0), np.array([0.1, 0.05, 0.025, 0.05, 0.1])
    score = seed_collision_score(t, d, 0.05, CollisionRiskConfig())
    assert (score.peak, score.exposure) == pytest.approx((0.25, 0.5))
    assert score.score == pytest.approx(0.5 * 0.25 + 0.5 * 0.5)


def test_report_uses_the_seed_score(world: World, cmodel: CollisionModel) -> None:
    qpos = np.linspace(world.home_qpos(), _reach_pose(world), 30)
    report = assess_collision(cmodel, Path(np.linspace(0.0, 1.5, 30), qpos))
    assert report.mode == "collision"
    ref = seed_collision_score(
        report.times, report.traces["distance"], world.scenario.risk.d_safety, world.scenario.risk.collision
    )
    assert report.seed_score == pytest.approx(ref.score)
    assert report.details["min_distance"] == pytest.approx(float(np.min(report.traces["distance"])))
    lo, hi = report.probability_bounds
    assert 0.0 <= lo <= report.probability <= hi <= 1.0


# --- 4. broad phase ------------------------------------------------------------------------------------


def test_broad_phase_keeps_the_minimum_and_skips_most_pairs(world: World, cmodel: CollisionModel) -> None:
    qpos = np.linspace(world.home_qpos(), _reach_pose(world), 40)
    path = Path(np.linspace(0.0, 2.0, 40), qpos)
    fast = cmodel.profile(path)
    full = cmodel.profile(path, broad_phase=False)
    np.testing.assert_allclose(fast.distances, full.distances, atol=1e-12)
    assert [k.robot_geom for k in fast.knots] == [k.robot_geom for k in full.knots]
    assert full.pairs_skipped == 0
    total = fast.pairs_checked + fast.pairs_skipped
    assert total == full.pairs_checked
    assert fast.pairs_skipped > 0.7 * total, (fast.pairs_checked, fast.pairs_skipped)
    a = assess_collision(cmodel, path)
    b = assess_collision(cmodel, path, broad_phase=False)
    assert a.probability == pytest.approx(b.probability, rel=1e-12, abs=1e-15)
    assert float(np.min(fast.distances)) < world.scenario.risk.d_safety  # the reach comes close


def test_the_least_distance_alone_is_the_same_for_fewer_pairs(world: World, cmodel: CollisionModel) -> None:
    """knot(near=False), the guards' query: nearest bound first until none is below the best,
    without the pass over every pair within the cutoff. Against every pair computed
    (broad_phase=False): the same distance and pair along a reach that comes close."""
    checked = {True: 0, False: 0}
    for q in np.linspace(world.home_qpos(), _reach_pose(world), 40):
        full = cmodel.knot(q, broad_phase=False)
        for near in (True, False):
            k = cmodel.knot(q, near=near)
            assert k.distance == pytest.approx(full.distance, abs=1e-12)
            assert (k.robot_geom, k.env_geom) == (full.robot_geom, full.env_geom)
            checked[near] += k.pairs_checked
        assert cmodel.knot(q, near=False).near == ()
    print(f"pairs computed over 40 knots: {checked[True]} with the near pairs, {checked[False]} without")
    assert checked[False] < 0.8 * checked[True]  # 461 of 683 when written


def test_travel_bound_along_a_trajectory_changes_no_answer(world: World, cmodel: CollisionModel) -> None:
    """profile() skips pairs whose last coal distance less the travel since stays beyond the cutoff;
    every knot must still equal a fresh, independent query of that knot (same minimum, witness
    and near pairs)."""
    qpos = np.linspace(world.home_qpos(), _reach_pose(world), 60)
    path = Path(np.linspace(0.0, 3.0, 60), qpos)
    prof = cmodel.profile(path)
    alone = [cmodel.knot(q) for q in qpos]
    for k, (a, b) in enumerate(zip(prof.knots, alone, strict=True)):
        assert a.distance == b.distance, k
        assert (a.robot_geom, a.env_geom) == (b.robot_geom, b.env_geom), k
        np.testing.assert_array_equal(a.normal, b.normal)
        assert [(p.env_geom, p.robot_geom, p.distance) for p in a.near] == [
            (p.env_geom, p.robot_geom, p.distance) for p in b.near
        ], k
    # ... with fewer coal calls than the knots queried one by one.
    assert prof.pairs_checked < sum(b.pairs_checked for b in alone)


# --- 5. severity per body part ---------------------------------------------------------------------------


def _with_obstacle(world: World, name: str, position: tuple[float, float, float]) -> World:
    sc = world.scenario
    block = Body(name, "box", (0.04, 0.04, 0.04), position, (0.0, 0.0, 0.0))
    return build(replace(sc, scene=replace(sc.scene, obstacles=(*sc.scene.obstacles, block))))


@pytest.mark.parametrize(
    ("position", "part", "body"),
    [
        ((0.16, 0.0, 1.70), "head", "head"),  # 2 cm in front of the visor
        ((0.10, 0.32, 1.16), "forearm", "left_forearm"),  # outboard of the left forearm
    ],
)
def test_severity_follows_the_body_part(
    world: World, position: tuple[float, float, float], part: str, body: str
) -> None:
    near = _with_obstacle(world, "probe_block", position)
    model = CollisionModel(near)
    q = near.home_qpos()
    report = assess_collision(model, Path(np.array([0.0]), q[None, :]))
    factors = dict(near.scenario.risk.severity.body_parts)
    assert report.details["closest_env_body"] == "probe_block"
    assert report.details["closest_robot_body"] == body
    assert report.details["body_part"] == part
    assert report.severity == pytest.approx(near.scenario.risk.severity.collision * factors[part])


def test_hand_factor_and_carried_object(world: World, cmodel: CollisionModel) -> None:
    knot = cmodel.knot(_reach_pose(world))
    assert cmodel.body_part(knot.robot_geom) == ("hand", 1.5)
    # A carried book (on the robot side) 1 cm beside the stack; it still rests on the table.
    q = world.home_qpos()
    adr = world.ids.object_qpos["book"]
    q[adr : adr + 2] = (0.62, 0.08 + 0.055 + 0.01)
    resting = cmodel.knot(q, carried="book")
    assert (resting.robot_geom_name, resting.env_geom_name) == ("book", "table_top")
    assert resting.distance == pytest.approx(0.0, abs=1e-9)
    lifted = cmodel.knot(q, carried="book", allow=cmodel.support_allow("book"))
    assert (lifted.robot_geom_name, lifted.env_geom_name) == ("book", "book_stack")
    assert lifted.distance == pytest.approx(0.01, abs=1e-9)
    assert cmodel.body_part(lifted.robot_geom) == ("other", 1.0)


@pytest.mark.slow
def test_a_carried_object_keeps_its_own_pose_error_first_order_matches_monte_carlo() -> None:
    """The book carried past the stack: both the stack's and the book's own 1 cm errors count.

    Reference: Monte Carlo with exact coal distances, the stack and the carried book each
    shifted by their own draw per sample. With the stack's error alone the first-order value
    would be far smaller (sigma 1 cm instead of 1.41 cm on the same clearance).
    """
    from executive.planning.planner import Planner
    from executive.tasks.steps import plan_alternative

    scenario = load("book_transfer")
    world = build(scenario)
    plan = plan_alternative(Planner(world), world, scenario.mission[0], "left")
    model = CollisionModel(world, scenario.risk, uncertainty=scenario.uncertainty)
    traj = plan.trajectories["left.transfer"]
    step = next(s for s in plan.steps if s.name == "left.transfer")
    allow = model.step_allow(step.side, step.kind, "book", step.allow_contact, traj.carried)
    first = report_from_profile(model, model.profile(traj, allow=allow))
    mc = monte_carlo_collision_probability(model, traj, np.random.default_rng(1), samples=4000, allow=allow)
    print(f"carried book: first order {first.probability:.4f}, MC {mc.probability:.4f} +- {mc.stderr:.4f}")
    assert first.details["min_distance"] > 0.014  # more than one relative sigma: first order holds
    assert abs(first.probability - mc.probability) < max(0.2 * mc.probability, 3 * mc.stderr)
    # the book's own error matters: the stack's alone gives a much smaller probability
    stack_only = collision_probability(
        [k.near for k in model.profile(traj, allow=allow).knots], model.setup.env_sigma
    )
    assert stack_only.probability < 0.6 * first.probability


def test_one_half_plane_is_the_closed_form_and_two_the_quadrature() -> None:
    # One event: Phi(-b/|a|) exactly. Two orthogonal events: 1 - Phi(b1) Phi(b2) (independent axes).
    assert gaussian_union_probability(np.array([[0.0, 2.0]]), np.array([3.0])) == norm.cdf(-1.5)
    two = gaussian_union_probability(np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([1.0, 2.0]))
    assert two == pytest.approx(1.0 - norm.cdf(1.0) * norm.cdf(2.0), abs=1e-6)  # 720-angle midpoint rule


def test_the_other_hand_near_a_carried_object_is_a_pair_with_the_objects_own_sigma(
    world: World, cmodel: CollisionModel
) -> None:
    """A handover's receiver rises beside the book the giver holds: that hand is not allowed to
    touch it (the failure detector calls it a collision), so the model measures it. Reference:
    MuJoCo's mj_geomDistance between the right hand's geoms and the book at every knot; the
    first-order probability of the closest such pair is Phi(-d / sigma_object) (the hand's pose
    is known, the book's in the hand is not)."""
    from executive.planning.planner import Planner
    from executive.tasks.steps import plan_alternative

    scenario = world.scenario
    plan = plan_alternative(Planner(world), world, scenario.mission[0], "left_to_right")
    step = next(s for s in plan.steps if s.name == "right.rise")
    traj = plan.trajectories[step.name]
    assert traj.carried == ("left", "book")
    allow = cmodel.step_allow(step.side, step.kind, "book", step.allow_contact, traj.carried)
    book = world.ids.object_geoms["book"]
    names = {world.model.geom(g).name for g in world.ids.robot_geoms}
    assert not any(pair[1] == "book" and pair[0].startswith("right") for pair in allow)
    assert any(pair[1] == "book" and pair[0].startswith("left") for pair in allow)  # the holder
    assert all(pair[0] in names for pair in allow if pair[1] == "book")
    profile = cmodel.profile(traj, allow=allow)
    model, data = world.model, mujoco.MjData(world.model)
    right = [g for g in world.ids.robot_geoms if model.geom_bodyid[g] in set(world.ids.hand_bodies["right"])]
    reference, modelled, closest = [], [], None
    for q, knot in zip(traj.qpos, profile.knots, strict=True):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        reference.append(min(mujoco.mj_geomDistance(model, data, g, book, 0.2, None) for g in right))
        pairs = [p for p in knot.near if p.env_geom == book and p.robot_geom in right]
        modelled.append(min((p.distance for p in pairs), default=np.inf))
        for p in pairs:
            if closest is None or p.distance < closest.distance:
                closest = p
    reference_min, modelled_min = min(reference), min(modelled)
    print(f"right hand to the held book in right.rise: coal {modelled_min:.4f}, MuJoCo {reference_min:.4f} m")
    assert reference_min < 0.05  # the rise does pass near the book
    assert modelled_min == pytest.approx(reference_min, abs=1e-3)
    # the closest pair alone, to first order along its normal's horizontal part: a lower bound
    assert closest is not None
    sigma_n = scenario.uncertainty.object_position * float(np.hypot(*closest.normal[:2]))
    report = report_from_profile(cmodel, profile)
    assert report.probability >= norm.cdf(-closest.distance / sigma_n) * (1 - 1e-6) > 1e-4
