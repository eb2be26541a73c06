"""Load and validate robot profiles (YAML) into :class:`~executive.robot.profile_types.RobotProfile`.

The schema by example is ``scenarios/robots/humanoid/profile.yaml``::

    name: humanoid
    mjcf: humanoid.xml            # optional; relative to the profile file; must exist
    base_body: pelvis
    torso_body: torso
    head_body: head               # optional (null: no head)
    keyframe: stand
    home_joints: {name: angle}    # optional; rad, replacing the keyframe's angles of these joints
    return_along_lane: false      # optional; a hand that placed across the body goes back first
    unsupported_alternatives:     # optional; alternatives this robot cannot do, each with the reason
      left_to_right: "..."
    safe_posture:                 # optional; each key optional (defaults: world.posture.SafePosture)
      max_pelvis_drop: 0.10       # m below standing the planner may lower the pelvis
      max_trunk_tilt_deg: 20      # deg the planner may tilt the torso
      pelvis_tolerance: 0.05      # m deeper than that the detector still accepts
      tilt_tolerance_deg: 10      # deg more tilt the detector still accepts
    waist_joints: [...]
    legs: {left: [...], right: [...]}
    feet: {left: {body: ..., geoms: [...]}, right: {...}}      # geoms optional
    arms:
      left:
        joints: [...]             # shoulder to wrist, non-empty
        hand: {site: ...}         # or {body: ..., offset: [x, y, z], quat: [w, x, y, z]}
                                  # optional closing_yaw: deg (HandFrame.closing_yaw_deg)
        hand_body: ...
        forearm_body: ...         # optional
        gripper: {actuators: [...], open: [...], closed: [...]}   # equal lengths
      right: {...}

Every error is a :class:`~executive.errors.RobotProfileError` naming the file and key path.
Whether the names exist in the MJCF model is checked by the world builder.
"""

from __future__ import annotations

import math
from pathlib import Path

from executive.errors import RobotProfileError
from executive.robot.posture import SafePosture
from executive.robot.profile_types import ArmProfile, FootProfile, GripperProfile, HandFrame, RobotProfile
from executive.schema import catalog as registry
from executive.schema.yaml_nodes import Node, check_model_file, load_yaml_file, load_yaml_text

__all__ = ["SIDES", "load_bundled_profile", "load_profile", "loads_profile", "profile_from_node"]

#: The sides every profile describes, for arms, legs and feet.
SIDES: tuple[str, ...] = ("left", "right")

#: Ranges of the profile's numbers: home_joints angles (rad) within +-4 pi (two turns; the world
#: builder checks each against its joint's own range); safe_posture drops and
#: tolerances (m) in [0, 0.5] (its angles in [0, 90] deg); a hand frame's offset (m) within +-1;
#: gripper actuator targets within +-10 (the actuator's units: m for slides, rad for hinges).
JOINT_ANGLE_MAX = 4.0 * math.pi
POSTURE_DROP_MAX = 0.5
HAND_OFFSET_MAX = 1.0
GRIPPER_TARGET_MAX = 10.0

_TOP_REQUIRED = ("name", "base_body", "torso_body", "keyframe", "waist_joints", "legs", "feet", "arms")
_TOP_OPTIONAL = (
    "mjcf",
    "head_body",
    "home_joints",
    "return_along_lane",
    "safe_posture",
    "unsupported_alternatives",
)


def load_profile(path: Path) -> RobotProfile:
    """Load the profile file at ``path``; a relative ``mjcf`` is resolved against its folder."""
    try:
        path = Path(path).expanduser().resolve()
    except (OSError, ValueError, RuntimeError) as exc:  # a symlink loop, a NUL byte, ~nosuchuser
        raise RobotProfileError(str(path), "", f"invalid profile path: {exc}") from None
    root = load_yaml_file(path, RobotProfileError)
    return profile_from_node(root, base_dir=path.parent, source_path=path)


def loads_profile(text: str, source: str = "<string>", base_dir: Path | None = None) -> RobotProfile:
    """Load a profile from YAML text; a relative ``mjcf`` is resolved against ``base_dir`` (default: cwd)."""
    root = load_yaml_text(text, source, RobotProfileError)
    return profile_from_node(root, base_dir=base_dir if base_dir is not None else Path.cwd())


def load_bundled_profile(name: str) -> RobotProfile:
    """Load the profile of the bundled robot ``name``."""
    path = registry.robot_profile_path(name)
    if path is None:
        raise RobotProfileError(
            name, "", f"unknown robot; bundled robots are: {', '.join(registry.list_robots()) or '(none)'}"
        )
    return load_profile(path)


def profile_from_node(root: Node, base_dir: Path, source_path: Path | None = None) -> RobotProfile:
    """Validate a parsed profile document (the root :class:`Node`) and build the profile."""
    root.check_keys(_TOP_REQUIRED, _TOP_OPTIONAL)
    # Read in schema order, so the first error reported is the first in the document.
    name = root.get("name").string()
    mjcf_node = root.opt("mjcf")
    mjcf = mjcf_node.file_path(base_dir, "MJCF file") if mjcf_node is not None else None
    if mjcf_node is not None and mjcf is not None:
        check_model_file(mjcf_node, mjcf)
    base_body = root.get("base_body").string()
    torso_body = root.get("torso_body").string()
    head_node = root.opt("head_body")
    head_body = head_node.string() if head_node is not None else None
    keyframe = root.get("keyframe").string()
    home_node = root.opt("home_joints")
    home_joints = (
        {name: node.number(ge=-JOINT_ANGLE_MAX, le=JOINT_ANGLE_MAX) for name, node in home_node.items()}
        if home_node is not None
        else {}
    )
    lane_node = root.opt("return_along_lane")
    return_along_lane = lane_node.boolean() if lane_node is not None else False
    waist_joints = root.get("waist_joints").strings()
    leg_joints = {side: node.strings(min_len=1) for side, node in _sides(root.get("legs"))}
    feet = {side: _foot(node) for side, node in _sides(root.get("feet"))}
    arms = {side: _arm(node) for side, node in _sides(root.get("arms"))}
    unsupported_node = root.opt("unsupported_alternatives")
    unsupported = (
        {alt: node.string() for alt, node in unsupported_node.items()} if unsupported_node is not None else {}
    )
    posture_node = root.opt("safe_posture")
    safe_posture = _safe_posture(posture_node) if posture_node is not None else SafePosture()
    profile = RobotProfile(
        name=name,
        base_body=base_body,
        torso_body=torso_body,
        head_body=head_body,
        keyframe=keyframe,
        arms=arms,
        feet=feet,
        waist_joints=waist_joints,
        leg_joints=leg_joints,
        mjcf=mjcf,
        source=source_path,
        home_joints=home_joints,
        return_along_lane=return_along_lane,
        safe_posture=safe_posture,
        unsupported_alternatives=unsupported,
    )
    _check_unique_joints(root, profile)
    return profile


def _safe_posture(node: Node) -> SafePosture:
    """The ``safe_posture`` mapping: any of SafePosture's fields, the rest its defaults."""
    keys = ("max_pelvis_drop", "max_trunk_tilt_deg", "pelvis_tolerance", "tilt_tolerance_deg")
    node.check_keys(optional=keys)
    values = {}
    for key in keys:
        child = node.opt(key)
        if child is not None:
            values[key] = (
                child.number(ge=0.0, le=90.0)
                if key.endswith("deg")
                else child.number(ge=0.0, le=POSTURE_DROP_MAX)
            )
    return SafePosture(**values)


def _sides(node: Node) -> list[tuple[str, Node]]:
    node.check_keys(SIDES)
    return [(side, node.get(side)) for side in SIDES]


def _foot(node: Node) -> FootProfile:
    node.check_keys(("body",), ("geoms",))
    geoms = node.opt("geoms")
    return FootProfile(body=node.get("body").string(), geoms=geoms.strings() if geoms is not None else ())


def _arm(node: Node) -> ArmProfile:
    node.check_keys(("joints", "hand", "hand_body", "gripper"), ("forearm_body",))
    forearm = node.opt("forearm_body")
    return ArmProfile(
        joints=node.get("joints").strings(min_len=1),
        hand=_hand(node.get("hand")),
        gripper=_gripper(node.get("gripper")),
        hand_body=node.get("hand_body").string(),
        forearm_body=forearm.string() if forearm is not None else None,
    )


def _hand(node: Node) -> HandFrame:
    node.check_keys(optional=("site", "body", "offset", "quat", "closing_yaw"))
    closing_node = node.opt("closing_yaw")
    closing = closing_node.number(ge=-180.0, le=180.0) if closing_node is not None else None
    site, body = node.opt("site"), node.opt("body")
    if (site is None) == (body is None):
        node.fail("expected exactly one of 'site' (an existing site) or 'body' (plus offset and quat)")
    if site is not None or body is None:
        for key in ("offset", "quat"):
            if node.has(key):
                node.child(key, None).fail(f"'{key}' only applies with 'body', not with 'site'")
        return HandFrame(site=site.string() if site is not None else None, closing_yaw_deg=closing)
    offset_node, quat_node = node.opt("offset"), node.opt("quat")
    offset = (
        offset_node.numbers(3, ge=-HAND_OFFSET_MAX, le=HAND_OFFSET_MAX)
        if offset_node is not None
        else (0.0, 0.0, 0.0)
    )
    quat = (1.0, 0.0, 0.0, 0.0)
    if quat_node is not None:
        raw = quat_node.numbers(4, ge=-1e3, le=1e3)
        norm = math.sqrt(sum(q * q for q in raw))
        if norm < 1e-6:
            quat_node.fail("expected a unit quaternion [w, x, y, z], got a zero quaternion")
        quat = (raw[0] / norm, raw[1] / norm, raw[2] / norm, raw[3] / norm)
    return HandFrame(
        body=body.string(),
        offset=(offset[0], offset[1], offset[2]),
        quat=quat,
        closing_yaw_deg=closing,
    )


def _gripper(node: Node) -> GripperProfile:
    node.check_keys(("actuators", "open", "closed"))
    actuators = node.get("actuators").strings(min_len=1)
    n = len(actuators)
    targets = {}
    for key in ("open", "closed"):
        child = node.get(key)
        if not isinstance(child.value, list) or len(child.value) != n:
            child.expected(f"a list of {n} numbers (one per actuator)")
        targets[key] = child.numbers(n, ge=-GRIPPER_TARGET_MAX, le=GRIPPER_TARGET_MAX)
    return GripperProfile(actuators=actuators, open=targets["open"], closed=targets["closed"])


def _check_unique_joints(root: Node, profile: RobotProfile) -> None:
    """A joint may appear in one list only (waist, a leg, an arm)."""
    seen: dict[str, str] = {}
    lists: list[tuple[str, tuple[str, ...]]] = [("waist_joints", profile.waist_joints)]
    lists += [(f"legs.{side}", profile.leg_joints[side]) for side in SIDES]
    lists += [(f"arms.{side}.joints", profile.arms[side].joints) for side in SIDES]
    for path, joints in lists:
        for i, joint in enumerate(joints):
            where = f"{path}[{i}]"
            if joint in seen:
                raise RobotProfileError(
                    root.source, where, f"joint '{joint}' is listed twice (also at {seen[joint]})"
                )
            seen[joint] = where
