"""One trial of a campaign: an alternative's plan executed in physics on a sampled truth.

Trial ``i`` of every alternative uses the seed :func:`trial_seed` and so the same truth
(common random numbers). :func:`trial_scene` draws the trial's estimate and truth from that
seed; :func:`run_trial` executes the plan on it and returns the record written to
``trials.jsonl``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import asdict
from typing import Any

import numpy as np

from executive.planning.restance import LocalReplanner
from executive.schema.types import Scenario, SceneVariation
from executive.validation.campaign_predictions import Prediction, predict
from executive.world.model import Perturbation

__all__ = ["execute_trial", "run_trial", "trial_record", "trial_scene", "trial_seed", "vary_scene"]


def trial_seed(base_seed: int, index: int) -> int:
    """The seed of trial ``index``: ``trials.seed + index`` (the same for every alternative)."""
    return base_seed + index


def vary_scene(
    scenario: Scenario, variation: SceneVariation, rng: np.random.Generator
) -> tuple[Scenario, dict[str, Any]]:
    """A trial's scene: every object and obstacle of ``scenario`` shifted by a draw of ``variation``.

    Draws in a fixed order (objects: dx, dy, dyaw; then obstacles: dx, dy; then, when
    ``variation.perception_scale`` is a range, the trial's perception factor, log-uniform).
    Returns the shifted scenario (the trial's estimate, its pose sigmas scaled by that
    factor) and the shifts, for the record.
    """
    objects, obstacles = [], []
    shifts: dict[str, Any] = {"object_offsets": {}, "obstacle_offsets": {}}
    for body in scenario.scene.objects:
        dx, dy = rng.normal(0.0, variation.object_position, 2) if variation.object_position else (0.0, 0.0)
        dyaw = float(rng.normal(0.0, variation.object_yaw_rad)) if variation.object_yaw_rad else 0.0
        x, y, z = body.position
        roll, pitch, yaw = body.orientation_rad
        objects.append(
            dataclasses.replace(body, position=(x + dx, y + dy, z), orientation_rad=(roll, pitch, yaw + dyaw))
        )
        shifts["object_offsets"][body.name] = [float(dx), float(dy), dyaw]
    for body in scenario.scene.obstacles:
        dx, dy = (
            rng.normal(0.0, variation.obstacle_position, 2) if variation.obstacle_position else (0.0, 0.0)
        )
        x, y, z = body.position
        obstacles.append(dataclasses.replace(body, position=(x + dx, y + dy, z)))
        shifts["obstacle_offsets"][body.name] = [float(dx), float(dy)]
    scene = dataclasses.replace(scenario.scene, objects=tuple(objects), obstacles=tuple(obstacles))
    uncertainty = scenario.uncertainty
    if variation.varies_perception:
        low, high = variation.perception_scale
        factor = float(np.exp(rng.uniform(np.log(low), np.log(high))))
        uncertainty = dataclasses.replace(
            uncertainty,
            object_position=uncertainty.object_position * factor,
            object_yaw_rad=uncertainty.object_yaw_rad * factor,
            obstacle_position=uncertainty.obstacle_position * factor,
        )
        shifts["perception_scale"] = factor
    return dataclasses.replace(scenario, scene=scene, uncertainty=uncertainty), _perturbation_json(shifts)


def trial_scene(scenario: Scenario, seed: int) -> tuple[Scenario, Perturbation, dict[str, Any] | None]:
    """Trial ``seed``'s estimate (the scenario, or a varied scene), its truth, and the variation.

    One generator per trial: first the scene variation (when the scenario has one), then the
    truth's perturbation from the estimate's uncertainty (:func:`executive.world.model.sample_perturbation`).
    """
    from executive.world.model import sample_perturbation

    rng = np.random.default_rng(seed)
    variation = scenario.trials.scene_variation
    if variation.is_zero():
        return scenario, sample_perturbation(scenario, rng), None
    estimate, shifts = vary_scene(scenario, variation, rng)
    return estimate, sample_perturbation(estimate, rng), shifts


def run_trial(
    scenario: Scenario,
    task_index: int,
    alternative: str,
    index: int,
    seed: int,
    prediction: Prediction | None = None,
) -> dict[str, Any]:
    """Execute one trial; the record written to ``trials.jsonl`` (JSON-safe, no timings).

    The trial takes the alternative's plan and predicted risk on the *estimate*, builds the
    truth world of its perturbation (object and obstacle poses, object mass, friction, the
    robot's CoM offset) and executes the plan in physics with the alternative forced (no
    selection, no approval, no live guards: the question is what the plan does, not whether a
    guard would stop it). Outcome: ``success``, or a failure's verdict (``collision``, ``fall``,
    ``unstable``, ``slip``, ``drop``, ``tracking``), or a verdict no mode predicts (``guard``,
    ``task``, ``timeout``: not finished in the time limit; :mod:`executive.schema.failure_modes`);
    ``infeasible`` when the alternative does not plan (nothing is executed) and ``error`` when
    the trial's code raised (a defect; counted, never hidden). What follows a walk inside the
    plan is re-planned from the stance the robot measures (its odometry seeded by the trial),
    its risk checked as a mission would (:func:`_replanner`); the record's ``restance`` says how.

    ``prediction``: the alternative planned on the scenario's fixed estimate, once per
    alternative (planning is deterministic: planning again per trial gives the same plan);
    None: plan it here, on the trial's own scene, as a scenario with a scene variation needs.
    """
    estimate, perturbation, shifts = trial_scene(scenario, seed)
    if prediction is None or shifts is not None:
        prediction = predict(estimate, task_index, alternative)
    record = trial_record(index, alternative, seed, _predicted(prediction), shifts, perturbation)
    if not prediction.feasible:
        record["failure"] = {"mode": "infeasible", "detail": prediction.error}
        return record
    return execute_trial(record, prediction.plan, estimate, perturbation, task_index, prediction.value)


def trial_record(
    index: int,
    alternative: str,
    seed: int,
    predicted: dict[str, Any] | None,
    shifts: dict[str, Any] | None,
    perturbation: Perturbation,
) -> dict[str, Any]:
    """A trial's record before it runs: outcome ``infeasible`` until :func:`execute_trial` runs it.

    Args:
        index, alternative, seed: which trial.
        predicted: its predicted risk (per-mode probabilities, ``value``; None: it did not plan).
        shifts: the trial's scene variation (None: the scenario's scene).
        perturbation: the truth's perturbation.
    """
    return {
        "trial": index,
        "alternative": alternative,
        "seed": seed,
        "outcome": "infeasible",
        "failure": None,
        "placement_error_m": None,
        "sim_time_s": 0.0,
        "predicted": predicted,
        "scene": shifts,
        "truth": _perturbation_json(asdict(perturbation)),
    }


def execute_trial(
    record: dict[str, Any],
    plan: Any,
    estimate: Scenario,
    perturbation: Perturbation,
    task_index: int,
    value: float | None = None,
) -> dict[str, Any]:
    """``record`` with the outcome of ``plan`` executed in physics on the truth of ``perturbation``.

    The alternative is forced: no selection, no approval, no live guards. A trial whose code
    raises records outcome ``error`` (a defect; counted, never hidden).

    Args:
        record: the trial's record (:func:`trial_record`), updated and returned.
        plan: the alternative's plan (an :class:`~executive.planning.plan.AlternativePlan`).
        estimate: the trial's estimate (the truth is built from it and ``perturbation``).
        perturbation: the truth's perturbation.
        task_index: the task of ``estimate``'s mission the plan does.
        value: the alternative's predicted value, the bound a re-plan after a walk is checked
            against (:func:`_replanner`); None: not checked.
    """
    from executive.execution.runner import error_fields, execute_plan, outcome_fields
    from executive.world.model import build

    try:
        truth = build(estimate, perturbation, kind="truth")
        replanner = _replanner(estimate, value)
        result = execute_plan(
            plan, truth, estimate.mission[task_index], replanner=replanner, seed=record["seed"]
        )
    except Exception as exc:  # a defect in a trial must not end the campaign; it is counted
        record.update(error_fields(exc))
        return record
    record.update(outcome_fields(result))
    return record


def _replanner(estimate: Scenario, value: float | None) -> LocalReplanner:
    """What follows a walk inside the plan is re-planned from the measured stance on the trial's
    estimate, its risk checked as a mission checks it: against the prediction's value, approved
    (forced) at that value or the threshold if higher."""
    from executive.decision.restance import Approval, RiskRecheck

    risk = estimate.risk
    if value is None:
        return LocalReplanner(estimate)
    approval = Approval.of(value, risk.threshold, risk.ordering)
    return LocalReplanner(estimate, check=RiskRecheck(approval))


def _predicted(prediction: Prediction) -> dict[str, Any] | None:
    """A record's prediction: per-mode probabilities and the value ranked by; with rollouts,
    the analytic prediction they were fused with under ``analytic``."""
    if prediction.risk is None:
        return None
    out: dict[str, Any] = {**prediction.risk, "value": prediction.value}
    if prediction.analytic is not None:
        out["analytic"] = prediction.analytic
    return out


def _perturbation_json(p: dict[str, Any]) -> dict[str, Any]:
    def r(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: r(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [r(x) for x in v]
        if isinstance(v, float):
            return round(v, 9)
        return v

    return r(p)
