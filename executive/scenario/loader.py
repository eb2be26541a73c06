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
Every key is declared once (:mod:`executive.scenario.keys`, :mod:`executive.schema.scene_keys`, each
task kind's ``keys``): read with its declaration here and described from it by ``executive schema``
(docs/scenarios.md); the schema by example is the bundled ``scenarios/book_transfer.yaml``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TypeVar

from executive.risk.orderings import ordering as ordering_named
from executive.robot.model import BODY_PART_LABELS, RobotFacts, robot_facts
from executive.robot.profile import load_profile
from executive.robot.profile_types import RobotProfile
from executive.scenario.checks import check_scene
from executive.scenario.keys import APPROVAL, APPROVAL_MODES, RISK, SCENARIO, TRIALS, UNCERTAINTY
from executive.schema import catalog as registry
from executive.schema.readers import read_scene
from executive.schema.types import (
    ApprovalConfig,
    RiskConfig,
    RobotSpec,
    Scenario,
    SceneConfig,
    TrialsConfig,
    Uncertainty,
)
from executive.schema.yaml_nodes import (
    Node,
    check_model_file,
    load_yaml_file,
    load_yaml_text,
    suggest,
    unknown_name,
)
from executive.tasks.base import Task

__all__ = ["APPROVAL_MODES", "from_dict", "load", "loads", "max_ordering_value", "with_threshold"]


T = TypeVar("T")


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
    SCENARIO.check_keys(root)
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
        uncertainty=_optional(root, "uncertainty", UNCERTAINTY.read, Uncertainty),
        risk=_optional(root, "risk", lambda n: _risk(n, scene), RiskConfig),
        approval=_optional(root, "approval", APPROVAL.read, ApprovalConfig),
        mission=_mission(root.get("mission"), scene, tuple(allow_modules)),
        trials=_optional(root, "trials", TRIALS.read, TrialsConfig),
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


# ----------------------------------------------------------------------------- risk


def _risk(node: Node, scene: SceneConfig | None = None) -> RiskConfig:
    """The ``risk`` block (:data:`executive.scenario.keys.RISK`); its threshold below the maximum."""
    config: RiskConfig = RISK.read(node)
    _check_threshold(node, config, scene)
    return config


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
