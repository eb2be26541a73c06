"""Regret of the risk ranking: does choosing per trial beat the best fixed alternative?

The choice in a trial is the alternative with the lowest predicted value (a ``--decide``
campaign's recorded choice; none chosen: a failure). Its regret is the failure rate of the
choices minus that of the best *fixed* alternative on the same truths: negative when the
per-trial ranking helps. The best fixed alternative is cross-fitted (Chernozhukov et al. 2018):
picked on the even trials and scored on the odd ones, and the other way round, which removes the
in-sample bias against the choice (reported beside it). Failures are 0/1 per trial and
alternative (``infeasible`` fails); trials with an ``error`` or no feasible alternative are left
out and counted. Significance is the exact sign (McNemar) test; the interval Newcombe's
(docs/risk_in_physics.md, "How to read the regret").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Regret",
    "TrialTable",
    "best_fixed",
    "choices",
    "newcombe_interval",
    "regret",
    "sign_test",
    "trial_table",
    "wilson",
]

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

Z95 = 1.959963984540054  # standard normal quantile at 0.975


@dataclass(frozen=True)
class TrialTable:
    """A campaign's trials as arrays: one row per trial, one column per alternative.

    ``failed``: the outcome was not ``success`` (``infeasible`` included); ``value``: the
    predicted value the selector ranks by, ``inf`` when infeasible; ``trials``: the trials'
    indices; ``dropped``: trials left out, by reason (``incomplete``, ``error``,
    ``all_infeasible``); ``chosen``: the column the executive's recorded decision chose per
    trial (-1: none), None when the records carry no decision (the choice is then the lowest
    value's, :func:`choices`).
    """

    alternatives: tuple[str, ...]
    trials: IntArray
    failed: BoolArray
    value: FloatArray
    dropped: dict[str, int] = field(default_factory=dict)
    chosen: IntArray | None = None


def trial_table(records: Sequence[dict[str, Any]], alternatives: Sequence[str]) -> TrialTable:
    """Arrange a campaign's ``trials.jsonl`` records (see :mod:`executive.validation.campaign`) by trial."""
    by_trial: dict[int, dict[str, dict[str, Any]]] = {}
    for record in records:
        by_trial.setdefault(int(record["trial"]), {})[record["alternative"]] = record
    dropped = {"incomplete": 0, "error": 0, "all_infeasible": 0}
    rows, failed, value, chosen = [], [], [], []
    for t in sorted(by_trial):
        row = by_trial[t]
        if any(a not in row for a in alternatives):
            dropped["incomplete"] += 1
            continue
        mine = [row[a] for a in alternatives]
        if any(r["outcome"] == "error" for r in mine):
            dropped["error"] += 1
            continue
        feasible = [r["outcome"] != "infeasible" and r.get("predicted") is not None for r in mine]
        if not any(feasible):
            dropped["all_infeasible"] += 1
            continue
        rows.append(t)
        failed.append([r["outcome"] != "success" for r in mine])
        value.append([_value(r) if ok else math.inf for r, ok in zip(mine, feasible, strict=True)])
        chosen.append(_decided(mine[0], alternatives))
    n_alt = len(alternatives)
    return TrialTable(
        tuple(alternatives),
        np.asarray(rows, dtype=np.intp),
        np.asarray(failed, dtype=bool).reshape(-1, n_alt),
        np.asarray(value, dtype=float).reshape(-1, n_alt),
        dropped,
        np.asarray(chosen, dtype=np.intp) if rows and None not in chosen else None,
    )


def _decided(record: dict[str, Any], alternatives: Sequence[str]) -> int | None:
    """The column of the alternative the trial's recorded decision chose (-1: none; None: the
    record carries no decision)."""
    decision = record.get("decision")
    if not isinstance(decision, dict):
        return None
    chosen = decision.get("chosen")
    names = list(alternatives)
    return names.index(chosen) if isinstance(chosen, str) and chosen in names else -1


def _value(record: dict[str, Any]) -> float:
    predicted = record["predicted"]
    value = predicted.get("value", predicted.get("expected_loss"))
    return math.inf if value is None else float(value)  # None: never chosen (its dry run failed)


def choices(value: FloatArray) -> IntArray:
    """Per trial, the column of the lowest predicted value (the first on ties)."""
    return np.argmin(value, axis=1).astype(np.intp)


def best_fixed(failed: BoolArray) -> int:
    """The column with the fewest failures (the first on ties)."""
    return int(np.argmin(failed.sum(axis=0)))


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval for k successes in n trials (Wilson 1927); (0, 1) for n = 0."""
    if n <= 0:
        return (0.0, 1.0)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (max(0.0, centre - half), min(1.0, centre + half))


def newcombe_interval(both: int, first_only: int, second_only: int, neither: int) -> tuple[float, float]:
    """95% interval of p1 - p2 for paired 0/1 outcomes (Newcombe 1998, method 10).

    Args:
        both: pairs where both outcomes are 1.
        first_only: pairs where only the first is 1.
        second_only: pairs where only the second is 1.
        neither: pairs where both are 0.

    Returns:
        (lower, upper); (-1, 1) when there are no pairs.
    """
    n = both + first_only + second_only + neither
    if n == 0:
        return (-1.0, 1.0)
    p1, p2 = (both + first_only) / n, (both + second_only) / n
    l1, u1 = wilson(both + first_only, n)
    l2, u2 = wilson(both + second_only, n)
    margins = (both + first_only) * (second_only + neither) * (both + second_only) * (first_only + neither)
    phi = (both * neither - first_only * second_only) / math.sqrt(margins) if margins > 0 else 0.0
    delta = p1 - p2
    lower = delta - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    upper = delta + math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    return (max(-1.0, lower), min(1.0, upper))


def sign_test(positive: int, negative: int) -> float:
    """Two-sided exact sign (McNemar) test: p = min(1, 2 P(X <= min)), X ~ Binomial(n, 1/2)."""
    from scipy.stats import binom

    n = positive + negative
    if n == 0:
        return 1.0
    return float(min(1.0, 2.0 * binom.cdf(min(positive, negative), n, 0.5)))


@dataclass(frozen=True)
class Regret:
    """The regret of the per-trial choice on one campaign (see the module's doc).

    ``regret``, ``naive_regret``: failure rate differences (None without trials in both
    halves); ``ci95``: Newcombe's interval; ``discordant``: trials where only the choice
    failed, and where only the best fixed alternative failed; ``p_value``: exact sign test;
    ``best``: the best fixed alternative picked on the even and on the odd trials (each
    scored on the other half) and on all trials (the naive one).
    """

    trials: int
    choice_failures: int
    best_failures: int
    regret: float | None
    ci95: tuple[float, float]
    discordant: tuple[int, int]
    p_value: float
    naive_regret: float | None
    best: dict[str, str | None]
    chosen: dict[str, int]
    dropped: dict[str, int]

    @property
    def significant_above_zero(self) -> bool:
        """The choice fails significantly more often than the best fixed alternative (5%)."""
        return self.regret is not None and self.regret > 0 and self.p_value < 0.05

    @property
    def significant_below_zero(self) -> bool:
        """The choice fails significantly less often than the best fixed alternative (5%)."""
        return self.regret is not None and self.regret < 0 and self.p_value < 0.05

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["significant_above_zero"] = self.significant_above_zero
        out["significant_below_zero"] = self.significant_below_zero
        return out


def cross_fitted_best(table: TrialTable) -> tuple[IntArray | None, dict[str, str | None]]:
    """Per trial, the best fixed alternative picked on the other half (None: a half is empty)."""
    fold = table.trials % 2
    names: dict[str, str | None] = {"even": None, "odd": None}
    if table.failed.shape[0] == 0 or fold.min() == fold.max():
        return None, names
    best_on = {f: best_fixed(table.failed[fold == f]) for f in (0, 1)}
    names = {"even": table.alternatives[best_on[0]], "odd": table.alternatives[best_on[1]]}
    return np.where(fold == 0, best_on[1], best_on[0]).astype(np.intp), names


def regret(table: TrialTable) -> Regret:
    """The cross-fitted regret of the per-trial choice, its interval and paired test."""
    n = table.failed.shape[0]
    rows = np.arange(n)
    chosen = choices(table.value) if table.chosen is None else table.chosen
    choice_failed = np.where(chosen >= 0, table.failed[rows, np.maximum(chosen, 0)], True)  # none: failed
    counts = {a: int((chosen == i).sum()) for i, a in enumerate(table.alternatives)}
    if (chosen < 0).any():
        counts["(none)"] = int((chosen < 0).sum())
    best, names = cross_fitted_best(table)
    naive = None
    if n:
        names["all"] = table.alternatives[best_fixed(table.failed)]
        naive = float(choice_failed.mean() - table.failed.sum(axis=0).min() / n)
    if best is None:
        return Regret(n, int(choice_failed.sum()), 0, None, (-1.0, 1.0), (0, 0), 1.0, naive, names, counts,
                      dict(table.dropped))  # fmt: skip
    best_failed = table.failed[rows, best]
    plus = int((choice_failed & ~best_failed).sum())
    minus = int((~choice_failed & best_failed).sum())
    both = int((choice_failed & best_failed).sum())
    return Regret(
        trials=n,
        choice_failures=int(choice_failed.sum()),
        best_failures=int(best_failed.sum()),
        regret=(plus - minus) / n,
        ci95=newcombe_interval(both, plus, minus, n - both - plus - minus),
        discordant=(plus, minus),
        p_value=sign_test(plus, minus),
        naive_regret=naive,
        best=names,
        chosen=counts,
        dropped=dict(table.dropped),
    )
