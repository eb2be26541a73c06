"""Frozen dataclasses a scenario file loads into.

Units: metres, kilograms, seconds; angles are given in degrees in YAML and held
in radians here (field names end in ``_rad``). Positions are in the world
frame: the robot's base stands at the origin facing +x, +y is its left, +z up.
Sizes are full edge lengths (not MuJoCo half-sizes): a box ``[x, y, z]``, a
cylinder ``[radius, length]``, a sphere ``[radius]``.

Every number has a physically meaningful range, written in brackets beside its field
(``[a, b]`` inclusive, ``(a, b]`` excluding a) and enforced by the readers with a message
naming the key path, the value and the range; the limits are the constants of
:mod:`executive.schema.ranges`. Beyond the ranges, a loaded scene is physically possible
(:mod:`executive.scenario.checks`): no object overlaps an obstacle or another object, every
object and target rests on the table (or on something on it) within the robot's reach.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, Literal

from executive.schema.failure_modes import failure_mode, failure_modes, mode_names

__all__ = [
    "OBSTACLE_CATEGORIES",
    "SHAPES",
    "ApprovalConfig",
    "Body",
    "CollisionRiskConfig",
    "FallRiskConfig",
    "GraspRiskConfig",
    "RiskConfig",
    "RobotSpec",
    "Scenario",
    "SceneConfig",
    "SceneVariation",
    "Severity",
    "Table",
    "Task",
    "TrialsConfig",
    "Uncertainty",
    "default_weights",
]

Shape = Literal["box", "cylinder", "sphere"]
SHAPES: tuple[str, ...] = ("box", "cylinder", "sphere")
#: An obstacle's ``category``: touching a "breach" obstacle breaches containment.
OBSTACLE_CATEGORIES: tuple[str, ...] = ("obstacle", "breach")
#: Names of the ways a two-armed robot can do a transfer task.


@dataclass(frozen=True)
class RobotSpec:
    """Which robot: a bundled one by name, or any MJCF file plus a profile.

    ``mjcf`` and ``profile`` are resolved absolute paths (a bundled profile's
    path is inside the installed package).
    """

    name: str
    mjcf: Path
    profile: Path


@dataclass(frozen=True)
class Table:
    """A rectangular table; ``height`` is the height of its top surface."""

    position: tuple[float, float]  # centre of the top, x y (m), each in [-10, 10]; within the robot's reach
    size: tuple[float, float, float]  # full extents x y (m) in (0, 10] and top thickness (m) in (0, 0.5]
    height: float  # top surface above the floor (m), (0, 3]
    yaw_rad: float = 0.0  # [-360, 360] deg in YAML


@dataclass(frozen=True)
class Body:
    """An object the robot may manipulate, or a static obstacle."""

    name: str
    shape: Shape
    # full extents (m), see module doc; each in [0.001, 2] (objects), [0.001, 5] (obstacles)
    size: tuple[float, ...]
    # centre (m); x, y in [-10, 10], z in [0, 5]; z defaults to resting on the table
    position: tuple[float, float, float]
    # roll, pitch, yaw (rad), applied z-y-x; each [-360, 360] deg in YAML
    orientation_rad: tuple[float, float, float]
    mass: float | None = None  # kg, [0.001, 50]; None for obstacles (static)
    friction: float = 1.0  # sliding friction coefficient, [0.01, 5]
    rgba: tuple[float, float, float, float] | None = None  # each [0, 1]
    # Order of the object's rotational symmetry about its vertical axis: a half turn (2) leaves
    # a plain box where it was; 1 (default) means its yaw matters (a labelled container, a book
    # whose spine must face one way). Yaw errors count modulo 2*pi / yaw_symmetry.
    yaw_symmetry: int = 1
    # Obstacles only. The loss of touching this obstacle, (0, 1000]; None: ``risk.severity.collision``.
    severity: float | None = None
    # m, (0, 1]: the planner's clearance to this obstacle and the collision risk's ``d_safety``
    # for it; None: the planner's ``min_distance`` and ``risk.d_safety``.
    clearance: float | None = None
    # "obstacle" (default) or "breach": touching a breach obstacle (a glovebox window, a port rim)
    # breaches containment; the risk report gives its probability and expected loss separately.
    category: str = "obstacle"

    def half_height(self) -> float:
        """Half the body's vertical extent when upright (roll = pitch = 0)."""
        if self.shape == "box":
            return self.size[2] / 2.0
        if self.shape == "cylinder":
            return self.size[1] / 2.0
        return self.size[0]


@dataclass(frozen=True)
class SceneConfig:
    table: Table
    objects: tuple[Body, ...]
    obstacles: tuple[Body, ...] = ()


@dataclass(frozen=True)
class Uncertainty:
    """1-sigma errors of the robot's estimate of the world (all default 0).

    object_position: m, per horizontal axis; object_yaw_rad: rad;
    obstacle_position: m, per horizontal axis; com: m, per horizontal axis,
    error of the robot's own centre-of-mass estimate; object_mass: relative
    (0.1 = 10 %); friction: relative; base_position (m, per horizontal axis) and base_yaw_rad:
    the error of the robot's own measure of where its base stands after it walked (odometry).
    """

    object_position: float = 0.0  # m, [0, 0.2]
    object_yaw_rad: float = 0.0  # [0, 180] deg in YAML
    obstacle_position: float = 0.0  # m, [0, 0.2]
    com: float = 0.0  # m, [0, 0.1]
    object_mass: float = 0.0  # relative, [0, 1]
    friction: float = 0.0  # relative, [0, 1]
    base_position: float = 0.0  # m, [0, 0.2]
    base_yaw_rad: float = 0.0  # [0, 180] deg in YAML


@dataclass(frozen=True)
class CollisionRiskConfig:
    """Seed collision metric: ``r(t) = (1 - d/d_safety)^exponent`` inside ``d_safety``."""

    exponent: float = 2.0  # (0, 10]
    peak_weight: float = 0.5  # [0, 100]
    exposure_weight: float = 0.5  # [0, 100]


@dataclass(frozen=True)
class FallRiskConfig:
    """Seed fall metric: uncertainty circle of ``circle_radius`` (m) around the CoM.

    ``circle_radius`` None means: use the scenario's CoM 1-sigma times ``sigmas``.
    """

    circle_radius: float | None = None  # m, (0, 1]
    sigmas: float = 2.0  # (0, 10]
    exponent: float = 2.0  # (0, 10]


@dataclass(frozen=True)
class GraspRiskConfig:
    """Seed grasp metric: logistic in the translational and angular pre-grasp error."""

    position_scale: float = 0.02  # m, (0, 0.5], error at which the positional term is 0.5
    position_max: float = 0.05  # m, (0, 0.5], error beyond which the grasp surely fails (x_max); > scale
    angle_scale_rad: float = 0.17  # rad; (0, 180] deg in YAML
    angle_max_rad: float = 0.52  # rad; (0, 180] deg in YAML; > angle_scale
    steepness: float = 1.0  # b in the seed's form, (0, 100]
    position_weight: float = 0.6  # [0, 100]; position_weight + angle_weight > 0
    angle_weight: float = 0.4  # [0, 100]


@dataclass(frozen=True, init=False)
class Severity:
    """Cost of each failure mode (dimensionless, relative) and per body part for collisions.

    One value per mode of :mod:`executive.schema.failure_modes` (``Severity(fall=20.0)``; a
    mode not given keeps the table's default), read as an attribute (``severity.fall``) or
    with :meth:`of`. ``body_parts``: the factor on the collision severity per body part,
    each (0, 1000]; a name is a label (head, hand, forearm) or a body of the robot's MJCF
    (executive.robot.model); any other name is rejected.
    """

    modes: tuple[tuple[str, float], ...]  # (mode, severity), each (0, 1000]
    body_parts: tuple[tuple[str, float], ...]

    def __init__(
        self,
        *,
        body_parts: tuple[tuple[str, float], ...] = (("head", 3.0), ("hand", 1.5), ("forearm", 1.0)),
        **modes: float,
    ) -> None:
        object.__setattr__(self, "modes", _every_mode(modes))
        object.__setattr__(self, "body_parts", tuple(body_parts))

    @classmethod
    def from_modes(
        cls, modes: dict[str, float], body_parts: tuple[tuple[str, float], ...] | None = None
    ) -> Severity:
        """A severity of ``modes`` (mode -> value) and ``body_parts`` (None: the default factors)."""
        out = cls() if body_parts is None else cls(body_parts=body_parts)
        object.__setattr__(out, "modes", _every_mode(modes))
        return out

    def of(self, mode: str) -> float:
        """The severity of ``mode``: the scenario's, else the failure-mode table's default."""
        return dict(self.modes).get(mode, failure_mode(mode).severity)

    def __getattr__(self, name: str) -> float:
        if name.startswith("_") or name not in mode_names():
            raise AttributeError(name)
        return self.of(name)

    def __reduce__(self) -> tuple[object, ...]:
        return (_severity, (self.body_parts, self.modes))


def _every_mode(given: dict[str, float]) -> tuple[tuple[str, float], ...]:
    """(mode, severity) for every mode of the table: ``given``'s, else the table's default."""
    for name in given:
        failure_mode(name)  # raises, listing the valid names
    return tuple((m.name, float(given.get(m.name, m.severity))) for m in failure_modes())


def _severity(body_parts: tuple[tuple[str, float], ...], modes: tuple[tuple[str, float], ...]) -> Severity:
    """Unpickle a :class:`Severity` (its constructor takes the modes as keywords)."""
    return Severity.from_modes(dict(modes), body_parts)


def default_weights() -> tuple[tuple[str, float], ...]:
    """``risk.weights``' default: every failure mode's seed weight from the table."""
    return tuple((m.name, m.weight) for m in failure_modes())


@dataclass(frozen=True)
class GuardConfig:
    """Live risk guards (behaviours/guard.py): limits re-checked on every tick while a motion runs."""

    min_distance: float = 0.01  # m, [0, 0.5]: least robot-environment distance, now and over the look-ahead
    lookahead_s: float = 0.3  # s, [0, 5]: how far along the planned trajectory the distance is predicted
    # m, [0, 0.3]: least CoM margin inside the support polygon of the foot contacts; a negative margin
    # would let the CoM leave the feet before the guard trips (the fall guard off) and is rejected
    min_com_margin: float = 0.02


@dataclass(frozen=True)
class RolloutConfig:
    """Monte Carlo risk in physics before ranking (``risk.rollouts``; executive/rollouts.py).

    Each feasible alternative is executed on truths sampled from the uncertainty, in rounds
    of ``batch``; after ``min_count`` each, a round is only for the alternatives whose
    posterior still leaves the choice (or the best's approval) unsure
    (:mod:`executive.decision.rollout_allocation`), until none is, ``count`` rollouts of an
    alternative are done (the cap), or ``budget_s`` of wall time is spent. The counts are
    fused with the analytic prediction (a Beta prior of weight ``prior_weight``). The dry run
    (each alternative once on the estimate) always runs; it is not configured here.
    """

    count: int = 4  # [0, 1000] most rollouts per alternative (the cap); 0: off (the dry runs still run)
    min_count: int = (
        2  # [1, 1000] rollouts every alternative gets before the allocation may stop it; <= count
    )
    batch: int = 2  # [1, 1000] rollouts per alternative per round
    budget_s: float = 30.0  # (0, 3600] s of wall time for all rollouts of one decision
    confidence: float = (
        0.95  # (0.5, 0.999] posterior probability at which the stopping rule calls the choice clear
    )
    indifference: float = (
        0.05  # [0, 1000] in the ordering's units: a choice this close to the best is as good
    )
    prior_weight: float = 10.0  # [0, 10000] pseudo-trials the analytic prediction counts for
    jobs: int = 2  # [1, 256] worker processes


@dataclass(frozen=True)
class RiskConfig:
    """Everything the risk models and the selector take from the scenario."""

    d_safety: float = 0.05  # m, (0, 1]
    collision: CollisionRiskConfig = field(default_factory=CollisionRiskConfig)
    fall: FallRiskConfig = field(default_factory=FallRiskConfig)
    grasp: GraspRiskConfig = field(default_factory=GraspRiskConfig)
    # (mode, seed weight), each [0, 100]; a mode not given keeps the table's default
    weights: tuple[tuple[str, float], ...] = field(default_factory=default_weights)
    severity: Severity = field(default_factory=Severity)
    ordering: str = "expected_loss"  # a name of executive.risk.orderings' registry
    # >= 0 and below the largest value the ordering can take (Ordering.max_value in
    # executive.risk.orderings): a threshold no alternative can exceed would never ask for
    # approval, and is rejected.
    threshold: float = 0.3
    # [0, 1000] loss per second of planned motion: the ordering loss_and_time ranks by the expected
    # loss plus this times the alternative's planned duration (a slower way costs its time); 0: none
    loss_per_second: float = 0.0
    guard: GuardConfig = field(default_factory=GuardConfig)
    rollouts: RolloutConfig = field(default_factory=RolloutConfig)


@dataclass(frozen=True)
class ApprovalConfig:
    mode: Literal["prompt", "auto", "deny"] = "deny"
    timeout_s: float = 60.0  # s, (0, 86400]


@dataclass(frozen=True)
class SceneVariation:
    """How a campaign's scenes differ from trial to trial (1-sigma, all default 0).

    Unlike :class:`Uncertainty` (the error of the robot's estimate of one scene), this
    moves the estimate itself: trial i's scene is the scenario's with each object and
    obstacle shifted by a draw of these, and its truth is that scene plus a draw of the
    uncertainty. Zero (the default) keeps one fixed estimate for every trial.
    object_position, obstacle_position: m, per horizontal axis; object_yaw_rad: rad.
    perception_scale: (low, high): trial i's perception is this much better or worse than
    the scenario's: its object and obstacle pose sigmas (``Uncertainty`` object_position,
    object_yaw_rad, obstacle_position) are multiplied by a factor drawn log-uniformly in
    [low, high]; the truth is drawn with those sigmas and the risk is predicted with them,
    as a pose estimator reports its covariance with each estimate. (1, 1), the default:
    every trial has the scenario's sigmas.
    """

    object_position: float = 0.0  # m, [0, 0.2]
    object_yaw_rad: float = 0.0  # [0, 180] deg in YAML
    obstacle_position: float = 0.0  # m, [0, 0.2]
    perception_scale: tuple[float, float] = (1.0, 1.0)  # each (0, 10], low <= high

    def is_zero(self) -> bool:
        return (
            self.object_position == 0.0
            and self.object_yaw_rad == 0.0
            and self.obstacle_position == 0.0
            and not self.varies_perception
        )

    @property
    def varies_perception(self) -> bool:
        """Whether trials draw their own perception factor (``perception_scale`` is not (1, 1))."""
        return self.perception_scale != (1.0, 1.0)


@dataclass(frozen=True)
class TrialsConfig:
    count: int = 10  # [1, 100000]
    seed: int = 0  # [0, 2**32 - 1]
    scene_variation: SceneVariation = field(default_factory=SceneVariation)


@dataclass(frozen=True, kw_only=True)
class Task:
    """One task of a mission. Subclasses are frozen dataclasses with their kind's fields.

    ``object``: the scene object the task acts on ("" for none, e.g. a press);
    ``alternatives``: the names the scenario allows (empty: every alternative the kind offers).
    """

    kind: ClassVar[str] = ""
    object: str
    alternatives: tuple[str, ...] = ()

    def label(self) -> str:
        """One line for logs and tables, e.g. ``transfer book to (0.52, -0.26)``."""
        return f"{self.kind} {self.object}".strip()

    def restricted(self, names: tuple[str, ...]) -> Task:
        """The same task allowing only ``names`` (a re-plan without the alternatives tried)."""
        return dataclasses.replace(self, alternatives=names)


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    robot: RobotSpec
    scene: SceneConfig
    uncertainty: Uncertainty
    risk: RiskConfig
    approval: ApprovalConfig
    mission: tuple[Task, ...]
    trials: TrialsConfig
    source: Path | None = None  # the file it was loaded from
