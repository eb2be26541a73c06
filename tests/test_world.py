"""World building: estimate vs truth, seeded sampling, the scene's contents."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from executive.errors import WorldError
from executive.scenario import load
from executive.schema.types import Body, Uncertainty
from executive.world.model import Perturbation, build, build_pair, sample_perturbation, subtree_bodies


@pytest.fixture(scope="module")
def scenario():  # type: ignore[no-untyped-def]
    return load("book_transfer")


@pytest.fixture(scope="module")
def estimate(scenario):  # type: ignore[no-untyped-def]
    return build(scenario)


def test_estimate_has_robot_table_objects_obstacles(scenario, estimate) -> None:  # type: ignore[no-untyped-def]
    m = estimate.model
    for name in ("table_top", "floor", "book", "book_stack"):
        assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name) >= 0, name
    # The book rests on the table: its bottom face at the table top height.
    book = scenario.scene.objects[0]
    pos, _ = estimate.object_pose("book")
    assert pos[2] - book.size[2] / 2 == pytest.approx(scenario.scene.table.height, abs=1e-9)
    assert estimate.kind == "estimate"
    assert estimate.perturbation.is_zero()
    # The robot's keyframe was carried over: robot joints at the profile's stand pose.
    assert estimate.robot_dof >= 6 + 6 + 2 + 7 + 7


def test_same_seed_same_truth(scenario) -> None:  # type: ignore[no-untyped-def]
    _, t1 = build_pair(scenario, np.random.default_rng(42))
    _, t2 = build_pair(scenario, np.random.default_rng(42))
    _, t3 = build_pair(scenario, np.random.default_rng(43))
    assert t1.perturbation == t2.perturbation
    np.testing.assert_array_equal(t1.data.qpos, t2.data.qpos)
    np.testing.assert_array_equal(t1.model.body_ipos, t2.model.body_ipos)
    np.testing.assert_array_equal(t1.model.geom_friction, t2.model.geom_friction)
    assert t1.perturbation != t3.perturbation
    assert not np.array_equal(t1.data.qpos, t3.data.qpos)


def test_zero_uncertainty_truth_equals_estimate(scenario, estimate) -> None:  # type: ignore[no-untyped-def]
    exact = replace(scenario, uncertainty=Uncertainty())
    pert = sample_perturbation(exact, np.random.default_rng(7))
    assert pert.is_zero()
    truth = build(exact, pert, kind="truth")
    np.testing.assert_array_equal(truth.data.qpos, estimate.data.qpos)
    np.testing.assert_array_equal(truth.model.body_mass, estimate.model.body_mass)


def test_truth_applies_each_perturbation(scenario, estimate) -> None:  # type: ignore[no-untyped-def]
    pert = Perturbation(
        object_offsets={"book": (0.03, -0.02, np.deg2rad(10.0))},
        obstacle_offsets={"book_stack": (-0.01, 0.015)},
        object_mass_scale={"book": 1.5},
        friction_scale=0.8,
        com_offset=(0.02, -0.01),
    )
    truth = build(scenario, pert)
    est_pos, est_quat = estimate.object_pose("book")
    pos, quat = truth.object_pose("book")
    np.testing.assert_allclose(pos - est_pos, [0.03, -0.02, 0.0], atol=1e-12)
    # yaw difference between the two quaternions: 10 degrees about z
    rel = np.zeros(4)
    mujoco.mju_negQuat(rel, est_quat)
    mujoco.mju_mulQuat(rel, quat, rel)
    assert 2 * np.degrees(np.arctan2(rel[3], rel[0])) == pytest.approx(10.0, abs=1e-9)
    stack = truth.ids.obstacle_geoms["book_stack"]
    np.testing.assert_allclose(
        truth.data.geom_xpos[stack] - estimate.data.geom_xpos[stack], [-0.01, 0.015, 0.0], atol=1e-12
    )
    book_body = truth.ids.object_bodies["book"]
    assert truth.model.body_mass[book_body] == pytest.approx(1.5 * estimate.model.body_mass[book_body])
    book_geom = truth.ids.object_geoms["book"]
    assert truth.model.geom_friction[book_geom, 0] == pytest.approx(
        0.8 * estimate.model.geom_friction[book_geom, 0]
    )

    # Whole-robot CoM at the keyframe, recomputed independently as the mass-weighted mean of bodies.
    def robot_com(world):  # type: ignore[no-untyped-def]
        ids = list(world.ids.robot_bodies)
        m = world.model.body_mass[ids]
        return (m[:, None] * world.data.xipos[ids]).sum(axis=0) / m.sum()

    np.testing.assert_allclose((robot_com(truth) - robot_com(estimate))[:2], [0.02, -0.01], atol=2e-4)
    assert truth.robot_mass == pytest.approx(estimate.robot_mass)


def test_sampled_truth_matches_the_stated_sigmas(scenario) -> None:  # type: ignore[no-untyped-def]
    """Monte Carlo: the sample standard deviations are the scenario's 1-sigma values."""
    rng = np.random.default_rng(0)
    n = 4000
    draws = [sample_perturbation(scenario, rng) for _ in range(n)]
    u = scenario.uncertainty
    book_dx = np.array([d.object_offsets["book"][0] for d in draws])
    book_yaw = np.array([d.object_offsets["book"][2] for d in draws])
    stack_dy = np.array([d.obstacle_offsets["book_stack"][1] for d in draws])
    com_x = np.array([d.com_offset[0] for d in draws])
    # The standard error of a sample std is sigma / sqrt(2 n) ~ 1.1 %; allow 5 %.
    for sample, sigma in (
        (book_dx, u.object_position),
        (book_yaw, u.object_yaw_rad),
        (stack_dy, u.obstacle_position),
        (com_x, u.com),
    ):
        assert sample.std() == pytest.approx(sigma, rel=0.05)
        assert abs(sample.mean()) < 4 * sigma / np.sqrt(n)


def test_object_name_clashing_with_robot_is_an_error(scenario) -> None:  # type: ignore[no-untyped-def]
    book = scenario.scene.objects[0]
    clash = replace(scenario, scene=replace(scenario.scene, objects=(replace(book, name="pelvis"),)))
    with pytest.raises(WorldError, match="pelvis"):
        build(clash)


def test_world_works_with_a_sphere_and_cylinder(scenario) -> None:  # type: ignore[no-untyped-def]
    table_h = scenario.scene.table.height
    extra = (
        Body("ball", "sphere", (0.03,), (0.7, 0.4, table_h + 0.03), (0.0, 0.0, 0.0), 0.2),
        Body("can", "cylinder", (0.03, 0.12), (0.7, -0.4, table_h + 0.06), (0.0, 0.0, 0.0), 0.3),
    )
    sc = replace(scenario, scene=replace(scenario.scene, objects=scenario.scene.objects + extra))
    world = build(sc)
    assert set(world.ids.object_bodies) == {"book", "ball", "can"}
    # one free joint (7 qpos) per object after the robot
    assert world.model.nq == build(scenario).model.nq + 14


# ----------------------------------------------------------------------------- the home pose


def _robot_key(world):  # type: ignore[no-untyped-def]
    """The home keyframe's robot part (robot joints come first, objects after)."""
    m = world.model
    robot_nq = int(m.nq) - 7 * len(world.ids.object_bodies)
    return m.key_qpos[world.ids.keyframe, :robot_nq], m.key_ctrl[world.ids.keyframe]


def test_humanoid_home_is_its_models_keyframe(scenario, estimate) -> None:  # type: ignore[no-untyped-def]
    """No home_joints, hands already open in its keyframe: home is the MJCF's own 'stand'."""
    model = mujoco.MjModel.from_xml_path(str(scenario.robot.mjcf))
    key = model.key("stand").id
    qpos, ctrl = _robot_key(estimate)
    assert np.array_equal(qpos, model.key_qpos[key])
    assert np.array_equal(ctrl, model.key_ctrl[key])


def _with_home_joints(scenario, tmp_path, home_joints):  # type: ignore[no-untyped-def]
    import yaml

    from executive.schema import catalog as registry

    path = registry.robot_profile_path("humanoid")
    data = yaml.safe_load(path.read_text())  # type: ignore[union-attr]
    data["mjcf"] = str(scenario.robot.mjcf)
    data["home_joints"] = home_joints
    profile = tmp_path / "profile.yaml"
    profile.write_text(yaml.safe_dump(data))
    return replace(scenario, robot=replace(scenario.robot, profile=profile))


def test_home_joints_replace_the_keyframes_angles(scenario, estimate, tmp_path) -> None:  # type: ignore[no-untyped-def]
    world = build(_with_home_joints(scenario, tmp_path, {"left_elbow": -1.0}))
    m = world.model
    joint, actuator = m.joint("left_elbow").id, m.actuator("left_elbow").id
    qpos, ctrl = _robot_key(world)
    base_qpos, base_ctrl = _robot_key(estimate)
    assert qpos[m.jnt_qposadr[joint]] == -1.0 != base_qpos[m.jnt_qposadr[joint]]
    assert ctrl[actuator] == -1.0  # its position servo's target too
    assert np.array_equal(np.delete(ctrl, actuator), np.delete(base_ctrl, actuator))
    others = np.arange(len(qpos)) != m.jnt_qposadr[joint]
    assert np.array_equal(qpos[others], base_qpos[others])
    assert world.data.qpos[m.jnt_qposadr[joint]] == -1.0  # the world starts there


@pytest.mark.parametrize(
    ("home_joints", "message"),
    [
        ({"left_elbw": 0.1}, "'left_elbw', which is not a hinge or slide joint"),
        ({"left_elbow": 9.0}, "outside"),
    ],
)
def test_bad_home_joints_are_world_errors(scenario, tmp_path, home_joints, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(WorldError, match=message):
        build(_with_home_joints(scenario, tmp_path, home_joints))


def test_g1_starts_with_open_hands_clear_of_its_body(g1_scenario_yaml: str) -> None:
    """The G1's home: its keyframe, the arms at the profile's home_joints, the Dex3 hands at their
    open pose (the model's keyframe has them half closed); open, they keep the planner's 2 cm from
    the rest of the robot, and standing half a second they stay open, touching nothing."""
    from executive.scenario import loads

    world = build(loads(g1_scenario_yaml, source="g1_book_transfer.yaml"))
    m, d, profile = world.model, world.data, world.profile
    model = mujoco.MjModel.from_xml_path(str(world.scenario.robot.mjcf))
    key = model.key(profile.keyframe).id
    qpos, ctrl = _robot_key(world)
    expected_q, expected_ctrl = model.key_qpos[key].copy(), model.key_ctrl[key].copy()
    for name, value in profile.home_joints.items():
        expected_q[model.jnt_qposadr[model.joint(name).id]] = value
        expected_ctrl[model.actuator(name).id] = value
    for arm in profile.arms.values():
        for name, value in zip(arm.gripper.actuators, arm.gripper.open, strict=True):
            expected_q[model.jnt_qposadr[model.actuator(name).trnid[0]]] = value
            expected_ctrl[model.actuator(name).id] = value
    assert np.array_equal(qpos, expected_q)
    assert np.array_equal(ctrl, expected_ctrl)
    assert not np.array_equal(expected_q, model.key_qpos[key])  # the hands did change

    hand = {
        g
        for side in profile.sides
        for g in world.ids.robot_geoms
        if m.geom_bodyid[g] in world.ids.hand_bodies[side]
    }
    arm_bodies = {
        b
        for side in profile.sides
        for b in subtree_bodies(m, int(m.jnt_bodyid[world.ids.arm_joints[side][0]]))
    }
    rest = [g for g in world.ids.robot_geoms if int(m.geom_bodyid[g]) not in arm_bodies]
    fromto = np.zeros(6)
    gap = min(mujoco.mj_geomDistance(m, d, a, b, 0.1, fromto) for a in hand for b in rest)
    assert gap > 0.02
    for _ in range(round(0.5 / m.opt.timestep)):
        d.ctrl[:] = world.home_ctrl()
        mujoco.mj_step(m, d)
    assert not any({int(c.geom1), int(c.geom2)} & hand for c in d.contact[: d.ncon])
    for side, arm in profile.arms.items():
        joints = m.actuator_trnid[list(world.ids.gripper_actuators[side]), 0]
        assert np.allclose(d.qpos[m.jnt_qposadr[joints]], arm.gripper.open, atol=0.02)
