"""Scoring a campaign: its predictions against the outcomes its trials observed.

:func:`summarise` gives, per alternative, the trials, the failures by verdict, the failure
rates with 95% Clopper-Pearson intervals and the mean predicted risk; and overall, per
failure mode (and "any"), the ROC AUC, Brier score and ECE of its predictor
(:func:`forecasts`) and Spearman's rank correlation across the alternatives, and the regret of
the per-trial choice (:mod:`executive.validation.regret`). A campaign that decides per trial
(``--decide``) also gets its fused and its analytic predictions scored on the same trials
(:func:`decision_scores`). The failure modes and verdicts come from
:mod:`executive.schema.failure_modes`.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from executive.schema.failure_modes import failure_mode, mode_names, verdict_names
from executive.schema.types import Scenario

if TYPE_CHECKING:
    from executive.validation.campaign_predictions import Prediction

__all__ = [
    "analytic_view",
    "choice_regrets",
    "decision_scores",
    "executed_trials",
    "finite",
    "forecasts",
    "group_rates",
    "observed_outcomes",
    "pooled_statistics",
    "reliability_curves",
    "scored_trials",
    "summarise",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
_ByMode = dict[str, float | None]  # a score per failure mode (None: not defined)


def observed_outcomes() -> tuple[str, ...]:
    """The verdicts a trial can end in, in the order tables show them: each failure mode's
    verdicts, then the outcomes no mode predicts (the failure-mode table; ``error`` apart)."""
    return tuple(v for v in verdict_names() if v != "error")


def _forecasts_by_mode() -> dict[str, str]:
    """Each failure mode's predicted probability (its own key), and ``any``'s: ``combined``."""
    return {**{m: m for m in mode_names()}, "any": "combined"}


def executed_trials(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The trials that ran in physics (not infeasible, not failed by a defect)."""
    return [r for r in records if r["outcome"] not in ("infeasible", "error")]


def scored_trials(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The trials whose predictions are scored: those executed in physics; of a campaign that
    decides per trial, those whose dry run passed (the executive never runs the others; their
    numbers are analytic, and they are executed and counted all the same)."""
    return [
        r for r in executed_trials(records) if (r.get("physics") or {}).get("dry_run", "success") == "success"
    ]


def analytic_view(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records as the analytic models alone predicted them (before the rollouts were fused),
    without the recorded decision (the choice is then the lowest analytic value's).

    Records without rollouts are their own analytic view.
    """
    out = []
    for r in records:
        predicted = r.get("predicted") or {}
        analytic = predicted.get("analytic")
        view = {k: v for k, v in r.items() if k != "decision"}
        out.append({**view, "predicted": analytic} if analytic is not None else view)
    return out


def pooled_statistics(records: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per failure mode, over the scored trials (:func:`scored_trials`): events, ROC AUC, the
    best AUC of a prediction constant per alternative (and variant), Brier, ECE."""
    from executive.validation.stats import brier, expected_calibration_error, roc_auc

    scored = scored_trials(records)
    groups = [(r.get("variant"), r["alternative"]) for r in scored]
    out = {}
    for mode, key, p, y in forecasts(scored):
        out[mode] = {
            "predicted_by": key,
            "trials": len(y),
            "events": int(y.sum()),
            "auc": finite(roc_auc(p, y)),
            "auc_ceiling": finite(roc_auc(group_rates(groups, y), y)),
            "brier": finite(brier(p, y)),
            "ece": finite(expected_calibration_error(p, y)),
        }
    return out


def choice_regrets(records: Sequence[dict[str, Any]], alternatives: Sequence[str]) -> dict[str, Any]:
    """The cross-fitted regret of the per-trial choice (:mod:`executive.validation.regret`): the
    recorded decision's, else the lowest predicted value's; and, when rollouts were fused,
    ``analytic``: the choice by the analytic value alone on the same truths (else None)."""
    from executive.validation.regret import regret, trial_table

    fused = any(isinstance(r.get("predicted"), dict) and "analytic" in r["predicted"] for r in records)
    analytic = regret(trial_table(analytic_view(records), alternatives)).as_dict() if fused else None
    return {"choice": regret(trial_table(records, alternatives)).as_dict(), "analytic": analytic}


def decision_scores(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """A campaign that decides per trial: the fused and the analytic predictions scored on the
    same trials (:func:`scored_trials`), the trials left out because their dry run failed, and
    how many decisions chose an alternative above the threshold (the executive asks first)."""
    decided = [r for r in records if isinstance(r.get("decision"), dict)]
    above = {r["trial"] for r in decided if r["decision"].get("above_threshold")}
    return {
        "trials": len(scored_trials(records)),
        "dry_run_failed": sum(
            (r.get("physics") or {}).get("dry_run", "success") != "success" for r in executed_trials(records)
        ),
        "decisions": len({r["trial"] for r in decided}),
        "above_threshold": len(above),
        "fused": pooled_statistics(records),
        "analytic": pooled_statistics(analytic_view(records)),
    }


def forecasts(executed: Sequence[dict[str, Any]]) -> Iterator[tuple[str, str, FloatArray, BoolArray]]:
    """Per failure mode (and "any"): the predicting key, its probabilities and the 0/1 outcomes.

    A mode some record does not predict (a campaign recorded before the mode was in the table)
    is left out."""
    for mode, key in _forecasts_by_mode().items():
        if any(key not in r["predicted"] for r in executed):
            continue
        p = np.array([r["predicted"][key] for r in executed], dtype=float)
        verdicts = () if mode == "any" else failure_mode(mode).verdicts
        y = np.array(
            [r["outcome"] != "success" if mode == "any" else r["outcome"] in verdicts for r in executed]
        )
        yield mode, key, p, y.astype(bool)


def _rate(failures: int, trials: int) -> dict[str, Any]:
    from executive.validation.stats import clopper_pearson

    low, high = clopper_pearson(failures, trials)
    return {"value": failures / trials if trials else None, "ci95": [low, high]}


def finite(x: float | None) -> float | None:
    """``x``, or None when it is None, NaN or infinite (a score that is not defined)."""
    return x if x is not None and math.isfinite(x) else None


def group_rates(groups: Sequence[Hashable], y: BoolArray) -> FloatArray:
    """Each trial scored by its group's observed rate of ``y`` (its alternative's, say).

    The best ROC AUC any prediction that is the same for every trial of a group can reach
    is that of these scores (an oracle ranking).
    """
    sums: dict[Hashable, list[float]] = {}
    for g, event in zip(groups, y, strict=True):
        sums.setdefault(g, []).append(float(event))
    rate = {g: float(np.mean(v)) for g, v in sums.items()}
    return np.array([rate[g] for g in groups])


def reliability_curves(executed: Sequence[dict[str, Any]]) -> list[tuple[str, FloatArray, BoolArray]]:
    """The curves of a reliability diagram: per failure mode (and "any"), its label, the
    predicted probabilities and the 0/1 outcomes of the ``executed`` trials."""
    return [(f"{mode} by P({key})", p, y) for mode, key, p, y in forecasts(executed)]


def summarise(
    scenario: Scenario,
    records: Sequence[dict[str, Any]],
    alternatives: Sequence[str],
    predictions: dict[str, Prediction],
) -> dict[str, Any]:
    """Per alternative: trials, failures by mode, failure rates with 95% Clopper-Pearson
    intervals, mean predicted risk; overall: AUC, Brier and ECE per mode over the scored trials
    (:func:`scored_trials`), Spearman, the regret of the per-trial choice (:func:`choice_regrets`)
    and, for a campaign that decides per trial, :func:`decision_scores`."""
    from executive.validation.stats import spearman

    executed = executed_trials(records)
    ordering = scenario.risk.ordering
    per_alt = [
        _alternative_summary(name, executed, records, predictions.get(name), ordering)
        for name in alternatives
    ]
    breach = sorted(o.name for o in scenario.scene.obstacles if o.category == "breach")
    for a in per_alt if breach else ():
        a["breach"] = _breach_touches([r for r in executed if r["alternative"] == a["name"]], set(breach))
    observed_by, auc, ceiling, brier_by, ece_by = _forecast_scores(scored_trials(records))
    ran = [a for a in per_alt if a["trials"]]
    rho = {
        q: finite(spearman([a["predicted"][q] for a in ran], [a["failure_rate"]["value"] for a in ran]))
        for q in ("combined", ordering)
    }
    decided = any(isinstance(r.get("decision"), dict) for r in records)
    return {
        "scenario": scenario.name,
        "task": None,
        "ordering": ordering,
        "trials_executed": len(executed),
        "trials_scored": len(scored_trials(records)),
        "alternatives": per_alt,
        "observed_failures": observed_by,
        "auc": auc,
        "auc_ceiling_per_alternative": ceiling,
        "brier": brier_by,
        "ece": ece_by,
        "spearman": rho[ordering],
        "spearman_by": rho,
        "predictor": _forecasts_by_mode(),
        "breach_obstacles": breach,
        "regret": choice_regrets(records, alternatives),
        "decision": decision_scores(records) if decided else None,
    }


def _breach_touches(mine: Sequence[dict[str, Any]], breach: set[str]) -> dict[str, Any]:
    """An alternative's executed trials whose failure touched a breach obstacle (the failure's
    bodies), with the 95% interval, and the mean predicted P(breach)."""
    touches = sum(bool(breach & set((r.get("failure") or {}).get("bodies") or ())) for r in mine)
    predicted = [float((r.get("predicted") or {}).get("breach", 0.0)) for r in mine]
    return {
        "touches": touches,
        "trials": len(mine),
        "rate": _rate(touches, len(mine)),
        "predicted": float(np.mean(predicted)) if predicted else None,
    }


def _alternative_summary(
    name: str,
    executed: Sequence[dict[str, Any]],
    records: Sequence[dict[str, Any]],
    prediction: Prediction | None,
    ordering: str,
) -> dict[str, Any]:
    """One alternative's row of the summary: its trials, failures by mode and rates, and its
    mean predicted risk over its executed trials."""
    mine = [r for r in executed if r["alternative"] == name]
    infeasible = [r for r in records if r["alternative"] == name and r["outcome"] == "infeasible"]
    n = len(mine)
    failures = {m: sum(r["outcome"] == m for r in mine) for m in observed_outcomes()}
    failures["any"] = sum(r["outcome"] != "success" for r in mine)
    predicted: dict[str, float | None] = {}
    if mine:
        keys = (*mode_names(), "combined", "weighted_sum", "expected_loss")
        keys = tuple(k for k in keys if all(k in r["predicted"] for r in mine))  # older records: fewer modes
        predicted = {k: float(np.mean([r["predicted"][k] for r in mine])) for k in keys}
        # the number the selector ranked by (fused with the rollouts when they ran)
        # (None: the executive would never run it, its dry run failed)
        values = [r["predicted"].get("value", r["predicted"][ordering]) for r in mine]
        predicted["value"] = None if None in values else float(np.mean(values))
    return {
        "name": name,
        "feasible": bool(prediction.feasible) if prediction else None,
        "error": prediction.error
        if prediction and (not prediction.feasible or prediction.value is None)
        else (infeasible[0]["failure"]["detail"] if infeasible else ""),  # planned per trial: the first's why
        "physics": prediction.physics if prediction else None,
        "trials": n,
        "errors": sum(r["outcome"] == "error" for r in records if r["alternative"] == name),
        "infeasible": sum(r["outcome"] == "infeasible" for r in records if r["alternative"] == name),
        "failures": failures,
        "failure_rate": _rate(failures["any"], n),
        "failure_rate_by_mode": {m: _rate(failures[m], n) for m in observed_outcomes()},
        "predicted": predicted,
    }


def _forecast_scores(
    executed: Sequence[dict[str, Any]],
) -> tuple[dict[str, int], _ByMode, _ByMode, _ByMode, _ByMode]:
    """Per failure mode (and "any"): the failures observed, the ROC AUC of its predictor, the
    best AUC of a prediction constant per alternative, the Brier score and the ECE."""
    from executive.validation.stats import brier, expected_calibration_error, roc_auc

    auc: _ByMode = {}
    # The best AUC any prediction that is the same for every trial of an alternative can reach:
    # score each trial by its alternative's observed rate of that mode (an oracle ranking). With
    # one fixed estimate every trial of an alternative has the same prediction, so the AUC of
    # the risk models is bounded by this, however good they are.
    ceiling: _ByMode = {}
    brier_by: _ByMode = {}
    ece_by: _ByMode = {}
    observed_by: dict[str, int] = {}
    for mode, _, p, y in forecasts(executed):
        observed_by[mode] = int(y.sum())
        auc[mode] = finite(roc_auc(p, y))
        ceiling[mode] = finite(roc_auc(group_rates([r["alternative"] for r in executed], y), y))
        brier_by[mode] = finite(brier(p, y))
        ece_by[mode] = finite(expected_calibration_error(p, y))
    return observed_by, auc, ceiling, brier_by, ece_by
