"""The keys of a scenario's top level and of its uncertainty, risk, approval and trials blocks.

Declared once (:mod:`executive.schema.declarations`): the loader (:mod:`executive.scenario.loader`)
reads with them, and ``executive schema`` (:mod:`executive.scenario.json_schema`) describes them,
so a range cannot differ between the two. The scene's keys are in
:mod:`executive.schema.scene_keys`, a task's in its kind (``TaskKind.keys``). The limits are the
constants of :mod:`executive.schema.ranges`; the defaults are the dataclasses' of
:mod:`executive.schema.types`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from executive.risk.orderings import ordering_names
from executive.robot.profile import load_profile
from executive.schema import catalog
from executive.schema import ranges as R
from executive.schema.declarations import Block, Choice, Integer, Key, Number, Text, Vector, nullable
from executive.schema.failure_modes import canonical_mode, failure_modes, mode_names
from executive.schema.scene_keys import SCENE
from executive.schema.types import (
    ApprovalConfig,
    CollisionRiskConfig,
    FallRiskConfig,
    GraspRiskConfig,
    GuardConfig,
    RiskConfig,
    RolloutConfig,
    SceneVariation,
    Severity,
    TrialsConfig,
    Uncertainty,
    default_weights,
)
from executive.schema.yaml_nodes import Node, unknown_name

__all__ = [
    "APPROVAL",
    "APPROVAL_MODES",
    "RISK",
    "ROBOT",
    "SCENARIO",
    "TRIALS",
    "UNCERTAINTY",
    "Described",
]

#: How an approval request is answered when risk is above the threshold.
APPROVAL_MODES: tuple[str, ...] = ("prompt", "auto", "deny")


@dataclasses.dataclass(frozen=True)
class Described(Key):
    """A key the loader reads itself (it needs the file's folder or the scene), declared here for
    its words and its JSON Schema (``schema``, a function: asked when the schema is made)."""

    description: str
    schema: Any
    unit: str = ""

    def read(self, node: Node) -> Any:
        raise TypeError(f"{node.path}: read by the loader itself (executive.scenario.loader)")

    def value_schema(self) -> dict[str, Any]:
        return dict(self.schema())


def _robot_schema() -> dict[str, Any]:
    """A bundled robot's name (one that ships its model), or ``{name | profile, mjcf}``."""
    robots = catalog.list_robots()
    modelled = [n for n in robots if load_profile(catalog.robot_profile_path(n)).mjcf is not None]  # type: ignore[arg-type]
    unmodelled = [n for n in robots if n not in modelled]
    keys = {
        "name": Choice("a bundled robot, its profile and model", robots),
        "profile": Text("a bundled robot's name or a profile file (relative to the scenario's folder)"),
        "mjcf": Text(
            "the robot's MJCF model file (relative to the scenario's folder); needed with a profile that "
            "ships no model"
        ),
    }
    properties = {key: nullable(spec.json_schema()) for key, spec in keys.items()}
    mapping: dict[str, Any] = {
        "title": "a robot's profile (a bundled robot's, or a file) and optionally its MJCF model",
        "type": "object",
        "properties": properties,
        "additionalProperties": False,
        "oneOf": [
            {"required": ["name"], "properties": {"name": {"type": "string"}}},
            {"required": ["profile"], "properties": {"profile": {"type": "string"}}},
        ],
    }
    if unmodelled:
        bundled_without_model = {"properties": {"name": {"enum": unmodelled}}, "required": ["name"]}
        mapping["allOf"] = [{"if": bundled_without_model, "then": {"required": ["mjcf"]}}]
    return {"oneOf": [{"type": "string", "enum": modelled}, mapping]}


ROBOT = Described(
    "which robot: a bundled robot's name (`executive list`), or {mjcf: PATH, profile: NAME-OR-PATH} "
    "for any MJCF model and a profile (a bundled robot's name or a file); paths are relative to the "
    "scenario's folder",
    _robot_schema,
)


def _deg_sigma(description: str) -> Number:
    return Number(description, "deg", 0.0, R.YAW_SIGMA_MAX_DEG, to_radians=True)


# 1-sigma spreads of the scene's poses: an estimate's error (uncertainty) and the trial-to-trial
# shift of a campaign's scene (trials.scene_variation).
_POSE_SPREADS: dict[str, Key] = {
    "object_position": Number("objects' horizontal position, per axis", "m", 0.0, R.POSITION_SIGMA_MAX),
    "object_yaw": _deg_sigma("objects' yaw"),
    "obstacle_position": Number("obstacles' horizontal position, per axis", "m", 0.0, R.POSITION_SIGMA_MAX),
}
_POSE_FIELDS = {"object_yaw": "object_yaw_rad"}

UNCERTAINTY = Block(
    "1-sigma errors of the robot's estimate of the world: the truth a run or a trial meets is drawn "
    "from them",
    {
        **_POSE_SPREADS,
        "com": Number(
            "the robot's own centre-of-mass estimate, per horizontal axis", "m", 0.0, R.COM_SIGMA_MAX
        ),
        "object_mass": Number("objects' mass, relative (0.1: 10 %)", "", 0.0, R.RELATIVE_SIGMA_MAX),
        "friction": Number("friction coefficients, relative", "", 0.0, R.RELATIVE_SIGMA_MAX),
        "base_position": Number(
            "the robot's own measure of where its base stands after a walk (odometry), per horizontal axis",
            "m",
            0.0,
            R.POSITION_SIGMA_MAX,
        ),
        "base_yaw": _deg_sigma("the robot's own measure of its heading after a walk (odometry)"),
    },
    factory=Uncertainty,
    fields={**_POSE_FIELDS, "base_yaw": "base_yaw_rad"},
)

APPROVAL = Block(
    "How a request for approval is answered when the chosen alternative's risk is above the threshold",
    {
        "mode": Choice(
            "prompt asks on the terminal (only there; elsewhere deny), auto approves, deny refuses",
            APPROVAL_MODES,
        ),
        "timeout_s": Number(
            "how long a prompt waits for an answer before it aborts", "s", 0.0, R.TIMEOUT_MAX_S, open_low=True
        ),
    },
    factory=ApprovalConfig,
)


def _check_perception(node: Node, variation: SceneVariation) -> SceneVariation:
    low, high = variation.perception_scale
    if low > high:
        node.get("perception_scale").fail(
            f"the range [{low:g}, {high:g}] is reversed: give [low, high] with low <= high"
        )
    return variation


_SCENE_VARIATION = Block(
    "How a campaign's scene differs from trial to trial (1-sigma shifts of the scene the robot "
    "perceives and plans on; the uncertainty is then the error of that perception); zero: every "
    "trial has the same estimate",
    {
        **_POSE_SPREADS,
        "perception_scale": Vector(
            "[low, high]: each trial's object and obstacle pose sigmas are the uncertainty's times a "
            "factor drawn log-uniformly in [low, high] (how well the scene is seen differs too); "
            "low <= high",
            (Number("factor", "", 0.0, R.PERCEPTION_SCALE_MAX, open_low=True),),
            (2,),
            ("low", "high"),
        ),
    },
    factory=SceneVariation,
    fields=_POSE_FIELDS,
    check=_check_perception,
)

TRIALS = Block(
    "A campaign's trials (`executive campaign`)",
    {
        "count": Integer("trials per alternative", 1, R.TRIALS_MAX),
        "seed": Integer("seed of trial 0 (trial i uses seed + i for every alternative)", 0, R.SEED_MAX),
        "scene_variation": _SCENE_VARIATION,
    },
    factory=TrialsConfig,
)


# ----------------------------------------------------------------------------- risk


@dataclasses.dataclass(frozen=True)
class _ComMargin(Number):
    """``guard.min_com_margin``: a negative margin is refused with why (it switches the fall guard off)."""

    def read(self, node: Node) -> float:
        value = node.number()
        if value < 0.0:
            node.fail(
                f"expected a number >= 0 and <= {R.COM_MARGIN_MAX:g} (m), got {value:g}: a negative margin "
                "lets the centre of mass leave the support polygon before the guard trips, which switches "
                "the fall guard off"
            )
        return super().read(node)


def _mode_key(child: Node, key: str, extra: tuple[str, ...] = ()) -> str:
    """The failure mode a ``risk.weights`` / ``risk.severity`` key names (an old name warns)."""
    name = canonical_mode(key, f"{child.source}: {child.path}")
    if name is None:
        child.fail(unknown_name("key", key, [*mode_names(), *extra], "valid keys"))
    return name


def _mode_properties(value: Number, defaults: dict[str, float]) -> dict[str, Any]:
    """A property per failure mode (its default from the table), and the old names, deprecated."""
    properties: dict[str, Any] = {}
    for mode in failure_modes():
        words = dataclasses.replace(value, description=f"{mode.name}: {mode.description}")
        properties[mode.name] = words.json_schema(defaults[mode.name])
        for alias in mode.aliases:
            old = dataclasses.replace(value, description=f"the old name of {mode.name}; write {mode.name}")
            properties[alias] = {**old.json_schema(), "deprecated": True}
    return properties


@dataclasses.dataclass(frozen=True)
class ModeWeights(Key):
    """``risk.weights``: failure mode -> its seed weight (a mode not given keeps the table's)."""

    description: str
    value: Number
    unit: str = ""

    def read(self, node: Node) -> tuple[tuple[str, float], ...]:
        if not node.is_mapping():
            node.expected("a mapping of failure mode -> weight, e.g. {collision: 1.0, fall: 2.0}")
        weights = dict(default_weights())
        for key, child in node.items():
            weights[_mode_key(child, key)] = self.value.read(child)
        return tuple(weights.items())

    def value_schema(self) -> dict[str, Any]:
        properties = _mode_properties(self.value, dict(default_weights()))
        return {"type": "object", "properties": properties, "additionalProperties": False}

    def range_text(self) -> str:
        return f"each {self.value.range_text()}"

    def to_yaml(self, value: Any) -> Any:
        return dict(value)


@dataclasses.dataclass(frozen=True)
class ModeSeverities(Key):
    """``risk.severity``: failure mode -> its loss, and ``body_parts``: body part -> factor."""

    description: str
    value: Number
    part: Number
    unit: str = ""

    def read(self, node: Node) -> Severity:
        if not node.is_mapping():
            node.expected("a mapping of failure mode -> severity, and body_parts")
        modes: dict[str, float] = {}
        body_parts = None
        for key, child in node.items():
            if key == "body_parts":
                body_parts = self._body_parts(child)
            else:
                modes[_mode_key(child, key, ("body_parts",))] = self.value.read(child)
        return Severity.from_modes(modes, body_parts)

    def _body_parts(self, node: Node) -> tuple[tuple[str, float], ...]:
        if not node.is_mapping():
            node.expected("a mapping of body part -> severity, e.g. {head: 3.0, hand: 1.5}")
        parts = []
        for key, child in node.items():
            if not key.strip():
                child.fail("expected a body part name, got an empty key")
            parts.append((key, self.part.read(child)))
        return tuple(parts)

    def value_schema(self) -> dict[str, Any]:
        default = Severity()
        properties = _mode_properties(self.value, {m.name: default.of(m.name) for m in failure_modes()})
        parts = _BodyParts(self.part.description, self.part).json_schema(dict(default.body_parts))
        properties["body_parts"] = parts
        return {"type": "object", "properties": properties, "additionalProperties": False}

    def range_text(self) -> str:
        return f"each {self.value.range_text()}"

    def to_yaml(self, value: Any) -> Any:
        return {**dict(value.modes), "body_parts": dict(value.body_parts)}


@dataclasses.dataclass(frozen=True)
class _BodyParts(Key):
    """``risk.severity.body_parts``: body part -> factor (read by :class:`ModeSeverities`)."""

    description: str
    value: Number
    unit: str = ""

    def read(self, node: Node) -> Any:
        raise TypeError(f"{node.path}: read by ModeSeverities")

    def value_schema(self) -> dict[str, Any]:
        return {
            "type": "object",
            "propertyNames": {"pattern": "\\S"},
            "additionalProperties": self.value.value_schema(),
        }

    def range_text(self) -> str:
        return f"each {self.value.range_text()}"


def _check_grasp(node: Node, config: GraspRiskConfig) -> GraspRiskConfig:
    """position_scale < position_max, angle_scale < angle_max, and not both weights 0."""
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


def _check_rollouts(node: Node, config: RolloutConfig) -> RolloutConfig:
    """min_count <= count (a default minimum above a count given follows it down)."""
    if config.count and config.min_count > config.count:
        if not node.has("min_count"):  # the default minimum never exceeds the count given
            return dataclasses.replace(config, min_count=config.count)
        node.get("min_count").fail(f"min_count ({config.min_count}) is more than count ({config.count})")
    return config


def _open(description: str, high: float, unit: str = "") -> Number:
    return Number(description, unit, 0.0, high, open_low=True)


_WEIGHT = Number("weight", "", 0.0, R.WEIGHT_MAX)

_COLLISION = Block(
    "The seed collision metric: r(t) = (1 - d / d_safety)^exponent inside d_safety",
    {
        "exponent": _open("exponent of the metric", R.EXPONENT_MAX),
        "peak_weight": dataclasses.replace(_WEIGHT, description="weight of the metric's peak"),
        "exposure_weight": dataclasses.replace(_WEIGHT, description="weight of the metric's time integral"),
    },
    factory=CollisionRiskConfig,
)
_FALL = Block(
    "The seed fall metric: an uncertainty circle around the centre of mass",
    {
        "circle_radius": _open(
            "radius of the circle; absent: uncertainty.com times sigmas", R.FALL_RADIUS_MAX, "m"
        ),
        "sigmas": _open("the circle's radius in CoM 1-sigmas", R.SIGMAS_MAX),
        "exponent": _open("exponent of the metric", R.EXPONENT_MAX),
    },
    factory=FallRiskConfig,
)
_ANGLE_SCALE = Number("", "deg", 0.0, R.GRASP_ANGLE_MAX_DEG, open_low=True, to_radians=True)
_GRASP = Block(
    "The seed grasp metric: logistic in the translational and angular pre-grasp error",
    {
        "position_scale": _open(
            "position error at which the positional term is 0.5; < position_max", R.GRASP_POSITION_MAX, "m"
        ),
        "position_max": _open(
            "position error beyond which the grasp surely fails", R.GRASP_POSITION_MAX, "m"
        ),
        "angle_scale": dataclasses.replace(
            _ANGLE_SCALE, description="angle error at which the angular term is 0.5; < angle_max"
        ),
        "angle_max": dataclasses.replace(
            _ANGLE_SCALE, description="angle error beyond which the grasp surely fails"
        ),
        "steepness": _open("b, the logistic's steepness", R.STEEPNESS_MAX),
        "position_weight": dataclasses.replace(
            _WEIGHT, description="weight of the positional term; position_weight + angle_weight > 0"
        ),
        "angle_weight": dataclasses.replace(_WEIGHT, description="weight of the angular term"),
    },
    factory=GraspRiskConfig,
    fields={"angle_scale": "angle_scale_rad", "angle_max": "angle_max_rad"},
    check=_check_grasp,
)
_GUARD = Block(
    "Live guards, re-checked every tick while a motion runs",
    {
        "min_distance": Number(
            "least robot-environment distance, now and over the look-ahead", "m", 0.0, R.GUARD_DISTANCE_MAX
        ),
        "lookahead_s": Number(
            "how far along the planned trajectory the distance is predicted", "s", 0.0, R.LOOKAHEAD_MAX_S
        ),
        "min_com_margin": _ComMargin(
            "least margin of the centre of mass inside the support polygon of the foot contacts; a "
            "negative margin would switch the fall guard off and is refused",
            "m",
            0.0,
            R.COM_MARGIN_MAX,
        ),
    },
    factory=GuardConfig,
)
_ROLLOUTS = Block(
    "Monte Carlo risk in physics before ranking: each feasible alternative is executed on truths "
    "sampled from the uncertainty, in rounds of batch: every one up to min_count, then only those "
    "the stopping rule still finds in contention, each up to count (the cap), or until budget_s is "
    "spent; fused with the analytic prediction",
    {
        "count": Integer(
            "most rollouts per alternative (the cap); 0: off (the dry runs still run)", 0, R.ROLLOUTS_MAX
        ),
        "min_count": Integer(
            "rollouts every alternative gets before the stopping rule may stop it; <= count",
            1,
            R.ROLLOUTS_MAX,
        ),
        "batch": Integer("rollouts per alternative per round", 1, R.ROLLOUTS_MAX),
        "budget_s": _open("wall time for all rollouts of one decision", R.BUDGET_MAX_S, "s"),
        "confidence": Number(
            "posterior probability at which the stopping rule calls the choice clear",
            "",
            0.5,
            0.999,
            open_low=True,
        ),
        "indifference": Number(
            "a choice this close to the best (in the ordering's units) is as good",
            "",
            0.0,
            R.INDIFFERENCE_MAX,
        ),
        "prior_weight": Number(
            "pseudo-trials the analytic prediction counts for", "", 0.0, R.PRIOR_WEIGHT_MAX
        ),
        "jobs": Integer("worker processes", 1, R.JOBS_MAX),
    },
    factory=RolloutConfig,
    check=_check_rollouts,
)

RISK = Block(
    "Everything the risk models and the selector take from the scenario",
    {
        "d_safety": _open("distance inside which the collision metric counts", R.D_SAFETY_MAX, "m"),
        "collision": _COLLISION,
        "fall": _FALL,
        "grasp": _GRASP,
        "weights": ModeWeights("each failure mode's weight in the weighted sum", _WEIGHT),
        "severity": ModeSeverities(
            "each failure mode's loss (dimensionless, relative), and body_parts",
            _open("severity", R.SEVERITY_MAX),
            _open(
                "factor on the collision severity per body part: a label (head, hand, forearm) or a "
                "body of the robot's MJCF",
                R.SEVERITY_MAX,
            ),
        ),
        "ordering": Choice("what the selector ranks the alternatives by (lower is better)", ordering_names),
        "threshold": Number(
            "above it the chosen alternative needs approval; below the largest value the ordering "
            "can take (else the gate would never ask), which depends on the severities and weights",
            "",
            0.0,
        ),
        "loss_per_second": Number(
            "loss_and_time adds this times the planned duration (s) to the expected loss",
            "",
            0.0,
            R.SEVERITY_MAX,
        ),
        "guard": _GUARD,
        "rollouts": _ROLLOUTS,
    },
    factory=RiskConfig,
)


# ----------------------------------------------------------------------------- the document


def _mission_schema() -> dict[str, Any]:
    """Any list of task mappings (:func:`executive.scenario.json_schema.scenario_schema` adds the kinds)."""
    return {"type": "array", "minItems": 1, "items": {"type": "object"}}


SCENARIO = Block(
    "A scenario: a robot, a scene, and a mission of tasks the executive plans, gates on risk and runs",
    {
        "name": Text("the scenario's name (in logs and reports)"),
        "description": Text("what the scenario is, in words", allow_empty=True),
        "robot": ROBOT,
        "scene": SCENE,
        "uncertainty": UNCERTAINTY,
        "risk": RISK,
        "approval": APPROVAL,
        "mission": Described(
            "the tasks, in order: each a mapping with one key, its kind ({transfer: {...}}), or "
            "{kind: NAME-OR-package.module:Class, ...its keys}",
            _mission_schema,
        ),
        "trials": TRIALS,
    },
    required=("name", "robot", "scene", "mission"),
)
