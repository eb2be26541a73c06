"""Robot profiles: the bundled ones load; malformed ones fail with the key path; the G1 matches its model."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from executive.errors import RobotProfileError, ScenarioError
from executive.robot.profile import load_bundled_profile, load_profile, loads_profile
from executive.robot.profile_types import RobotProfile
from executive.schema import catalog as registry

G1_DIR = Path(__file__).resolve().parents[2] / "shared" / "robots" / "unitree_g1"


def test_bundled_humanoid_profile() -> None:
    p = load_bundled_profile("humanoid")
    folder = registry.bundled_root() / "robots" / "humanoid"
    assert p.name == "humanoid"
    assert p.mjcf == (folder / "humanoid.xml").resolve()
    assert p.source == (folder / "profile.yaml").resolve()
    assert (p.base_body, p.torso_body, p.head_body, p.keyframe) == ("pelvis", "torso", "head", "stand")
    assert p.sides == ("left", "right")
    assert p.arms["left"].hand.site == "left_hand"
    assert p.arms["left"].hand.body is None
    assert len(p.arms["right"].joints) == 7
    assert p.arms["right"].gripper.open == (0.085, 0.085)
    assert p.arms["right"].gripper.closed == (0.0, 0.0)
    assert p.feet["left"].geoms == ("left_sole",)
    assert p.leg_joints["right"][3] == "right_knee"
    assert p.waist_joints == ("waist_yaw", "waist_pitch", "waist_roll")


def test_every_bundled_profile_loads() -> None:
    assert registry.list_robots() == ["humanoid", "unitree_g1"]
    for name in registry.list_robots():
        assert isinstance(load_bundled_profile(name), RobotProfile)


def test_g1_profile_schema() -> None:
    p = load_bundled_profile("unitree_g1")
    assert p.name == "unitree_g1"
    assert p.mjcf is None
    assert p.head_body is None
    for side in ("left", "right"):
        arm = p.arms[side]
        assert len(arm.joints) == 7
        assert arm.hand.site is None
        assert arm.hand.body == arm.hand_body
        assert len(arm.gripper.actuators) == len(arm.gripper.open) == len(arm.gripper.closed) == 7
        assert len(p.leg_joints[side]) == 6
        assert p.feet[side].geoms == ()
    assert p.arms["left"].hand.offset[1] == -p.arms["right"].hand.offset[1]
    # the Dex3 hands close with their fingers towards the midline; the arms stand a little out
    assert (p.arms["left"].hand.closing_yaw_deg, p.arms["right"].hand.closing_yaw_deg) == (-90.0, 90.0)
    assert p.home_joints == {"left_shoulder_roll_joint": 0.4, "right_shoulder_roll_joint": -0.4}
    assert load_bundled_profile("humanoid").arms["left"].hand.closing_yaw_deg is None
    assert p.return_along_lane and not load_bundled_profile("humanoid").return_along_lane
    assert load_bundled_profile("humanoid").home_joints == {}


def test_unknown_bundled_robot_lists_the_bundled_ones() -> None:
    with pytest.raises(RobotProfileError, match="bundled robots are: humanoid, unitree_g1"):
        load_bundled_profile("atlas")


# ----------------------------------------------------------------------------- malformed

Doc = dict[str, Any]


def put(path: str, value: object) -> Callable[[Doc], Doc]:
    def mutate(data: Doc) -> Doc:
        *parents, last = path.split(".")
        node = data
        for key in parents:
            node = node[key]
        node[last] = value
        return data

    return mutate


def drop(path: str) -> Callable[[Doc], Doc]:
    def mutate(data: Doc) -> Doc:
        *parents, last = path.split(".")
        node = data
        for key in parents:
            node = node[key]
        del node[last]
        return data

    return mutate


PROFILE_CASES: list[tuple[str, Callable[[Doc], Doc], str, str]] = [
    ("missing-name", drop("name"), "name", "missing required key 'name'"),
    ("unknown-top-key", put("torso", "x"), "torso", "unknown key 'torso'"),
    ("misspelt-key", put("arms.left.hand_bdy", "x"), "arms.left.hand_bdy", "did you mean 'hand_body'?"),
    ("missing-arm", drop("arms.right"), "arms.right", "missing required key 'right'"),
    ("extra-side", put("legs.middle", ["x"]), "legs.middle", "unknown key 'middle'"),
    ("empty-arm-joints", put("arms.left.joints", []), "arms.left.joints", "at least 1 item"),
    (
        "joint-not-a-string",
        put("waist_joints", ["waist_yaw", 3]),
        "waist_joints[1]",
        "expected a string, got int 3",
    ),
    (
        "gripper-length-mismatch",
        put("arms.left.gripper.closed", [0.0]),
        "arms.left.gripper.closed",
        "expected a list of 2 numbers (one per actuator)",
    ),
    (
        "gripper-nan",
        put("arms.right.gripper.open", [0.085, float("nan")]),
        "arms.right.gripper.open[1]",
        "finite",
    ),
    (
        "hand-site-and-body",
        put("arms.left.hand", {"site": "a", "body": "b"}),
        "arms.left.hand",
        "exactly one of",
    ),
    ("hand-neither", put("arms.left.hand", {}), "arms.left.hand", "exactly one of"),
    (
        "offset-with-site",
        put("arms.left.hand", {"site": "a", "offset": [0, 0, 0]}),
        "arms.left.hand.offset",
        "only applies with 'body'",
    ),
    (
        "offset-length",
        put("arms.left.hand", {"body": "b", "offset": [0, 0]}),
        "arms.left.hand.offset",
        "expected a list of 3 numbers",
    ),
    (
        "zero-quat",
        put("arms.left.hand", {"body": "b", "quat": [0, 0, 0, 0]}),
        "arms.left.hand.quat",
        "zero quaternion",
    ),
    ("missing-mjcf", put("mjcf", "nowhere.xml"), "mjcf", "MJCF file not found"),
    ("foot-not-a-mapping", put("feet.left", "left_foot"), "feet.left", "expected a mapping, got str"),
    (
        "duplicate-joint",
        put("waist_joints", ["waist_yaw", "left_knee"]),
        "legs.left[3]",
        "joint 'left_knee' is listed twice (also at waist_joints[1])",
    ),
    ("bool-keyframe", put("keyframe", True), "keyframe", "expected a string, got bool True"),
    (
        "closing-yaw-range",
        put("arms.left.hand", {"site": "a", "closing_yaw": 270}),
        "arms.left.hand.closing_yaw",
        "expected a number >= -180 and <= 180, got int 270",
    ),
    (
        "closing-yaw-string",
        put("arms.right.hand", {"body": "b", "closing_yaw": "left"}),
        "arms.right.hand.closing_yaw",
        "expected a number, got str",
    ),
    ("home-joints-list", put("home_joints", [0.1]), "home_joints", "expected a mapping"),
    (
        "home-joint-angle",
        put("home_joints", {"left_shoulder1": "up"}),
        "home_joints.left_shoulder1",
        "expected a number, got str",
    ),
    ("return-along-lane-int", put("return_along_lane", 1), "return_along_lane", "expected true or false"),
]


@pytest.mark.parametrize(
    ("mutate", "key_path", "message"), [c[1:] for c in PROFILE_CASES], ids=[c[0] for c in PROFILE_CASES]
)
def test_malformed_profile_names_the_key_path(
    mutate: Callable[[Doc], Doc], key_path: str, message: str, tmp_path: Path
) -> None:
    original = yaml.safe_load(registry.robot_profile_path("humanoid").read_text())  # type: ignore[union-attr]
    (tmp_path / "humanoid.xml").write_text("<mujoco/>\n")
    path = tmp_path / "profile.yaml"
    path.write_text(yaml.safe_dump(mutate(copy.deepcopy(original))))
    with pytest.raises(RobotProfileError) as info:
        load_profile(path)
    assert key_path in info.value.key_path, str(info.value)
    assert message in info.value.problem, str(info.value)
    assert str(info.value).startswith(f"{path}: ")


def test_profile_yaml_errors_are_profile_errors() -> None:
    for text in ("", "- a", "a: &a [*a]", "name: !!python/object/apply:os.system [ls]"):
        with pytest.raises(RobotProfileError):
            loads_profile(text)
    assert issubclass(RobotProfileError, ScenarioError)


def test_hand_quat_is_normalised(tmp_path: Path) -> None:
    data = yaml.safe_load((registry.robot_profile_path("unitree_g1") or Path()).read_text())
    data["arms"]["left"]["hand"]["quat"] = [2.0, 0.0, 0.0, 0.0]
    p = loads_profile(yaml.safe_dump(data), base_dir=tmp_path)
    assert p.arms["left"].hand.quat == (1.0, 0.0, 0.0, 0.0)


# ----------------------------------------------------------------------------- G1 against its model


@pytest.fixture(scope="module")
def g1_model() -> Any:
    xml = G1_DIR / "g1_with_hands.xml"
    if not xml.is_file():
        pytest.skip(f"the Unitree G1 model is not available at {xml}")
    mujoco = pytest.importorskip("mujoco")
    return mujoco.MjModel.from_xml_path(str(xml))


def test_every_name_in_the_g1_profile_exists_in_the_model(g1_model: Any) -> None:
    import mujoco

    p = load_bundled_profile("unitree_g1")
    obj = mujoco.mjtObj

    def exists(kind: Any, name: str) -> bool:
        return int(mujoco.mj_name2id(g1_model, kind, name)) >= 0

    bodies = [p.base_body, p.torso_body, *(f.body for f in p.feet.values())]
    joints = [*p.waist_joints, *(j for legs in p.leg_joints.values() for j in legs)]
    actuators: list[str] = []
    for arm in p.arms.values():
        bodies += [arm.hand_body, *(b for b in (arm.forearm_body, arm.hand.body) if b is not None)]
        joints += arm.joints
        actuators += arm.gripper.actuators
        if arm.hand.site is not None:
            assert exists(obj.mjOBJ_SITE, arm.hand.site), arm.hand.site
    if p.head_body is not None:
        bodies.append(p.head_body)
    missing = [b for b in bodies if not exists(obj.mjOBJ_BODY, b)]
    missing += [j for j in joints if not exists(obj.mjOBJ_JOINT, j)]
    missing += [a for a in actuators if not exists(obj.mjOBJ_ACTUATOR, a)]
    missing += [g for f in p.feet.values() for g in f.geoms if not exists(obj.mjOBJ_GEOM, g)]
    assert missing == []
    assert exists(obj.mjOBJ_KEY, p.keyframe)
    # 29 body joints + 14 hand joints: the profile names every hinge joint except the hands'
    assert len(joints) == 29 and g1_model.njnt == 1 + 29 + 14
    for arm in p.arms.values():
        # the hand frame's site belongs to the hand's subtree
        hand = g1_model.body(arm.hand_body).id
        assert g1_model.body(arm.hand.body).id == hand
        # each gripper target lies within its actuator's control range
        for name, low_high in zip(
            arm.gripper.actuators, zip(arm.gripper.open, arm.gripper.closed, strict=True), strict=True
        ):
            lo, hi = g1_model.actuator(name).ctrlrange
            assert all(lo - 1e-9 <= v <= hi + 1e-9 for v in low_high), name


def _hand_points(model: Any, side: str, pose: tuple[float, ...]) -> dict[str, np.ndarray]:
    """Vertices of the collision meshes of one G1 hand, in its profile hand frame, by forward
    kinematics with the gripper joints at ``pose``: "palm" (the wrist link), "thumb", "fingers"."""
    import mujoco

    p = load_bundled_profile("unitree_g1")
    arm = p.arms[side]
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(p.keyframe).id)
    for name, value in zip(arm.gripper.actuators, pose, strict=True):
        data.qpos[model.jnt_qposadr[model.actuator(name).trnid[0]]] = value
    mujoco.mj_kinematics(model, data)
    wrist = model.body(arm.hand_body).id
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.array(arm.hand.quat))
    site_rot = data.xmat[wrist].reshape(3, 3) @ rot.reshape(3, 3)
    site_pos = data.xpos[wrist] + data.xmat[wrist].reshape(3, 3) @ np.array(arm.hand.offset)
    out: dict[str, list[np.ndarray]] = {"palm": [], "thumb": [], "fingers": []}
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        name = model.body(body).name
        if not model.geom_contype[g] or not (body == wrist or name.startswith(f"{side}_hand_")):
            continue
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = model.geom_dataid[g]
            start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            local = model.mesh_vert[start : start + count]
        else:  # a box or other primitive: the corners of its size box
            signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
            local = signs * model.geom_size[g]
        world = data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T
        part = "palm" if body == wrist else "thumb" if "thumb" in name else "fingers"
        out[part].append((world - site_pos) @ site_rot)
    return {k: np.vstack(v) for k, v in out.items()}


@pytest.mark.parametrize("side", ["left", "right"])
def test_g1_hand_frame_pinches_across_a_book(g1_model: Any, side: str) -> None:
    """The G1 hand frame against the Dex3 collision meshes (forward kinematics, not the profile's
    numbers): palm above the site (+z, the approach, points away from it), thumb on -y and the two
    fingers on +y with the site midway, open wide enough for the test scene's 9 cm book with room
    for the approach, shallow enough for a site 1 cm under the top of the 4 cm book to keep the
    open hand clear of the table, and closing onto the book: fingers to its face, thumb past it."""
    arm = load_bundled_profile("unitree_g1").arms[side]
    half_width, top, bottom = 0.045, -0.01, 0.03  # the book in the site frame (z down)
    open_ = _hand_points(g1_model, side, arm.gripper.open)
    # palm down: the whole palm lies behind the grasp point, at least 3 cm
    assert open_["palm"][:, 2].max() < -0.03
    # what passes beside the book on the way down (below its top face): thumb on -y, fingers on +y
    thumb = open_["thumb"][open_["thumb"][:, 2] > top]
    fingers = open_["fingers"][open_["fingers"][:, 2] > top]
    assert len(thumb) and len(fingers)
    inner_thumb, inner_fingers = float(thumb[:, 1].max()), float(fingers[:, 1].min())
    assert inner_thumb < -(half_width + 0.02) and inner_fingers > half_width + 0.02  # 2 cm each side
    assert abs(inner_thumb + inner_fingers) < 0.002  # the site is midway
    # the lowest point of the open hand: 1 to 2 cm past the site (the table is 3 cm past it)
    lowest = max(float(v[:, 2].max()) for v in open_.values())
    assert 0.01 <= lowest <= bottom - 0.01
    # closed: the finger tips just reach into the book's face (a squeeze of under 6 mm) and the
    # thumb presses well past it (it pushes the book against the fingers)
    closed = _hand_points(g1_model, side, arm.gripper.closed)
    band = closed["fingers"][(closed["fingers"][:, 2] > top) & (closed["fingers"][:, 2] < bottom)]
    assert half_width - 0.006 < float(band[:, 1].min()) < half_width
    assert float(closed["thumb"][:, 1].max()) > -half_width + 0.02
