"""Scoring a campaign: its predictions against the outcomes its trials observed.

:func:`summarise` gives, per alternative, the trials, the failures by verdict, the failure
rates with 95% Clopper-Pearson intervals and the mean predicted risk; and overall, per
failure mode (and "any"), the ROC AUC, Brier score and ECE of its predictor
(:func:`forecasts`) and Spearman's rank correlation across the alternatives. The failure
modes and verdicts come from :mod:`executive.schema.failure_modes`.
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
    "executed_trials",
    "finite",
    "forecasts",
    "group_rates",
    "observed_outcomes",
    "reliability_curves",
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


def forecasts(executed: Sequence[dict[str, Any]]) -> Iterator[tuple[str, str, FloatArray, BoolArray]]:
    """Per failure mode (and "any"): the predicting key, its probabilities and the 0/1 outcomes."""
    for mode, key in _forecasts_by_mode().items():
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
    intervals, mean predicted risk; overall: AUC, Brier and ECE per mode and Spearman."""
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
    observed_by, auc, ceiling, brier_by, ece_by = _forecast_scores(executed)
    ran = [a for a in per_alt if a["trials"]]
    rho = {
        q: finite(spearman([a["predicted"][q] for a in ran], [a["failure_rate"]["value"] for a in ran]))
        for q in ("combined", ordering)
    }
    return {
        "scenario": scenario.name,
        "task": None,
        "ordering": ordering,
        "trials_executed": len(executed),
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
