"""The risk model of each failure mode: a registry the assessment of an alternative reads.

Every mode of the failure-mode table (:mod:`executive.schema.failure_modes`) has one model,
a function of the planned alternative (:class:`PlanContext`) that returns the mode's
:class:`executive.risk.report.RiskReport`. The built-in models (collision, fall, drop, tracking) are
registered by :mod:`executive.decision.assessment`; a new mode registers its own::

    register_model("spill", lambda ctx: RiskReport("spill", p, (p, p), ctx.severity("spill"), p))

A model whose prediction a dry run can measure (the plan executed once on the estimate, before
any rollout; :mod:`executive.decision.physics_check`) registers how the run's record refines its
report (:func:`register_dry_run_update`); the refined report is the prior the rollouts update.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from executive.errors import ExecutiveError
from executive.planning.plan import AlternativePlan
from executive.planning.timing import Trajectory
from executive.risk.collision import CollisionModel
from executive.risk.fall import ExternalForce
from executive.risk.report import RiskReport
from executive.risk.tracking import TrackingPrediction, predict_tracking
from executive.schema.failure_modes import failure_mode
from executive.world.model import World

__all__ = [
    "DryRunUpdate",
    "PlanContext",
    "RiskModel",
    "dry_run_update",
    "register_dry_run_update",
    "register_model",
    "risk_model",
    "unregister_model",
]


@dataclass(frozen=True)
class PlanContext:
    """What a risk model reads of one planned alternative.

    world: the estimate it was planned on; plan: the alternative's steps and trajectories;
    collision_model: the scene's collision model (pairs set up once per scene);
    whole: every step's trajectory concatenated; pushes: the push forces the plan exerts
    (None: it pushes nothing); external: the external forces on the robot (a push's or a press's).
    """

    world: World
    plan: AlternativePlan
    collision_model: CollisionModel
    whole: Trajectory
    pushes: ExternalForce | None
    external: ExternalForce | None

    def severity(self, mode: str) -> float:
        """The scenario's severity of ``mode``."""
        return self.world.scenario.risk.severity.of(mode)

    @cached_property
    def tracking(self) -> TrackingPrediction:
        """Where each hand move's hands end (:mod:`executive.risk.tracking`), computed once: the
        tracking model's, and the execution error the grasp and placement models add."""
        return predict_tracking(self.world, self.plan)


RiskModel = Callable[[PlanContext], RiskReport]
#: (the analytic report, the dry run's record) -> the report refined by what the run measured
DryRunUpdate = Callable[[RiskReport, Mapping[str, Any]], RiskReport]
_MODELS: dict[str, RiskModel] = {}
_DRY_RUN: dict[str, DryRunUpdate] = {}


def register_model(mode: str, model: RiskModel) -> None:
    """Make ``model`` the risk model of ``mode`` (a mode of the failure-mode table).

    Raises:
        ExecutiveError: ``mode`` is not in the table, or has a model already.
    """
    failure_mode(mode)
    if mode in _MODELS:
        raise ExecutiveError(f"the failure mode '{mode}' has a risk model already")
    _MODELS[mode] = model


def unregister_model(mode: str) -> None:
    """Remove the model of ``mode`` and its dry-run update (tests, plug-ins unloading)."""
    _MODELS.pop(mode, None)
    _DRY_RUN.pop(mode, None)


def register_dry_run_update(mode: str, update: DryRunUpdate) -> None:
    """Make ``update`` refine ``mode``'s report with a dry run's record (its ``end_errors``, ...).

    Raises:
        ExecutiveError: ``mode`` is not in the table, or has an update already.
    """
    failure_mode(mode)
    if mode in _DRY_RUN:
        raise ExecutiveError(f"the failure mode '{mode}' has a dry-run update already")
    _DRY_RUN[mode] = update


def dry_run_update(mode: str) -> DryRunUpdate | None:
    """How a dry run refines ``mode``'s report (None: it does not; the analytic report stands)."""
    return _DRY_RUN.get(mode)


def risk_model(mode: str) -> RiskModel:
    """The risk model of ``mode``.

    Raises:
        ExecutiveError: the mode has none (the message says how to register one).
    """
    try:
        return _MODELS[mode]
    except KeyError:
        raise ExecutiveError(
            f"the failure mode '{mode}' has no risk model; register one with "
            "executive.decision.risk_models.register_model"
        ) from None
