"""Frozen dataclasses a scenario file loads into.

Units: metres, kilograms, seconds; angles are given in degrees in YAML and held
in radians here (field names end in ``_rad``). Positions are in the world
frame: the robot's base stands at the origin facing +x, +y is its left, +z up.
Sizes are full edge lengths (not MuJoCo half-sizes): a box ``[x, y, z]``, a
cylinder ``[radius, length]``, a sphere ``[radius]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

__all__ = [
    "ALTERNATIVES",
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
    "TransferTask",
    "TrialsConfig",
    "Uncertainty",
]

Shape = Literal["box", "cylinder", "sphere"]
SHAPES: tuple[str, ...] = ("box", "cylinder", "sphere")
#: Names of the ways a two-armed robot can do a transfer task.
ALTERNATIVES: tuple[str, ...] = ("left", "right", "left_to_right", "right_to_left")


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

    position: tuple[float, float]  # centre of the top, x y (m)
    size: tuple[float, float, float]  # full extents x y and top thickness (m)
    height: float  # top surface above the floor (m)
    yaw_rad: float = 0.0


@dataclass(frozen=True)
class Body:
    """An object the robot may manipulate, or a static obstacle."""

    name: str
    shape: Shape
    size: tuple[float, ...]  # full extents, see module doc
    position: tuple[float, float, float]  # centre (m); z defaults to resting on the table
    orientation_rad: tuple[float, float, float]  # roll, pitch, yaw (rad), applied z-y-x
    mass: float | None = None  # kg; None for obstacles (static)
    friction: float = 1.0  # sliding friction coefficient
    rgba: tuple[float, float, float, float] | None = None
    # Order of the object's rotational symmetry about its vertical axis: a half turn (2) leaves
    # a plain box where it was; 1 (default) means its yaw matters (a labelled container, a book
    # whose spine must face one way). Yaw errors count modulo 2*pi / yaw_symmetry.
    yaw_symmetry: int = 1

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
    (0.1 = 10 %); friction: relative.
    """

    object_position: float = 0.0
    object_yaw_rad: float = 0.0
    obstacle_position: float = 0.0
    com: float = 0.0
    object_mass: float = 0.0
    friction: float = 0.0


@dataclass(frozen=True)
class CollisionRiskConfig:
    """Seed collision metric: ``r(t) = (1 - d/d_safety)^exponent`` inside ``d_safety``."""

    exponent: float = 2.0
    peak_weight: float = 0.5
    exposure_weight: float = 0.5


@dataclass(frozen=True)
class FallRiskConfig:
    """Seed fall metric: uncertainty circle of ``circle_radius`` (m) around the CoM.

    ``circle_radius`` None means: use the scenario's CoM 1-sigma times ``sigmas``.
    """

    circle_radius: float | None = None
    sigmas: float = 2.0
    exponent: float = 2.0


@dataclass(frozen=True)
class GraspRiskConfig:
    """Seed grasp metric: logistic in the translational and angular pre-grasp error."""

    position_scale: float = 0.02  # m, error at which the positional term is 0.5
    position_max: float = 0.05  # m, error beyond which the grasp surely fails (x_max)
    angle_scale_rad: float = 0.17  # rad
    angle_max_rad: float = 0.52  # rad
    steepness: float = 1.0  # b in the seed's form
    position_weight: float = 0.6
    angle_weight: float = 0.4


@dataclass(frozen=True)
class Severity:
    """Cost of each failure mode (dimensionless, relative) and per body part for collisions."""

    collision: float = 3.0
    fall: float = 10.0
    drop: float = 2.0
    body_parts: tuple[tuple[str, float], ...] = (("head", 3.0), ("hand", 1.5), ("forearm", 1.0))


@dataclass(frozen=True)
class GuardConfig:
    """Live risk guards (behaviours/guard.py): limits re-checked on every tick while a motion runs."""

    min_distance: float = 0.01  # m: least robot-environment distance, now and over the look-ahead
    lookahead_s: float = 0.3  # s: how far along the planned trajectory the distance is predicted
    min_com_margin: float = 0.02  # m: least CoM margin inside the support polygon of the foot contacts


@dataclass(frozen=True)
class RolloutConfig:
    """Monte Carlo risk in physics before ranking (``risk.rollouts``; executive/rollouts.py).

    Each feasible alternative is executed on truths sampled from the uncertainty, in rounds
    of ``batch`` per alternative, until the sequential stopping rule says the choice is clear,
    ``count`` rollouts per alternative are done, or ``budget_s`` of wall time is spent. The
    counts are fused with the analytic prediction (a Beta prior of weight ``prior_weight``).
    The dry run (each alternative once on the estimate) always runs; it is not configured here.
    """

    count: int = 4  # most rollouts per alternative; 0: off (the dry runs still run)
    min_count: int = 4  # rollouts per alternative before the stopping rule may stop
    batch: int = 4  # rollouts per alternative per round
    budget_s: float = 30.0  # s of wall time for all rollouts of one decision
    confidence: float = 0.95  # posterior probability at which the stopping rule calls the choice clear
    indifference: float = 0.05  # in the ordering's units: a choice this close to the best is as good
    prior_weight: float = 10.0  # pseudo-trials the analytic prediction counts for
    jobs: int = 2  # worker processes


@dataclass(frozen=True)
class RiskConfig:
    """Everything the risk models and the selector take from the scenario."""

    d_safety: float = 0.05
    collision: CollisionRiskConfig = field(default_factory=CollisionRiskConfig)
    fall: FallRiskConfig = field(default_factory=FallRiskConfig)
    grasp: GraspRiskConfig = field(default_factory=GraspRiskConfig)
    weights: tuple[tuple[str, float], ...] = (("collision", 1.0), ("fall", 2.0), ("grasp", 1.0))
    severity: Severity = field(default_factory=Severity)
    ordering: Literal["weighted_sum", "probability", "expected_loss"] = "expected_loss"
    threshold: float = 0.3
    guard: GuardConfig = field(default_factory=GuardConfig)
    rollouts: RolloutConfig = field(default_factory=RolloutConfig)


@dataclass(frozen=True)
class ApprovalConfig:
    mode: Literal["prompt", "auto", "deny"] = "deny"
    timeout_s: float = 60.0


@dataclass(frozen=True)
class TransferTask:
    """Move ``object`` to ``to`` (centre x, y[, z]); z None means resting on the table."""

    object: str
    to: tuple[float, float, float | None]
    to_yaw_rad: float | None = None  # None: keep the object's yaw
    alternatives: tuple[str, ...] = ALTERNATIVES[:3]

    @property
    def kind(self) -> str:
        return "transfer"


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

    object_position: float = 0.0
    object_yaw_rad: float = 0.0
    obstacle_position: float = 0.0
    perception_scale: tuple[float, float] = (1.0, 1.0)

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
    count: int = 10
    seed: int = 0
    scene_variation: SceneVariation = field(default_factory=SceneVariation)


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    robot: RobotSpec
    scene: SceneConfig
    uncertainty: Uncertainty
    risk: RiskConfig
    approval: ApprovalConfig
    mission: tuple[TransferTask, ...]
    trials: TrialsConfig
    source: Path | None = None  # the file it was loaded from
