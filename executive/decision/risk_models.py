"""The risk model of each failure mode: a registry the assessment of an alternative reads.

Every mode of the failure-mode table (:mod:`executive.schema.failure_modes`) has one model,
a function of the planned alternative (:class:`PlanContext`) that returns the mode's
:class:`executive.risk.report.RiskReport`. The built-in models (collision, fall, drop) are
registered by :mod:`executive.decision.assessment`; a new mode registers its own::

    register_model("spill", lambda ctx: RiskReport("spill", p, (p, p), ctx.severity("spill"), p))
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from executive.errors import ExecutiveError
from executive.planning.plan import AlternativePlan
from executive.planning.timing import Trajectory
from executive.risk.collision import CollisionModel
from executive.risk.fall import ExternalForce
from executive.risk.report import RiskReport
from executive.schema.failure_modes import failure_mode
from executive.world.model import World

__all__ = ["PlanContext", "RiskModel", "register_model", "risk_model", "unregister_model"]


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


RiskModel = Callable[[PlanContext], RiskReport]
_MODELS: dict[str, RiskModel] = {}


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
    """Remove the model of ``mode`` (tests, plug-ins unloading)."""
    _MODELS.pop(mode, None)


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
