"""Load a scenario (YAML) into frozen dataclasses, validating every value.

``load("book_transfer")`` or ``load("path/to/file.yaml")`` returns a
:class:`~executive.scenario_types.Scenario`. Every error is a
:class:`~executive.errors.ScenarioError` whose message reads
``<file>: <key.path>: expected X, got Y``; unknown keys are rejected with the
nearest valid name. Angles are degrees in the file and radians in the result.
Relative paths (a robot's MJCF or profile) resolve against the scenario's folder.
The schema by example is the bundled ``scenarios/book_transfer.yaml``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from executive import registry
from executive.robots.profile import load_profile
from executive.scenario_scene import read_scene, read_transfer
from executive.scenario_types import (
    ApprovalConfig,
    CollisionRiskConfig,
    FallRiskConfig,
    GraspRiskConfig,
    GuardConfig,
    RiskConfig,
    RobotSpec,
    RolloutConfig,
    Scenario,
    SceneConfig,
    SceneVariation,
    Severity,
    TransferTask,
    TrialsConfig,
    Uncertainty,
)
from executive.validation import Node, load_yaml_file, load_yaml_text, read_fields, unknown_name

__all__ = ["APPROVAL_MODES", "ORDERINGS", "TASK_KINDS", "from_dict", "load", "loads"]

#: Task kinds a mission may hold.
TASK_KINDS: tuple[str, ...] = ("transfer",)
#: How the selector ranks alternatives.
ORDERINGS: tuple[str, ...] = ("weighted_sum", "probability", "expected_loss")
#: How an approval request is answered when risk is above the threshold.
APPROVAL_MODES: tuple[str, ...] = ("prompt", "auto", "deny")
#: Failure modes the risk weights may name.
RISK_TERMS: tuple[str, ...] = ("collision", "fall", "grasp")

T = TypeVar("T")

_TOP_REQUIRED = ("name", "robot", "scene", "mission")
_TOP_OPTIONAL = ("description", "uncertainty", "risk", "approval", "trials")


def load(name_or_path: str | Path) -> Scenario:
    """Load a bundled scenario by name, or a scenario file by path."""
    path = registry.scenario_path(name_or_path)
    root = load_yaml_file(path)
    scenario = _scenario(root, path.parent)
    return dataclasses.replace(scenario, source=path)


def loads(text: str, source: str = "<string>", base_dir: Path | None = None) -> Scenario:
    """Load a scenario from YAML text; relative paths resolve against ``base_dir`` (default: cwd)."""
    root = load_yaml_text(text, source)
    return _scenario(root, base_dir if base_dir is not None else Path.cwd())


def from_dict(data: object, source: str = "<dict>", base_dir: Path | None = None) -> Scenario:
    """Validate an already-parsed document (e.g. built in code) and build the scenario."""
    root = Node(data, source)
    if not root.is_mapping():
        root.expected("a mapping at the top level")
    return _scenario(root, base_dir if base_dir is not None else Path.cwd())


def _scenario(root: Node, base_dir: Path) -> Scenario:
    root.check_keys(_TOP_REQUIRED, _TOP_OPTIONAL)
    # Read in schema order, so the first error reported is the first in the document.
    name = root.get("name").string()
    description = root.opt("description")
    robot = _robot(root.get("robot"), base_dir)
    scene = read_scene(root.get("scene"))
    return Scenario(
        name=name,
        description=description.string(allow_empty=True).strip() if description is not None else "",
        robot=robot,
        scene=scene,
        uncertainty=_optional(root, "uncertainty", _uncertainty, Uncertainty),
        risk=_optional(root, "risk", _risk, RiskConfig),
        approval=_optional(root, "approval", _approval, ApprovalConfig),
        mission=_mission(root.get("mission"), scene),
        trials=_optional(root, "trials", _trials, TrialsConfig),
    )


def _optional(root: Node, key: str, reader: Callable[[Node], T], default: Callable[[], T]) -> T:
    """Read ``root[key]`` with ``reader``; an absent or null block gives ``default()``."""
    node = root.opt(key)
    return default() if node is None else reader(node)


# ----------------------------------------------------------------------------- robot


def _bundled_robots() -> str:
    return ", ".join(registry.list_robots()) or "(none)"


def _robot(node: Node, base_dir: Path) -> RobotSpec:
    """``robot: humanoid`` or ``robot: {mjcf: PATH, profile: NAME-OR-PATH}`` or ``{name: NAME}``."""
    if isinstance(node.value, str):
        profile_path = _bundled_profile_path(node)
        mjcf_node: Node | None = None
    elif node.is_mapping():
        node.check_keys(optional=("name", "profile", "mjcf"))
        name_node, profile_node, mjcf_node = node.opt("name"), node.opt("profile"), node.opt("mjcf")
        if name_node is not None and profile_node is None:
            profile_path = _bundled_profile_path(name_node)
        elif profile_node is not None and name_node is None:
            profile_path = _profile_path(profile_node, base_dir)
        else:
            node.fail("expected exactly one of 'name' (a bundled robot) or 'profile' (a name or a file)")
    else:
        node.expected(
            f"a bundled robot's name ({_bundled_robots()}) or a mapping {{mjcf: ..., profile: ...}}"
        )
    profile = load_profile(profile_path)
    if mjcf_node is not None:
        mjcf = mjcf_node.file_path(base_dir, "MJCF file")
    elif profile.mjcf is not None:
        mjcf = profile.mjcf
    else:
        node.fail(
            f"the profile of robot '{profile.name}' ships no MJCF model; "
            f"name one: robot: {{mjcf: PATH, profile: {profile.name}}}"
        )
    return RobotSpec(name=profile.name, mjcf=mjcf, profile=profile_path)


def _bundled_profile_path(node: Node) -> Path:
    name = node.string()
    path = registry.robot_profile_path(name) if _is_plain_name(name) else None
    if path is None:
        node.fail(unknown_name("robot", name, registry.list_robots(), "bundled robots"))
    return path


def _profile_path(node: Node, base_dir: Path) -> Path:
    text = node.string()
    if _is_plain_name(text):
        bundled = registry.robot_profile_path(text)
        if bundled is not None:
            return bundled
    candidate = (base_dir / Path(text).expanduser()).resolve()
    if not candidate.is_file():
        node.fail(
            f"no profile file {text!r} (resolved to {candidate}) and no bundled robot of that name; "
            f"bundled robots: {_bundled_robots()}"
        )
    return candidate


def _is_plain_name(text: str) -> bool:
    return bool(text) and "/" not in text and "\\" not in text and not text.startswith(".")


# ----------------------------------------------------------------------------- mission


def _mission(node: Node, scene: SceneConfig) -> tuple[TransferTask, ...]:
    tasks = []
    for item in node.items_list(min_len=1):
        if not item.is_mapping():
            item.expected(f"a task mapping such as {{transfer: {{...}}}} (kinds: {', '.join(TASK_KINDS)})")
        kind, body = item.single_key(f"the task kind: {', '.join(TASK_KINDS)}")
        if kind not in TASK_KINDS:
            body.fail(unknown_name("task kind", kind, TASK_KINDS, "valid kinds"))
        tasks.append(read_transfer(body, scene))
    return tuple(tasks)


# ----------------------------------------------------------------------------- small blocks


def _deg(node: Node) -> float:
    return math.radians(node.number())


def _deg_positive(node: Node) -> float:
    return math.radians(node.positive())


def _deg_non_negative(node: Node) -> float:
    return math.radians(node.non_negative())


# 1-sigma spreads of the scene's poses (m, m, deg in YAML -> rad): an estimate's error
# (uncertainty) and the trial-to-trial shift of a campaign's scene (trials.scene_variation).
_POSE_SPREADS: dict[str, tuple[str, Callable[[Node], object]]] = {
    "object_position": ("object_position", Node.non_negative),
    "object_yaw": ("object_yaw_rad", _deg_non_negative),
    "obstacle_position": ("obstacle_position", Node.non_negative),
}


def _uncertainty(node: Node) -> Uncertainty:
    nonneg = Node.non_negative
    return read_fields(
        node,
        Uncertainty,
        {
            **_POSE_SPREADS,
            "com": ("com", nonneg),
            "object_mass": ("object_mass", nonneg),
            "friction": ("friction", nonneg),
        },
    )


def _approval(node: Node) -> ApprovalConfig:
    return read_fields(
        node,
        ApprovalConfig,
        {"mode": ("mode", lambda n: n.choice(APPROVAL_MODES)), "timeout_s": ("timeout_s", Node.positive)},
    )


def _trials(node: Node) -> TrialsConfig:
    return read_fields(
        node,
        TrialsConfig,
        {
            "count": ("count", lambda n: n.integer(ge=1)),
            "seed": ("seed", lambda n: n.integer(ge=0)),
            "scene_variation": ("scene_variation", _scene_variation),
        },
    )


def _scene_variation(node: Node) -> SceneVariation:
    return read_fields(
        node, SceneVariation, {**_POSE_SPREADS, "perception_scale": ("perception_scale", _scale_range)}
    )


def _scale_range(node: Node) -> tuple[float, float]:
    low, high = node.numbers(2, gt=0.0)
    if low > high:
        node.fail(f"the range [{low:g}, {high:g}] is reversed: give [low, high] with low <= high")
    return low, high


# ----------------------------------------------------------------------------- risk


def _risk(node: Node) -> RiskConfig:
    return read_fields(
        node,
        RiskConfig,
        {
            "d_safety": ("d_safety", Node.positive),
            "collision": ("collision", _collision),
            "fall": ("fall", _fall),
            "grasp": ("grasp", _grasp),
            "weights": ("weights", _weights),
            "severity": ("severity", _severity),
            "ordering": ("ordering", lambda n: n.choice(ORDERINGS)),
            "threshold": ("threshold", Node.non_negative),
            "guard": ("guard", _guard),
            "rollouts": ("rollouts", _rollouts),
        },
    )


def _rollouts(node: Node) -> RolloutConfig:
    config = read_fields(
        node,
        RolloutConfig,
        {
            "count": ("count", lambda n: n.integer(ge=0)),
            "min_count": ("min_count", lambda n: n.integer(ge=1)),
            "batch": ("batch", lambda n: n.integer(ge=1)),
            "budget_s": ("budget_s", Node.positive),
            "confidence": ("confidence", lambda n: n.number(gt=0.5, le=0.999)),
            "indifference": ("indifference", Node.non_negative),
            "prior_weight": ("prior_weight", Node.non_negative),
            "jobs": ("jobs", lambda n: n.integer(ge=1)),
        },
    )
    if config.count and config.min_count > config.count:
        node.get("min_count" if node.has("min_count") else "count").fail(
            f"min_count ({config.min_count}) is more than count ({config.count})"
        )
    return config


def _guard(node: Node) -> GuardConfig:
    return read_fields(
        node,
        GuardConfig,
        {
            "min_distance": ("min_distance", Node.non_negative),
            "lookahead_s": ("lookahead_s", Node.non_negative),
            "min_com_margin": ("min_com_margin", Node.number),
        },
    )


def _collision(node: Node) -> CollisionRiskConfig:
    return read_fields(
        node,
        CollisionRiskConfig,
        {
            "exponent": ("exponent", Node.positive),
            "peak_weight": ("peak_weight", Node.non_negative),
            "exposure_weight": ("exposure_weight", Node.non_negative),
        },
    )


def _fall(node: Node) -> FallRiskConfig:
    return read_fields(
        node,
        FallRiskConfig,
        {
            "circle_radius": ("circle_radius", Node.positive),
            "sigmas": ("sigmas", Node.positive),
            "exponent": ("exponent", Node.positive),
        },
    )


def _grasp(node: Node) -> GraspRiskConfig:
    config = read_fields(
        node,
        GraspRiskConfig,
        {
            "position_scale": ("position_scale", Node.positive),
            "position_max": ("position_max", Node.positive),
            "angle_scale": ("angle_scale_rad", _deg_positive),
            "angle_max": ("angle_max_rad", _deg_positive),
            "steepness": ("steepness", Node.positive),
            "position_weight": ("position_weight", Node.non_negative),
            "angle_weight": ("angle_weight", Node.non_negative),
        },
    )
    if not config.position_scale < config.position_max:
        where = node.child("position_scale" if node.has("position_scale") else "position_max", None)
        where.fail(
            "expected position_scale < position_max, "
            f"got {config.position_scale:g} >= {config.position_max:g}"
        )
    if not config.angle_scale_rad < config.angle_max_rad:
        where = node.child("angle_scale" if node.has("angle_scale") else "angle_max", None)
        where.fail(
            f"expected angle_scale < angle_max, got {math.degrees(config.angle_scale_rad):g} >= "
            f"{math.degrees(config.angle_max_rad):g} degrees"
        )
    return config


def _weights(node: Node) -> tuple[tuple[str, float], ...]:
    node.check_keys(optional=RISK_TERMS)
    weights = dict(RiskConfig().weights)
    for key, child in node.items():
        weights[key] = child.non_negative()
    return tuple(weights.items())


def _severity(node: Node) -> Severity:
    return read_fields(
        node,
        Severity,
        {
            "collision": ("collision", Node.positive),
            "fall": ("fall", Node.positive),
            "drop": ("drop", Node.positive),
            "body_parts": ("body_parts", _body_parts),
        },
    )


def _body_parts(node: Node) -> tuple[tuple[str, float], ...]:
    if not node.is_mapping():
        node.expected("a mapping of body part -> severity, e.g. {head: 3.0, hand: 1.5}")
    parts = []
    for key, child in node.items():
        if not key.strip():
            child.fail("expected a body part name, got an empty key")
        parts.append((key, child.positive()))
    return tuple(parts)
