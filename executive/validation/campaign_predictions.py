"""A campaign's predictions: each alternative planned and assessed on the estimate.

:func:`predict` plans one alternative on the scenario's estimate and assesses its risk
(as ``executive plan`` does); :func:`check_predictions` runs the physics check (dry runs,
rollouts) on those plans and fuses what it measures. A :class:`Prediction` is what a trial
executes and what its record reports as predicted.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from executive.schema.types import Scenario

if TYPE_CHECKING:
    from executive.decision.physics_check import RolloutJob
    from executive.risk.combine import CombinedRisk

__all__ = ["Prediction", "check_predictions", "predict", "prediction_text", "risk_fields"]


@dataclass(frozen=True)
class Prediction:
    """An alternative planned on the estimate: its risk report, or why it does not plan."""

    alternative: str
    feasible: bool
    risk: dict[str, float] | None  # CombinedRisk.as_dict(): each failure mode's, combined, ...
    value: float | None  # the scenario's ordering quantity
    error: str = ""
    plan: Any = field(default=None, repr=False)  # AlternativePlan (None when infeasible)
    assessed: Any = field(default=None, repr=False)  # CombinedRisk (None when infeasible)
    physics: dict[str, Any] | None = None  # the physics check's summary, when it ran
    analytic: dict[str, float] | None = None  # the analytic risk and value, when rollouts fused it


def predict(scenario: Scenario, task_index: int, alternative: str) -> Prediction:
    """Plan ``alternative`` on the estimate and assess its risk (as ``executive plan`` does)."""
    from executive.decision.assessment import assess_plan
    from executive.planning.planner import Planner, PlanningError
    from executive.risk.collision import CollisionModel
    from executive.tasks.steps import plan_alternative
    from executive.world.model import build

    world = build(scenario)
    task = scenario.mission[task_index]
    try:
        plan = plan_alternative(Planner(world), world, task, alternative)
    except PlanningError as exc:
        return Prediction(alternative, False, None, None, str(exc))
    model = CollisionModel(world, scenario.risk, uncertainty=scenario.uncertainty)
    risk = assess_plan(world, plan, model)
    return Prediction(
        alternative, True, risk_fields(risk), risk.value(scenario.risk.ordering), "", plan, risk
    )


def risk_fields(risk: CombinedRisk) -> dict[str, float]:
    """A risk report as a record has it: each failure mode's probability, the combined ones
    (:meth:`~executive.risk.combine.CombinedRisk.as_dict`) and, when the scene has a breach
    obstacle, P(touching one) as ``breach`` (a part of the collision mode)."""
    from executive.risk.collision import breach_summary

    out = risk.as_dict()
    breach = breach_summary(risk.components["collision"]) if "collision" in risk.components else None
    if breach is not None:
        out["breach"] = float(breach["probability"])
    return out


def check_predictions(
    scenario: Scenario,
    predictions: dict[str, Prediction],
    run_map: Callable[[Sequence[RolloutJob]], list[dict[str, Any]]],
    log: Callable[[str], Any] = print,
) -> dict[str, Prediction]:
    """The predictions after the physics check (:mod:`executive.decision.physics_check`) on the estimate.

    A fused alternative carries the fused risk and value. One whose dry run failed keeps its
    analytic risk but has no value (the executive would never run it); its trials still run,
    so the campaign measures it all the same.
    """
    from executive.decision.physics_check import check_alternatives

    feasible = {n: p for n, p in predictions.items() if p.feasible and p.assessed is not None}
    if not feasible:
        return predictions
    cfg = scenario.risk.rollouts
    rolls = f", then up to {cfg.count} rollouts each" if cfg.count else ""
    log(f"checking {', '.join(feasible)} in physics: a dry run on the estimate{rolls}")
    plans = {n: p.plan for n, p in feasible.items()}
    verdict = check_alternatives(plans, {n: p.assessed for n, p in feasible.items()}, scenario, run_map)
    out = dict(predictions)
    for name, result in verdict.alternatives.items():
        physics = result.as_dict(cfg.confidence)
        if not result.dry_run_ok:
            out[name] = dataclasses.replace(
                out[name], value=None, error=result.dry_run_reason(), physics=physics
            )
            continue
        risk, ordering = result.risk, scenario.risk.ordering
        analytic = None
        if result.risk is not result.analytic:  # fused with rollouts, or refined by the dry run
            analytic = {**result.analytic.as_dict(), "value": result.analytic.value(ordering)}
        out[name] = dataclasses.replace(
            out[name], risk=risk.as_dict(), value=risk.value(ordering), physics=physics, analytic=analytic
        )
    if verdict.stopped != "off":
        log(f"  rollouts: {verdict.rollouts} per alternative, stopped by {verdict.stopped}")
    return out


def prediction_text(p: Prediction, ordering: str) -> str:
    """One line of a prediction: its P(any) and ordering value, or why it is never run."""
    if not p.feasible or p.risk is None:
        return f"infeasible: {p.error}"
    if p.value is None:
        return f"never chosen: {p.error}"
    return f"P(any) {p.risk['combined']:.4f}  {ordering} {p.value:.4f}"
