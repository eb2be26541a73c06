"""Tests of the embedded humanoid MJCF on its own (no executive code involved).

The model is scenarios/robots/humanoid/humanoid.xml, a Valkyrie-proportioned
humanoid with parallel-jaw grippers. The file has no floor; tests that need one
add a plane with ``mujoco.MjSpec``. References are independent of the model:
names come from the profile YAML, targets from the book_transfer scene, and
tolerances from what the executive relies on (feet fixed, top-down grasps,
a book that stays in the hand while the wrist shakes).
"""

from __future__ import annotations

from pathlib import Path

import mink
import mujoco
import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
ROBOT_DIR = ROOT / "scenarios" / "robots" / "humanoid"
MJCF = ROBOT_DIR / "humanoid.xml"
PROFILE = ROBOT_DIR / "profile.yaml"
SIDES = ("left", "right")

LEG_JOINTS = ("hip_yaw", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
ARM_JOINTS = (
    "shoulder_pitch",
    "shoulder_roll",
    "shoulder_yaw",
    "elbow",
    "forearm_yaw",
    "wrist_roll",
    "wrist_pitch",
)
WAIST_JOINTS = ("waist_yaw", "waist_pitch", "waist_roll")
GRIP_OPEN = 0.085  # half gap between the pads, m

# Book of the book_transfer scene (full sizes, m; kg).
BOOK_SIZE = np.array([0.16, 0.11, 0.045])
BOOK_MASS = 0.6

# Top-down hand orientation: site z (approach) down, site y (closing) along world +y.
TOP_DOWN = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])

FREE, HINGE, SLIDE = (
    int(t) for t in (mujoco.mjtJoint.mjJNT_FREE, mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)
)


# ----------------------------------------------------------------------------- helpers


def _spec_with_floor() -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(MJCF))
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1], name="floor")
    return spec


def _id(model: mujoco.MjModel, obj: mujoco.mjtObj, name: str) -> int:
    i = mujoco.mj_name2id(model, obj, name)
    assert i >= 0, f"{obj.name} '{name}' missing from the model"
    return int(i)


def _qadr(model: mujoco.MjModel, joint: str) -> int:
    return int(model.jnt_qposadr[_id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)])


def _tilt_deg(data: mujoco.MjData, body: int) -> float:
    """Angle between the body's z axis and world z."""
    return float(np.degrees(np.arccos(np.clip(data.xmat[body][8], -1.0, 1.0))))


def _sole_corners(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> np.ndarray:
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    rot = data.geom_xmat[geom].reshape(3, 3)
    return data.geom_xpos[geom] + (signs * model.geom_size[geom]) @ rot.T


def _can_collide(model: mujoco.MjModel, g1: int, g2: int) -> bool:
    """Whether MuJoCo's broad filters let geoms g1 and g2 make contact."""
    if not (
        model.geom_contype[g1] & model.geom_conaffinity[g2]
        or model.geom_contype[g2] & model.geom_conaffinity[g1]
    ):
        return False
    b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
    if b1 == b2 or model.body_parentid[b1] == b2 or model.body_parentid[b2] == b1:
        return False
    excluded = set(model.exclude_signature[: model.nexclude].tolist())
    return not ({(b1 << 16) + b2, (b2 << 16) + b1} & excluded)


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(MJCF))


@pytest.fixture(scope="module")
def profile() -> dict:
    with PROFILE.open() as f:
        return yaml.safe_load(f)


# ----------------------------------------------------------------------------- 1. structure


def test_compiles_with_valkyrie_like_structure(model: mujoco.MjModel) -> None:
    assert model.names[: model.names.index(b"\0")].decode() == "humanoid"
    assert model.opt.timestep == pytest.approx(0.002)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert model.opt.impratio == pytest.approx(10.0)

    # One free joint (the base), every other joint a hinge or slide with exactly one actuator.
    types = [int(t) for t in model.jnt_type]
    assert types.count(FREE) == 1
    free = _id(model, mujoco.mjtObj.mjOBJ_JOINT, "floating_base")
    assert model.jnt_bodyid[free] == _id(model, mujoco.mjtObj.mjOBJ_BODY, "pelvis")
    actuated = [j for j in range(model.njnt) if types[j] in (HINGE, SLIDE)]
    assert model.nu == len(actuated) == model.njnt - 1
    assert np.all(model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT)
    targets = sorted(int(j) for j in model.actuator_trnid[:, 0])
    assert targets == sorted(actuated), "each hinge/slide joint must carry exactly one actuator"
    assert free not in targets

    for side in SIDES:
        for j in LEG_JOINTS + ARM_JOINTS:
            jid = _id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{side}_{j}")
            assert types[jid] == HINGE
        for body in ("foot", "forearm", "palm"):
            _id(model, mujoco.mjtObj.mjOBJ_BODY, f"{side}_{body}")
        for jaw in ("a", "b"):
            jid = _id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{side}_finger_{jaw}_slide")
            assert types[jid] == SLIDE
            assert model.jnt_range[jid] == pytest.approx([0.0, GRIP_OPEN])
            finger_body = model.jnt_bodyid[jid]
            assert model.body_parentid[finger_body] == _id(model, mujoco.mjtObj.mjOBJ_BODY, f"{side}_palm")
            act = _id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{side}_grip_{jaw}")
            assert model.actuator_trnid[act, 0] == jid
            assert 40.0 <= model.actuator_forcerange[act, 1] <= 80.0
    for j in WAIST_JOINTS:
        assert types[_id(model, mujoco.mjtObj.mjOBJ_JOINT, j)] == HINGE
    assert len(LEG_JOINTS) * 2 + len(WAIST_JOINTS) + len(ARM_JOINTS) * 2 + 4 == model.nu

    # Joint actuators are position servos named like their joints, ctrlrange = joint range.
    for a in range(model.nu):
        j = int(model.actuator_trnid[a, 0])
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        if int(model.jnt_type[j]) == HINGE:
            assert name == mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        assert (
            model.actuator_gainprm[a, 0] > 0 and model.actuator_biasprm[a, 1] == -model.actuator_gainprm[a, 0]
        )
        assert model.actuator_biasprm[a, 2] < 0, f"{name}: servo needs damping"
        assert model.actuator_ctrlrange[a] == pytest.approx(model.jnt_range[j])
        assert model.actuator_forcelimited[a] and 10.0 <= model.actuator_forcerange[a, 1] <= 400.0

    # No floor or table: only the robot's own geoms, none of them a plane.
    assert not np.any(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
    assert model.nmesh == 0

    # Valkyrie-like mass, with no implausibly light or heavy link.
    total = float(np.sum(model.body_mass))
    assert 120.0 <= total <= 135.0
    assert np.all(model.body_mass[1:] > 0.005)
    assert np.all(model.body_inertia[1:] > 0.0)
    assert model.body_mass[_id(model, mujoco.mjtObj.mjOBJ_BODY, "torso")] == pytest.approx(38.0, abs=5.0)


def test_profile_names_exist(model: mujoco.MjModel, profile: dict) -> None:
    body, joint, site, act, geom = (
        mujoco.mjtObj.mjOBJ_BODY,
        mujoco.mjtObj.mjOBJ_JOINT,
        mujoco.mjtObj.mjOBJ_SITE,
        mujoco.mjtObj.mjOBJ_ACTUATOR,
        mujoco.mjtObj.mjOBJ_GEOM,
    )
    assert profile["name"] == "humanoid"
    assert (ROBOT_DIR / profile["mjcf"]).resolve() == MJCF
    for key in ("base_body", "torso_body", "head_body"):
        _id(model, body, profile[key])
    _id(model, mujoco.mjtObj.mjOBJ_KEY, profile["keyframe"])
    for name in profile["waist_joints"]:
        _id(model, joint, name)
    for side in SIDES:
        for name in profile["legs"][side]:
            _id(model, joint, name)
        foot = profile["feet"][side]
        foot_id = _id(model, body, foot["body"])
        for name in foot["geoms"]:
            assert model.geom_bodyid[_id(model, geom, name)] == foot_id
        arm = profile["arms"][side]
        assert [n.removeprefix(f"{side}_") for n in arm["joints"]] == list(ARM_JOINTS)
        for name in arm["joints"]:
            _id(model, joint, name)
        palm = _id(model, body, arm["hand_body"])
        assert model.site_bodyid[_id(model, site, arm["hand"]["site"])] == palm
        _id(model, body, arm["forearm_body"])
        grip = arm["gripper"]
        for name, opened, closed in zip(grip["actuators"], grip["open"], grip["closed"], strict=True):
            a = _id(model, act, name)
            lo, hi = model.actuator_ctrlrange[a]
            assert lo <= closed <= hi and lo <= opened <= hi
            assert opened == pytest.approx(GRIP_OPEN) and closed == pytest.approx(0.0)


def test_stand_keyframe_geometry(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    key = _id(model, mujoco.mjtObj.mjOBJ_KEY, "stand")
    mujoco.mj_resetDataKeyframe(model, data, key)
    mujoco.mj_forward(model, data)

    # ctrl holds every actuated joint where the keyframe puts it; grippers open.
    for a in range(model.nu):
        q = data.qpos[model.jnt_qposadr[model.actuator_trnid[a, 0]]]
        assert data.ctrl[a] == pytest.approx(q, abs=1e-9)
    for side in SIDES:
        for jaw in ("a", "b"):
            assert data.qpos[_qadr(model, f"{side}_finger_{jaw}_slide")] == pytest.approx(GRIP_OPEN)

    # Soles: about 0.26 x 0.15 m, flat, resting on z = 0, 0.25-0.30 m apart.
    soles = [_id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_sole") for s in SIDES]
    for g in soles:
        assert model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
        assert 2 * model.geom_size[g][0] == pytest.approx(0.26, abs=0.02)
        assert 2 * model.geom_size[g][1] == pytest.approx(0.15, abs=0.02)
        bottom = np.sort(_sole_corners(model, data, g)[:, 2])[:4]
        assert np.all(np.abs(bottom) < 2e-4), f"sole not flat on the floor: {bottom}"
    spacing = np.linalg.norm(data.geom_xpos[soles[0]] - data.geom_xpos[soles[1]])
    assert 0.25 <= spacing <= 0.30

    # Height ~1.8 m (top of the head), torso upright, CoM over the middle of the feet.
    head = _id(model, mujoco.mjtObj.mjOBJ_GEOM, "head_geom")
    top = data.geom_xpos[head][2] + model.geom_size[head][0]
    assert 1.75 <= top <= 1.90
    assert _tilt_deg(data, _id(model, mujoco.mjtObj.mjOBJ_BODY, "torso")) < 0.5
    middle = 0.5 * (data.geom_xpos[soles[0]] + data.geom_xpos[soles[1]])
    assert np.linalg.norm(data.subtree_com[0][:2] - middle[:2]) < 0.01

    # Ready pose: hands in front at about table height, elbows bent, approach pointing down-ish.
    for side in SIDES:
        s = _id(model, mujoco.mjtObj.mjOBJ_SITE, f"{side}_hand")
        x, y, z = data.site_xpos[s]
        assert 0.2 <= x <= 0.4 and 0.85 <= z <= 1.05 and (y > 0.1 if side == "left" else y < -0.1)
        assert data.site_xmat[s].reshape(3, 3)[2, 2] < -0.9
        assert data.qpos[_qadr(model, f"{side}_elbow")] < -0.8

    # The head camera looks forward and down at the table in front.
    cam = _id(model, mujoco.mjtObj.mjOBJ_CAMERA, "head_camera")
    assert model.cam_bodyid[cam] == _id(model, mujoco.mjtObj.mjOBJ_BODY, "head")
    view = -data.cam_xmat[cam].reshape(3, 3)[:, 2]
    assert view[0] > 0.3 and view[2] < -0.5


def test_self_collision_filters(model: mujoco.MjModel) -> None:
    """Overlapping neighbours are excluded; hands can still hit the body and each other."""
    g = {
        n: _id(model, mujoco.mjtObj.mjOBJ_GEOM, n)
        for n in (
            "pelvis_geom",
            "torso_geom",
            "head_geom",
            "left_thigh_geom",
            "right_thigh_geom",
            "left_upper_arm_geom",
            "left_forearm_geom",
            "left_palm_geom",
            "left_pad_a",
            "right_palm_geom",
            "right_forearm_geom",
            "left_shin_geom",
            "left_sole",
        )
    }
    must = [
        ("left_palm_geom", "torso_geom"),
        ("left_palm_geom", "head_geom"),
        ("left_palm_geom", "left_thigh_geom"),
        ("left_palm_geom", "pelvis_geom"),
        ("left_forearm_geom", "torso_geom"),
        ("left_forearm_geom", "left_thigh_geom"),
        ("left_pad_a", "torso_geom"),
        ("left_palm_geom", "right_palm_geom"),
        ("left_forearm_geom", "right_forearm_geom"),
        ("left_thigh_geom", "right_thigh_geom"),
    ]
    for a, b in must:
        assert _can_collide(model, g[a], g[b]), f"{a} and {b} must be able to collide"
    never = [
        ("pelvis_geom", "torso_geom"),
        ("pelvis_geom", "left_thigh_geom"),
        ("torso_geom", "left_upper_arm_geom"),
        ("left_upper_arm_geom", "left_forearm_geom"),
        ("left_forearm_geom", "left_palm_geom"),
        ("left_shin_geom", "left_sole"),
    ]
    for a, b in never:
        assert not _can_collide(model, g[a], g[b]), f"{a} and {b} overlap by construction"


# ----------------------------------------------------------------------------- 2. standing


@pytest.mark.slow
def test_stands_still_for_30_seconds() -> None:
    model = _spec_with_floor().compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, _id(model, mujoco.mjtObj.mjOBJ_KEY, "stand"))
    mujoco.mj_forward(model, data)
    ctrl = data.ctrl.copy()

    pelvis = _id(model, mujoco.mjtObj.mjOBJ_BODY, "pelvis")
    torso = _id(model, mujoco.mjtObj.mjOBJ_BODY, "torso")
    floor = _id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    soles = {_id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_sole") for s in SIDES}
    allowed = {frozenset((floor, s)) for s in soles}

    def check_contacts() -> None:
        pairs = {frozenset((int(c.geom1), int(c.geom2))) for c in data.contact[: data.ncon]}
        names = [
            tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, i) for i in p) for p in pairs - allowed
        ]
        assert not names, f"unexpected contacts at t={data.time:.3f}: {names}"

    check_contacts()
    z0 = float(data.xpos[pelvis][2])
    max_drop = max_tilt = max_pen = 0.0
    for _ in range(15000):  # 30 s
        mujoco.mj_step(model, data)
        max_drop = max(max_drop, abs(float(data.xpos[pelvis][2]) - z0))
        max_tilt = max(max_tilt, _tilt_deg(data, torso))
        max_pen = max(max_pen, -min((float(c.dist) for c in data.contact[: data.ncon]), default=0.0))
        check_contacts()
    assert np.all(data.ctrl == ctrl)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    print(
        f"pelvis drift max {max_drop * 1000:.2f} mm, torso tilt max {max_tilt:.3f} deg, "
        f"sole penetration max {max_pen * 1000:.2f} mm"
    )
    assert max_drop < 0.02
    assert max_tilt < 2.0
    assert max_pen < 0.002
    # Joint servos hold the pose: no joint more than ~1 degree off its target at rest.
    assert np.max(np.abs(data.qpos[7:] - ctrl)) < 0.02


# ----------------------------------------------------------------------------- 3. reach across


@pytest.mark.parametrize(("side", "target"), [("left", (0.48, -0.20, 0.85)), ("right", (0.48, 0.20, 0.85))])
def test_mink_reach_across_the_midline(
    model: mujoco.MjModel, side: str, target: tuple[float, float, float]
) -> None:
    """Whole-body IK puts a hand top-down on the table across the body, feet fixed, CoM over the feet."""
    cfg = mink.Configuration(model)
    cfg.update_from_keyframe("stand")
    soles = [_id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_sole") for s in SIDES]
    corners = np.vstack([_sole_corners(model, cfg.data, g) for g in soles])
    lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
    middle = 0.5 * (cfg.data.geom_xpos[soles[0]] + cfg.data.geom_xpos[soles[1]])

    feet = []
    for s in SIDES:
        task = mink.FrameTask(f"{s}_foot", "body", position_cost=1000.0, orientation_cost=1000.0)
        task.set_target_from_configuration(cfg)
        feet.append(task)
    feet_start = [cfg.get_transform_frame_to_world(f"{s}_foot", "body") for s in SIDES]
    com = mink.ComTask(cost=[100.0, 100.0, 0.0])
    com.set_target(middle)
    goal = mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(TOP_DOWN), np.array(target))
    hand = mink.FrameTask(f"{side}_hand", "site", position_cost=10.0, orientation_cost=10.0)
    hand.set_target(goal)
    posture = mink.PostureTask(model, cost=0.1)
    posture.set_target_from_configuration(cfg)
    fingers = [
        int(model.jnt_dofadr[_id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{s}_finger_{j}_slide")])
        for s in SIDES
        for j in ("a", "b")
    ]
    frozen = mink.DofFreezingTask(model, dof_indices=fingers)
    limits = [mink.ConfigurationLimit(model)]

    dt = 0.01
    for _ in range(400):
        vel = mink.solve_ik(
            cfg,
            [*feet, com, hand, posture],
            dt,
            solver="daqp",
            damping=1e-3,
            limits=limits,
            constraints=[frozen],
        )
        cfg.integrate_inplace(vel, dt)

    reached = cfg.get_transform_frame_to_world(f"{side}_hand", "site")
    pos_err = float(np.linalg.norm(reached.translation() - goal.translation()))
    rot_err = float(np.degrees(np.linalg.norm((goal.rotation().inverse() @ reached.rotation()).log())))
    feet_moved = max(
        float(
            np.linalg.norm(
                cfg.get_transform_frame_to_world(f"{s}_foot", "body").translation() - start.translation()
            )
        )
        for s, start in zip(SIDES, feet_start, strict=True)
    )
    feet_turned = max(
        float(
            np.degrees(
                np.linalg.norm(
                    (
                        start.rotation().inverse()
                        @ cfg.get_transform_frame_to_world(f"{s}_foot", "body").rotation()
                    ).log()
                )
            )
        )
        for s, start in zip(SIDES, feet_start, strict=True)
    )
    com_xy = cfg.data.subtree_com[0][:2]
    print(
        f"{side}: hand error {pos_err * 1000:.2f} mm, {rot_err:.3f} deg; "
        f"feet moved {feet_moved * 1000:.4f} mm, {feet_turned:.4f} deg; CoM xy {com_xy}"
    )
    assert pos_err < 0.01
    assert rot_err < 5.0
    assert feet_moved < 0.001
    assert feet_turned < 0.1
    assert np.all(com_xy > lo) and np.all(com_xy < hi)
    # The solution respects the joint limits (mink's ConfigurationLimit).
    for j in range(1, model.njnt):
        q = cfg.q[model.jnt_qposadr[j]]
        assert model.jnt_range[j, 0] - 1e-6 <= q <= model.jnt_range[j, 1] + 1e-6


# ----------------------------------------------------------------------------- 4. grasp


@pytest.mark.parametrize("side", SIDES)
def test_gripper_holds_the_book_while_the_wrist_shakes(side: str) -> None:
    other = "right" if side == "left" else "left"
    # Hand site pose at the stand keyframe (robot alone).
    robot = mujoco.MjModel.from_xml_path(str(MJCF))
    rdata = mujoco.MjData(robot)
    mujoco.mj_resetDataKeyframe(robot, rdata, _id(robot, mujoco.mjtObj.mjOBJ_KEY, "stand"))
    mujoco.mj_forward(robot, rdata)
    site = _id(robot, mujoco.mjtObj.mjOBJ_SITE, f"{side}_hand")
    pos = rdata.site_xpos[site].copy()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rdata.site_xmat[site])

    # Scene: robot + floor + the book centred between the open jaws, its 11 cm side
    # along the closing direction (site y), floating (gravcomp) until the jaws close.
    spec = _spec_with_floor()
    book = spec.worldbody.add_body(name="book", pos=pos, quat=quat, gravcomp=1.0)
    book.add_freejoint(name="book_free")
    book.add_geom(
        name="book_geom",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=BOOK_SIZE / 2,
        mass=BOOK_MASS,
        friction=[1.0, 0.005, 0.0001],
    )
    key = spec.keys[0]
    key.qpos = [*key.qpos, *pos, *quat]
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, _id(model, mujoco.mjtObj.mjOBJ_KEY, "stand"))
    mujoco.mj_forward(model, data)
    soles = {_id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_sole") for s in SIDES}
    floor = _id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    start = {frozenset((int(c.geom1), int(c.geom2))) for c in data.contact[: data.ncon]}
    assert start == {frozenset((floor, s)) for s in soles}, "only the soles may touch anything at the start"

    bid = _id(model, mujoco.mjtObj.mjOBJ_BODY, "book")
    site = _id(model, mujoco.mjtObj.mjOBJ_SITE, f"{side}_hand")
    pelvis = _id(model, mujoco.mjtObj.mjOBJ_BODY, "pelvis")
    torso = _id(model, mujoco.mjtObj.mjOBJ_BODY, "torso")
    book_geom = _id(model, mujoco.mjtObj.mjOBJ_GEOM, "book_geom")
    act = {
        n: _id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n)
        for n in (
            f"{side}_grip_a",
            f"{side}_grip_b",
            f"{other}_grip_a",
            f"{other}_grip_b",
            f"{side}_wrist_pitch",
            f"{side}_forearm_yaw",
        )
    }
    ctrl0 = data.ctrl.copy()
    z0 = float(data.xpos[pelvis][2])

    def book_in_hand() -> np.ndarray:
        rot = data.site_xmat[site].reshape(3, 3)
        return rot.T @ (data.xpos[bid] - data.site_xpos[site])

    def touches_floor() -> bool:
        return any({int(c.geom1), int(c.geom2)} == {floor, book_geom} for c in data.contact[: data.ncon])

    # Close both grippers (the other one on nothing).
    for jaw in ("a", "b"):
        data.ctrl[act[f"{side}_grip_{jaw}"]] = 0.0
        data.ctrl[act[f"{other}_grip_{jaw}"]] = 0.0
    dt = model.opt.timestep
    for _ in range(round(0.5 / dt)):
        mujoco.mj_step(model, data)
    held = [data.qpos[_qadr(model, f"{side}_finger_{j}_slide")] for j in ("a", "b")]
    empty = [data.qpos[_qadr(model, f"{other}_finger_{j}_slide")] for j in ("a", "b")]
    assert held == pytest.approx([BOOK_SIZE[1] / 2] * 2, abs=0.003), "jaws rest on the book's 11 cm sides"
    assert empty == pytest.approx([0.0, 0.0], abs=0.001), "an empty gripper closes fully"
    grip = [abs(float(data.actuator_force[act[f"{side}_grip_{j}"]])) for j in ("a", "b")]
    assert all(40.0 <= f <= 80.0 for f in grip)
    reference = book_in_hand()
    assert np.linalg.norm(reference) < 0.005

    # Gravity on: hold 2 s, then shake the wrist 0.3 rad at 2 Hz for 2 s.
    model.body_gravcomp[bid] = 0.0
    t_start = data.time
    max_drift = max_offset = max_tilt = max_drop = 0.0
    while data.time < t_start + 4.0 - dt / 2:
        t = data.time - t_start
        if t >= 2.0:
            shake = 0.3 * np.sin(2 * np.pi * 2.0 * (t - 2.0))
            data.ctrl[act[f"{side}_wrist_pitch"]] = ctrl0[act[f"{side}_wrist_pitch"]] + shake
            data.ctrl[act[f"{side}_forearm_yaw"]] = ctrl0[act[f"{side}_forearm_yaw"]] + shake
        mujoco.mj_step(model, data)
        rel = book_in_hand()
        max_drift = max(max_drift, float(np.linalg.norm(rel - reference)))
        max_offset = max(max_offset, float(np.linalg.norm(rel)))
        max_tilt = max(max_tilt, _tilt_deg(data, torso))
        max_drop = max(max_drop, z0 - float(data.xpos[pelvis][2]))
        assert not touches_floor(), f"book touched the floor at t={t:.3f}"
    print(
        f"{side}: book drift in hand max {max_drift * 1000:.2f} mm (offset {max_offset * 1000:.2f} mm); "
        f"torso tilt max {max_tilt:.3f} deg; pelvis drop max {max_drop * 1000:.2f} mm"
    )
    assert np.all(np.isfinite(data.qpos))
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert max_drift < 0.01
    assert max_offset < 0.01
    assert max_tilt < 2.0 and max_drop < 0.02, "the robot must stay standing"
