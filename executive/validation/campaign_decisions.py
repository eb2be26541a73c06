"""A campaign trial that decides as the executive does, on the trial's own estimate (``--decide``).

A decision trial is one decision and its alternatives executed: on trial ``i``'s estimate
(:func:`~executive.validation.campaign_trials.trial_scene`) the selector's own planning work
(:class:`executive.decision.planning_job.Planning`) plans and assesses every alternative,
dry-runs them and rolls them out in physics and fuses the rollouts; the physics runs in the
campaign's worker process. Then every alternative that planned (the chosen one and the
others) is executed on the trial's truth, the one the analytic campaign draws from the same
seed. Each alternative's record carries what the executive decided with (``predicted``: fused
with the rollouts; ``predicted.analytic``: the analytic models' numbers), its dry run and
rollouts (``physics``) and the trial's decision (``decision``: the alternative chosen).

Rollout ``j`` of the trial with seed ``s`` draws its truth with
:func:`~executive.decision.physics_check.rollout_seed` ``(s, j)``: a run is reproducible.
How to run it and what it costs: docs/campaigns.md.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from executive.schema.types import Scenario
from executive.validation.campaign_predictions import risk_fields
from executive.validation.campaign_trials import execute_trial, trial_record, trial_scene

if TYPE_CHECKING:
    from executive.decision.assessment import AlternativeRisk
    from executive.decision.physics_check import PhysicsResult, PhysicsVerdict, RolloutJob

__all__ = ["TrialDecision", "decide", "decide_trial", "decision_scenario", "run_here"]


def run_here(jobs: Sequence[RolloutJob]) -> list[dict[str, Any]]:
    """Physics jobs (dry runs, rollouts) run one after the other in this process."""
    from executive.decision.physics_check import run_job

    return [run_job(job) for job in jobs]


def decision_scenario(estimate: Scenario, seed: int) -> Scenario:
    """The trial's estimate as its decision sees it: the rollouts seeded by the trial's ``seed``
    (``trials.seed``) and not bound by the wall-time budget (``risk.rollouts.budget_s``), so
    that the same seed gives the same decision however loaded the machine is."""
    rollouts = dataclasses.replace(estimate.risk.rollouts, budget_s=math.inf)
    risk = dataclasses.replace(estimate.risk, rollouts=rollouts)
    return dataclasses.replace(estimate, risk=risk, trials=dataclasses.replace(estimate.trials, seed=seed))


@dataclass(frozen=True)
class TrialDecision:
    """One trial's decision: every alternative assessed (after the physics check), the check's
    verdict, the alternative chosen (None: none feasible) and why the work failed (None: it did not)."""

    results: dict[str, AlternativeRisk]
    verdict: PhysicsVerdict | None
    chosen: str | None
    failure: str | None
    ordering: str
    threshold: float

    def fields(self) -> dict[str, Any]:
        """The record's ``decision``: the alternative chosen, its value, whether it is above the
        threshold (the executive would ask for approval first), the rollouts and why they stopped."""
        value = None
        if self.chosen is not None:
            risk = self.results[self.chosen].risk
            value = risk.value(self.ordering) if risk is not None else None
        verdict = self.verdict
        return {
            "chosen": self.chosen,
            "value": value,
            "above_threshold": None if value is None else value > self.threshold,
            "rollouts": verdict.rollouts if verdict is not None else 0,
            "stopped": verdict.stopped if verdict is not None else None,
            "choice_confidence": verdict.confidence if verdict is not None else None,
        }


def decide(estimate: Scenario, task_index: int, names: Sequence[str], seed: int) -> TrialDecision:
    """The executive's decision among ``names`` on ``estimate`` (see the module docstring).

    Args:
        estimate: the trial's estimate (the scene the robot perceives, its uncertainty).
        task_index: the task of its mission.
        names: the alternatives to decide among (the task restricted to them).
        seed: the trial's seed (it seeds the rollouts).

    Returns:
        The decision; planning work that raised gives ``failure`` and no results.
    """
    from executive.decision.physics_check import PhysicsCheck
    from executive.decision.planning_job import EstimateState, Planning, PlanningJob, ranked
    from executive.world.model import build

    scenario = decision_scenario(estimate, seed)
    world = build(scenario)
    task = scenario.mission[task_index].restricted(tuple(names))
    job = PlanningJob("campaign", task, world.home_qpos(), EstimateState.of(world), physics=True, guard=False)
    result = Planning(world, PhysicsCheck(1, run_map=run_here)).run(job)
    risk = scenario.risk
    if result.failure is not None:
        return TrialDecision({}, None, None, result.failure.detail(), risk.ordering, risk.threshold)
    feasible = ranked(result.results, risk.ordering)
    chosen = feasible[0].name if feasible else None
    results = {a.name: a for a in result.results}
    return TrialDecision(results, result.verdict, chosen, None, risk.ordering, risk.threshold)


def decide_trial(
    scenario: Scenario,
    task_index: int,
    names: Sequence[str],
    index: int,
    seed: int,
    run: Sequence[str] | None = None,
) -> list[dict[str, Any]]:
    """Decide trial ``index`` on its estimate and execute the alternatives on its truth.

    Args:
        scenario: the campaign's scenario.
        task_index: the task of its mission.
        names: the alternatives the campaign runs (the decision is among them).
        index, seed: the trial and its seed (:func:`~executive.validation.campaign_trials.trial_seed`).
        run: the alternatives to execute and record (default ``names``; a resumed campaign
            runs the ones missing, after the same decision).

    Returns:
        One record per alternative of ``run``, in that order (JSON-safe, no timings).
    """
    estimate, perturbation, shifts = trial_scene(scenario, seed)
    decision = decide(estimate, task_index, names, seed)
    records = []
    for name in names if run is None else run:
        predicted, physics, plan, error = _alternative(decision, name)
        record = trial_record(index, name, seed, predicted, shifts, perturbation)
        record.update(physics=physics, decision=decision.fields())
        if decision.failure is not None:
            record.update(outcome="error", failure={"mode": "error", "detail": decision.failure})
        elif plan is None:
            record["failure"] = {"mode": "infeasible", "detail": error}
        else:
            execute_trial(record, plan, estimate, perturbation, task_index, (predicted or {}).get("value"))
        records.append(record)
    return records


def _alternative(
    decision: TrialDecision, name: str
) -> tuple[dict[str, Any] | None, dict[str, Any] | None, Any, str]:
    """One alternative of a decision: its predicted risk for the record, its physics check's
    outcomes, its plan (None: it did not plan) and why it did not."""
    alt = decision.results.get(name)
    if alt is None or alt.plan is None:
        return None, None, None, alt.error if alt is not None else (decision.failure or "not decided")
    checked = decision.verdict.alternatives.get(name) if decision.verdict is not None else None
    if checked is None:  # no physics check ran: the analytic numbers are the decision's
        risk = alt.risk
        assert risk is not None
        return {**risk_fields(risk), "value": risk.value(decision.ordering)}, None, alt.plan, ""
    analytic = {**risk_fields(checked.analytic), "value": checked.analytic.value(decision.ordering)}
    physics = _physics_fields(checked)
    if not checked.dry_run_ok:  # never chosen; executed all the same, scored by its analytic risk
        return {**analytic, "value": None, "analytic": analytic}, physics, alt.plan, ""
    if checked.fused is None:  # rollouts off: the decision ranks by the analytic risk
        return analytic, physics, alt.plan, ""
    fused = {**risk_fields(checked.fused), "value": checked.fused.value(decision.ordering)}
    return {**fused, "analytic": analytic}, physics, alt.plan, ""


def _physics_fields(checked: PhysicsResult) -> dict[str, Any]:
    """An alternative's physics check for its record: the dry run's outcome (and failure), the
    rollouts and their outcomes (no timings)."""
    out: dict[str, Any] = {
        "dry_run": checked.dry_run.get("outcome"),
        "rollouts": checked.rollouts,
        "outcomes": dict(sorted(checked.counts.items())),
    }
    if not checked.dry_run_ok:
        out["dry_run_failure"] = checked.dry_run.get("failure")
    return out
