"""Load a scenario (YAML) into frozen dataclasses, validating every value.

``load("book_transfer")`` or ``load("path/to/file.yaml")`` returns a
:class:`~executive.schema.types.Scenario`. Every error is a
:class:`~executive.errors.ScenarioError` whose message reads
``<file>: <key.path>: expected X, got Y``; unknown keys are rejected with the
nearest valid name. Angles are degrees in the file and radians in the result.
Relative paths (a robot's MJCF or profile) resolve against the scenario's folder.

Beyond types, every number must lie in its range (:mod:`executive.schema.ranges`), no
setting may switch a safety check off (a negative ``risk.guard.min_com_margin``, a
``risk.threshold`` at or above the largest value its ordering can take:
:func:`max_ordering_value`), ``severity.body_parts`` names a body-part label or a body of the
robot's model, and the scene must be physically possible (:mod:`executive.scenario.checks`,
with the robot's reach measured in its MJCF by :mod:`executive.robot.model`).
The schema by example is the bundled ``scenarios/book_transfer.yaml``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TypeVar

from executive.risk.orderings import ordering as ordering_named
from executive.risk.orderings import ordering_names
from executive.robot.model import BODY_PART_LABELS, RobotFacts, robot_facts
from executive.robot.profile import load_profile
from executive.robot.profile_types import RobotProfile
from executive.scenario.checks import check_scene
from executive.schema import catalog as registry
from executive.schema import ranges as R
from executive.schema.failure_modes import canonical_mode, mode_names
from executive.schema.readers import read_scene
from executive.schema.types import (
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
    TrialsConfig,
    Uncertainty,
    default_weights,
)
from executive.schema.yaml_nodes import (
    Node,
    check_model_file,
    load_yaml_file,
    load_yaml_text,
    read_fields,
    suggest,
    unknown_name,
)
from executive.tasks.base import Task

__all__ = ["APPROVAL_MODES", "from_dict", "load", "loads", "max_ordering_value", "with_threshold"]

#: How an approval request is answered when risk is above the threshold.
APPROVAL_MODES: tuple[str, ...] = ("prompt", "auto", "deny")

T = TypeVar("T")

_TOP_REQUIRED = ("name", "robot", "scene", "mission")
_TOP_OPTIONAL = ("description", "uncertainty", "risk", "approval", "trials")


def load(name_or_path: str | Path, *, allow_modules: Iterable[str] = ()) -> Scenario:
    """Load a bundled scenario by name, or a scenario file by path.

    Args:
        name_or_path: a bundled scenario's name or a YAML file.
        allow_modules: the modules its ``kind: package.module:Class`` tasks may import (besides
            those ``EXECUTIVE_ALLOW_MODULES`` names); any other dotted kind is refused unimported.

    Raises:
        ScenarioError: the file is invalid, at the key path at fault.
    """
    path = registry.scenario_path(name_or_path)
    root = load_yaml_file(path)
    scenario = _scenario(root, path.parent, allow_modules)
    return dataclasses.replace(scenario, source=path)


def loads(
    text: str, source: str = "<string>", base_dir: Path | None = None, *, allow_modules: Iterable[str] = ()
) -> Scenario:
    """Load a scenario from YAML text; relative paths resolve against ``base_dir`` (default: cwd).

    ``allow_modules`` as :func:`load`'s.
    """
    root = load_yaml_text(text, source)
    return _scenario(root, base_dir if base_dir is not None else Path.cwd(), allow_modules)


def from_dict(
    data: object, source: str = "<dict>", base_dir: Path | None = None, *, allow_modules: Iterable[str] = ()
) -> Scenario:
    """Validate an already-parsed document (e.g. built in code) and build the scenario.

    ``allow_modules`` as :func:`load`'s.
    """
    root = Node(data, source)
    if not root.is_mapping():
        root.expected("a mapping at the top level")
    return _scenario(root, base_dir if base_dir is not None else Path.cwd(), allow_modules)


def _scenario(root: Node, base_dir: Path, allow_modules: Iterable[str] = ()) -> Scenario:
    root.check_keys(_TOP_REQUIRED, _TOP_OPTIONAL)
    # Read in schema order, so the first error reported is the first in the document.
    name = root.get("name").string()
    description = root.opt("description")
    robot, profile = _robot(root.get("robot"), base_dir)
    scene = read_scene(root.get("scene"))
    scenario = Scenario(
        name=name,
        description=description.string(allow_empty=True).strip() if description is not None else "",
        robot=robot,
        scene=scene,
        uncertainty=_optional(root, "uncertainty", _uncertainty, Uncertainty),
        risk=_optional(root, "risk", lambda n: _risk(n, scene), RiskConfig),
        approval=_optional(root, "approval", _approval, ApprovalConfig),
        mission=_mission(root.get("mission"), scene, tuple(allow_modules)),
        trials=_optional(root, "trials", _trials, TrialsConfig),
    )
    facts = robot_facts(robot.mjcf, profile)
    _check_body_parts(root, scenario, facts)
    check_scene(root, scenario, facts)
    return scenario


def _optional(root: Node, key: str, reader: Callable[[Node], T], default: Callable[[], T]) -> T:
    """Read ``root[key]`` with ``reader``; an absent or null block gives ``default()``."""
    node = root.opt(key)
    return default() if node is None else reader(node)


# ----------------------------------------------------------------------------- robot


def _bundled_robots() -> str:
    return ", ".join(registry.list_robots()) or "(none)"


def _robot(node: Node, base_dir: Path) -> tuple[RobotSpec, RobotProfile]:
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
        check_model_file(mjcf_node, mjcf)
    elif profile.mjcf is not None:
        mjcf = profile.mjcf
    else:
        node.fail(
            f"the profile of robot '{profile.name}' ships no MJCF model; "
            f"name one: robot: {{mjcf: PATH, profile: {profile.name}}}"
        )
    return RobotSpec(name=profile.name, mjcf=mjcf, profile=profile_path), profile


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
    try:
        candidate = (base_dir / Path(text).expanduser()).resolve()
        exists = candidate.is_file()
    except (OSError, ValueError, RuntimeError) as exc:
        node.fail(f"invalid profile path {text!r}: {exc}")
    if not exists:
        node.fail(
            f"no profile file {text!r} (resolved to {candidate}) and no bundled robot of that name; "
            f"bundled robots: {_bundled_robots()}"
        )
    return candidate


def _is_plain_name(text: str) -> bool:
    return bool(text) and "/" not in text and "\\" not in text and not text.startswith(".")


# ----------------------------------------------------------------------------- mission


def _mission(node: Node, scene: SceneConfig, allow_modules: tuple[str, ...] = ()) -> tuple[Task, ...]:
    """Each task: a mapping with one key, its kind (``transfer``, ...), or ``kind: package.module:Class``.

    A dotted kind's module is imported only if ``allow_modules`` (or the environment) allows it.
    """
    from executive.tasks.registry import TaskKindError, available, get

    tasks = []
    for item in node.items_list(min_len=1):
        if not item.is_mapping():
            item.expected(f"a task mapping such as {{transfer: {{...}}}} (kinds: {', '.join(available())})")
        if isinstance(item.value, dict) and "kind" in item.value:
            # {kind: package.module:Class, <the kind's keys>}: a plug-in named by its dotted path
            kind_node = item.get("kind")
            kind_name = kind_node.string()
            body = Node(
                {k: v for k, v in item.value.items() if k != "kind"}, item.source, item.path, item.error
            )
        else:
            kind_name, body = item.single_key(f"the task kind: {', '.join(available())}")
            kind_node = body
        try:
            kind = get(kind_name, allow_modules)
        except TaskKindError as error:
            kind_node.fail(str(error))
        tasks.append(kind.read(body, scene))
    return tuple(tasks)


# ----------------------------------------------------------------------------- small blocks


def between(low: float, high: float, *, open_low: bool = False) -> Callable[[Node], float]:
    """A reader of a finite number in [low, high] (or (low, high] with ``open_low``)."""
    if open_low:
        return lambda n: n.number(gt=low, le=high)
    return lambda n: n.number(ge=low, le=high)


def whole(low: int, high: int) -> Callable[[Node], int]:
    """A reader of an integer in [low, high]."""
    return lambda n: n.integer(ge=low, le=high)


def _deg_sigma(node: Node) -> float:
    return math.radians(node.number(ge=0.0, le=R.YAW_SIGMA_MAX_DEG))


def _deg_scale(node: Node) -> float:
    return math.radians(node.number(gt=0.0, le=R.GRASP_ANGLE_MAX_DEG))


# 1-sigma spreads of the scene's poses (m, m, deg in YAML -> rad): an estimate's error
# (uncertainty) and the trial-to-trial shift of a campaign's scene (trials.scene_variation).
_POSE_SPREADS: dict[str, tuple[str, Callable[[Node], object]]] = {
    "object_position": ("object_position", between(0.0, R.POSITION_SIGMA_MAX)),
    "object_yaw": ("object_yaw_rad", _deg_sigma),
    "obstacle_position": ("obstacle_position", between(0.0, R.POSITION_SIGMA_MAX)),
}


def _uncertainty(node: Node) -> Uncertainty:
    return read_fields(
        node,
        Uncertainty,
        {
            **_POSE_SPREADS,
            "com": ("com", between(0.0, R.COM_SIGMA_MAX)),
            "object_mass": ("object_mass", between(0.0, R.RELATIVE_SIGMA_MAX)),
            "friction": ("friction", between(0.0, R.RELATIVE_SIGMA_MAX)),
            "base_position": ("base_position", between(0.0, R.POSITION_SIGMA_MAX)),
            "base_yaw": ("base_yaw_rad", _deg_sigma),
        },
    )


def _approval(node: Node) -> ApprovalConfig:
    return read_fields(
        node,
        ApprovalConfig,
        {
            "mode": ("mode", lambda n: n.choice(APPROVAL_MODES)),
            "timeout_s": ("timeout_s", between(0.0, R.TIMEOUT_MAX_S, open_low=True)),
        },
    )


def _trials(node: Node) -> TrialsConfig:
    return read_fields(
        node,
        TrialsConfig,
        {
            "count": ("count", whole(1, R.TRIALS_MAX)),
            "seed": ("seed", whole(0, R.SEED_MAX)),
            "scene_variation": ("scene_variation", _scene_variation),
        },
    )


def _scene_variation(node: Node) -> SceneVariation:
    return read_fields(
        node, SceneVariation, {**_POSE_SPREADS, "perception_scale": ("perception_scale", _scale_range)}
    )


def _scale_range(node: Node) -> tuple[float, float]:
    low, high = node.numbers(2, gt=0.0, le=R.PERCEPTION_SCALE_MAX)
    if low > high:
        node.fail(f"the range [{low:g}, {high:g}] is reversed: give [low, high] with low <= high")
    return low, high


# ----------------------------------------------------------------------------- risk


def _risk(node: Node, scene: SceneConfig | None = None) -> RiskConfig:
    config = read_fields(
        node,
        RiskConfig,
        {
            "d_safety": ("d_safety", between(0.0, R.D_SAFETY_MAX, open_low=True)),
            "collision": ("collision", _collision),
            "fall": ("fall", _fall),
            "grasp": ("grasp", _grasp),
            "weights": ("weights", _weights),
            "severity": ("severity", _severity),
            "ordering": ("ordering", lambda n: n.choice(ordering_names())),
            "threshold": ("threshold", Node.non_negative),  # its maximum: check_threshold
            "loss_per_second": ("loss_per_second", between(0.0, R.SEVERITY_MAX)),
            "guard": ("guard", _guard),
            "rollouts": ("rollouts", _rollouts),
        },
    )
    _check_threshold(node, config, scene)
    return config


def _com_margin(node: Node) -> float:
    """``guard.min_com_margin`` (m): a negative margin would let the CoM leave the feet first."""
    value = node.number()
    if value < 0.0:
        node.fail(
            f"expected a number >= 0 and <= {R.COM_MARGIN_MAX:g} (m), got {value:g}: a negative margin lets "
            "the centre of mass leave the support polygon before the guard trips, which switches the "
            "fall guard off"
        )
    return node.number(ge=0.0, le=R.COM_MARGIN_MAX)


def max_ordering_value(risk: RiskConfig, scene: SceneConfig | None = None) -> tuple[float, str]:
    """The largest value ``risk.ordering`` can take, and how it is made up (for messages).

    Each ordering says it (:attr:`executive.risk.orderings.Ordering.max_value`): a probability is
    at most 1; a weighted sum is at most each mode's weight times its score's largest value; an
    expected loss at most the sum of the modes' severities, a per-body mode's (collision) the
    largest, an obstacle's own included, times the largest body-part factor.
    """
    return ordering_named(risk.ordering).max_value(risk, scene)


def _check_threshold(node: Node, risk: RiskConfig, scene: SceneConfig | None = None) -> None:
    """A threshold at or above the ordering's largest value would never ask for approval."""
    highest, how = max_ordering_value(risk, scene)
    if risk.threshold >= highest:
        where = node.child("threshold", risk.threshold) if node.has("threshold") else node
        where.fail(
            f"threshold {risk.threshold:g} can never be exceeded: the largest {risk.ordering} "
            f"any alternative can have is {highest:g} ({how}), so the approval gate would never ask; "
            f"give a threshold below {highest:g}"
        )


def with_threshold(scenario: Scenario, threshold: float | None, source: str = "--threshold") -> Scenario:
    """``scenario`` with ``risk.threshold`` set to ``threshold`` (None: unchanged), checked as the
    file's own value is: a finite number >= 0 and below the largest value ``risk.ordering`` can
    take (:func:`max_ordering_value`), so an override can lower or raise the gate but never switch
    it off.

    Args:
        scenario: a loaded scenario.
        threshold: the new threshold, in the units of ``risk.ordering``.
        source: what gave the value, for the message (a command-line option).

    Returns:
        A copy of ``scenario`` with the new threshold (``scenario`` itself for None).

    Raises:
        ScenarioError: a threshold out of that range, naming ``source`` and ``risk.threshold``.
    """
    if threshold is None:
        return scenario
    node = Node({"threshold": threshold}, source, "risk")
    risk = dataclasses.replace(scenario.risk, threshold=node.get("threshold").non_negative())
    _check_threshold(node, risk, scenario.scene)
    return dataclasses.replace(scenario, risk=risk)


def _rollouts(node: Node) -> RolloutConfig:
    config = read_fields(
        node,
        RolloutConfig,
        {
            "count": ("count", whole(0, R.ROLLOUTS_MAX)),
            "min_count": ("min_count", whole(1, R.ROLLOUTS_MAX)),
            "batch": ("batch", whole(1, R.ROLLOUTS_MAX)),
            "budget_s": ("budget_s", between(0.0, R.BUDGET_MAX_S, open_low=True)),
            "confidence": ("confidence", between(0.5, 0.999, open_low=True)),
            "indifference": ("indifference", between(0.0, R.INDIFFERENCE_MAX)),
            "prior_weight": ("prior_weight", between(0.0, R.PRIOR_WEIGHT_MAX)),
            "jobs": ("jobs", whole(1, R.JOBS_MAX)),
        },
    )
    if config.count and config.min_count > config.count:
        if not node.has("min_count"):  # the default minimum never exceeds the count given
            return dataclasses.replace(config, min_count=config.count)
        node.get("min_count").fail(f"min_count ({config.min_count}) is more than count ({config.count})")
    return config


def _guard(node: Node) -> GuardConfig:
    return read_fields(
        node,
        GuardConfig,
        {
            "min_distance": ("min_distance", between(0.0, R.GUARD_DISTANCE_MAX)),
            "lookahead_s": ("lookahead_s", between(0.0, R.LOOKAHEAD_MAX_S)),
            "min_com_margin": ("min_com_margin", _com_margin),
        },
    )


def _collision(node: Node) -> CollisionRiskConfig:
    return read_fields(
        node,
        CollisionRiskConfig,
        {
            "exponent": ("exponent", between(0.0, R.EXPONENT_MAX, open_low=True)),
            "peak_weight": ("peak_weight", between(0.0, R.WEIGHT_MAX)),
            "exposure_weight": ("exposure_weight", between(0.0, R.WEIGHT_MAX)),
        },
    )


def _fall(node: Node) -> FallRiskConfig:
    return read_fields(
        node,
        FallRiskConfig,
        {
            "circle_radius": ("circle_radius", between(0.0, R.FALL_RADIUS_MAX, open_low=True)),
            "sigmas": ("sigmas", between(0.0, R.SIGMAS_MAX, open_low=True)),
            "exponent": ("exponent", between(0.0, R.EXPONENT_MAX, open_low=True)),
        },
    )


def _grasp(node: Node) -> GraspRiskConfig:
    config = read_fields(
        node,
        GraspRiskConfig,
        {
            "position_scale": ("position_scale", between(0.0, R.GRASP_POSITION_MAX, open_low=True)),
            "position_max": ("position_max", between(0.0, R.GRASP_POSITION_MAX, open_low=True)),
            "angle_scale": ("angle_scale_rad", _deg_scale),
            "angle_max": ("angle_max_rad", _deg_scale),
            "steepness": ("steepness", between(0.0, R.STEEPNESS_MAX, open_low=True)),
            "position_weight": ("position_weight", between(0.0, R.WEIGHT_MAX)),
            "angle_weight": ("angle_weight", between(0.0, R.WEIGHT_MAX)),
        },
    )
    if not config.position_scale < config.position_max:
        where = node.child("position_scale" if node.has("position_scale") else "position_max", None)
        where.fail(
            "expected position_scale < position_max, "
            f"got {config.position_scale:g} >= {config.position_max:g}"
        )
    if config.position_weight + config.angle_weight <= 0.0:
        node.child("position_weight", None).fail(
            "position_weight and angle_weight are both 0: the grasp score would divide by zero; "
            "give at least one a positive weight"
        )
    if not config.angle_scale_rad < config.angle_max_rad:
        where = node.child("angle_scale" if node.has("angle_scale") else "angle_max", None)
        where.fail(
            f"expected angle_scale < angle_max, got {math.degrees(config.angle_scale_rad):g} >= "
            f"{math.degrees(config.angle_max_rad):g} degrees"
        )
    return config


def _mode_key(child: Node, key: str, extra: tuple[str, ...] = ()) -> str:
    """The failure mode a ``risk.weights`` / ``risk.severity`` key names (an old name warns)."""
    name = canonical_mode(key, f"{child.source}: {child.path}")
    if name is None:
        child.fail(unknown_name("key", key, [*mode_names(), *extra], "valid keys"))
    return name


def _weights(node: Node) -> tuple[tuple[str, float], ...]:
    if not node.is_mapping():
        node.expected("a mapping of failure mode -> weight, e.g. {collision: 1.0, fall: 2.0}")
    weights = dict(default_weights())
    for key, child in node.items():
        weights[_mode_key(child, key)] = child.number(ge=0.0, le=R.WEIGHT_MAX)
    return tuple(weights.items())


def _severity(node: Node) -> Severity:
    if not node.is_mapping():
        node.expected("a mapping of failure mode -> severity, and body_parts")
    modes: dict[str, float] = {}
    body_parts = None
    for key, child in node.items():
        if key == "body_parts":
            body_parts = _body_parts(child)
        else:
            modes[_mode_key(child, key, ("body_parts",))] = between(0.0, R.SEVERITY_MAX, open_low=True)(child)
    return Severity.from_modes(modes, body_parts)


def _body_parts(node: Node) -> tuple[tuple[str, float], ...]:
    if not node.is_mapping():
        node.expected("a mapping of body part -> severity, e.g. {head: 3.0, hand: 1.5}")
    parts = []
    for key, child in node.items():
        if not key.strip():
            child.fail("expected a body part name, got an empty key")
        parts.append((key, child.number(gt=0.0, le=R.SEVERITY_MAX)))
    return tuple(parts)


def _check_body_parts(root: Node, scenario: Scenario, facts: RobotFacts | None) -> None:
    """Each ``severity.body_parts`` name is a body-part label or a body of the robot's model."""
    if facts is None:
        return  # the model did not load: the world builder reports that
    valid = [*BODY_PART_LABELS, *facts.bodies]
    for name, _ in scenario.risk.severity.body_parts:
        if name not in valid:
            Node(None, root.source, f"risk.severity.body_parts.{name}", root.error).fail(
                f"unknown body part '{name}'{suggest(name, valid) or ';'} valid names: the body-part labels "
                f"{', '.join(BODY_PART_LABELS)}, or a body of the robot's model: {', '.join(facts.bodies)}"
            )
