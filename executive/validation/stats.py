"""Statistics of a validation campaign: does the predicted risk predict the observed failures?

Pure functions of arrays, each with the reference it follows:

* :func:`clopper_pearson`: exact binomial confidence interval (Clopper & Pearson 1934),
  from the beta distribution's quantiles;
* :func:`spearman`: rank correlation with average ranks for ties (Spearman 1904);
* :func:`roc_auc`: area under the ROC curve as the Mann-Whitney statistic, ties counted
  one half (Hanley & McNeil 1982);
* :func:`brier`: mean squared error of a probability forecast (Brier 1950);
* :func:`calibration_bins` and :func:`expected_calibration_error`: equal-width bins of the
  predicted probability, ECE = sum_b n_b / N |mean p_b - mean y_b| (Naeini et al. 2015);
* :func:`reliability_diagram`: observed rate against predicted probability, with the diagonal
  (DeGroot & Fienberg 1983).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CalibrationBin",
    "brier",
    "calibration_bins",
    "clopper_pearson",
    "expected_calibration_error",
    "quantile_groups",
    "rank",
    "reliability_diagram",
    "roc_auc",
    "spearman",
]

FloatArray = NDArray[np.float64]


def clopper_pearson(failures: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact (conservative) interval for a binomial proportion: ``failures`` out of ``trials``.

    Clopper & Pearson (1934): lower = Beta(a/2; k, n-k+1), upper = Beta(1-a/2; k+1, n-k).
    """
    from scipy.stats import beta

    if trials <= 0:
        return (0.0, 1.0)
    if not 0 <= failures <= trials:
        raise ValueError(f"failures must be in [0, trials]; got {failures} of {trials}")
    alpha = 1.0 - confidence
    lower = 0.0 if failures == 0 else float(beta.ppf(alpha / 2, failures, trials - failures + 1))
    upper = 1.0 if failures == trials else float(beta.ppf(1 - alpha / 2, failures + 1, trials - failures))
    return lower, upper


def rank(values: ArrayLike) -> FloatArray:
    """Ranks 1..n of ``values``, ties given the mean of the ranks they span."""
    x = np.asarray(values, dtype=float)
    order = np.argsort(x, kind="mergesort")
    ranks = np.empty(len(x))
    sorted_x = x[order]
    i = 0
    while i < len(x):
        j = i
        while j + 1 < len(x) and sorted_x[j + 1] == sorted_x[i]:
            j += 1
        ranks[order[i : j + 1]] = 0.5 * (i + j) + 1.0
        i = j + 1
    return ranks


def spearman(x: ArrayLike, y: ArrayLike) -> float:
    """Spearman's rank correlation: Pearson's correlation of the (tie-averaged) ranks.

    NaN when either variable is constant (the correlation is undefined) or n < 2.
    """
    rx, ry = rank(x), rank(y)
    if len(rx) != len(ry):
        raise ValueError(f"x and y differ in length: {len(rx)} vs {len(ry)}")
    if len(rx) < 2 or np.ptp(rx) == 0 or np.ptp(ry) == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def roc_auc(scores: ArrayLike, labels: ArrayLike) -> float:
    """P(score of a random positive > score of a random negative), ties counted 1/2.

    The Mann-Whitney U statistic over n_pos * n_neg (Hanley & McNeil 1982). NaN when
    there is no positive or no negative (the AUC is undefined).
    """
    s = np.asarray(scores, dtype=float)
    y = np.asarray(labels, dtype=bool)
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    r = rank(s)
    u = float(r[y].sum()) - n_pos * (n_pos + 1) / 2.0
    return u / (n_pos * n_neg)


def brier(probabilities: ArrayLike, labels: ArrayLike) -> float:
    """Mean squared difference between the predicted probability and the 0/1 outcome."""
    p = np.asarray(probabilities, dtype=float)
    y = np.asarray(labels, dtype=float)
    if len(p) == 0:
        return float("nan")
    return float(np.mean((p - y) ** 2))


@dataclass(frozen=True)
class CalibrationBin:
    """One equal-width bin of predicted probability: [low, high), its count and means."""

    low: float
    high: float
    count: int
    mean_predicted: float  # NaN for an empty bin
    observed_rate: float  # NaN for an empty bin


def calibration_bins(probabilities: ArrayLike, labels: ArrayLike, bins: int = 10) -> list[CalibrationBin]:
    """Equal-width bins over [0, 1] (the last one closed); the mean prediction and outcome per bin."""
    p = np.clip(np.asarray(probabilities, dtype=float), 0.0, 1.0)
    y = np.asarray(labels, dtype=float)
    index = np.minimum((p * bins).astype(int), bins - 1)
    out = []
    for b in range(bins):
        mask = index == b
        n = int(mask.sum())
        out.append(
            CalibrationBin(
                b / bins,
                (b + 1) / bins,
                n,
                float(p[mask].mean()) if n else float("nan"),
                float(y[mask].mean()) if n else float("nan"),
            )
        )
    return out


def expected_calibration_error(probabilities: ArrayLike, labels: ArrayLike, bins: int = 10) -> float:
    """ECE = sum over bins of n_b / N * |mean predicted_b - observed rate_b| (Naeini et al. 2015)."""
    table = calibration_bins(probabilities, labels, bins)
    total = sum(b.count for b in table)
    if total == 0:
        return float("nan")
    return float(sum(b.count / total * abs(b.mean_predicted - b.observed_rate) for b in table if b.count))


def quantile_groups(probabilities: ArrayLike, groups: int = 10) -> list[NDArray[np.intp]]:
    """Indices of ``probabilities`` in at most ``groups`` groups of near-equal size, in
    increasing order of probability, never splitting equal values (a campaign's predictions
    repeat: one value per alternative when the estimate is fixed)."""
    p = np.asarray(probabilities, dtype=float)
    order = np.argsort(p, kind="mergesort")
    out: list[NDArray[np.intp]] = []
    target = max(1, math.ceil(len(p) / groups))
    start = 0
    while start < len(p):
        end = min(len(p), start + target)
        while end < len(p) and p[order[end]] == p[order[end - 1]]:
            end += 1  # keep ties together
        out.append(order[start:end])
        start = end
    return out


def reliability_diagram(
    curves: Sequence[tuple[str, ArrayLike, ArrayLike]],
    path: Path | str,
    *,
    groups: int = 10,
    bins: int = 10,
    title: str = "Reliability of the predicted failure probabilities",
) -> Path:
    """One PNG: observed failure rate against mean predicted probability, per curve.

    ``curves``: (label, predicted probabilities, 0/1 outcomes). Trials are grouped by
    predicted probability into near-equal-count groups (:func:`quantile_groups`; equal-width
    bins put every small probability in the first bin); each point carries its 95%
    Clopper-Pearson interval; the x axis is logarithmic because failure probabilities of
    a good plan are small. The diagonal is perfect calibration; each label gives the
    curve's ECE (``bins`` equal-width bins) and Brier score.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    floor = 1e-4  # probabilities below are drawn at the axis' left edge
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    diagonal = np.logspace(np.log10(floor), 0.0, 200)  # y = x, which a log x axis bends
    ax.plot(diagonal, diagonal, color="0.6", linestyle="--", linewidth=1, label="perfect calibration")
    for label, p, y in curves:
        p_arr, y_arr = np.asarray(p, dtype=float), np.asarray(y, dtype=float)
        if len(p_arr) == 0:
            continue
        xs, ys, lows, highs = [], [], [], []
        for idx in quantile_groups(p_arr, groups):
            k, n = int(y_arr[idx].sum()), len(idx)
            low, high = clopper_pearson(k, n)
            xs.append(max(floor, float(p_arr[idx].mean())))
            ys.append(k / n)
            lows.append(k / n - low)
            highs.append(high - k / n)
        ece = expected_calibration_error(p_arr, y_arr, bins)
        ax.errorbar(
            xs,
            ys,
            yerr=[lows, highs],
            marker="o",
            capsize=3,
            linewidth=1,
            label=f"{label} (ECE {ece:.3f}, Brier {brier(p_arr, y_arr):.3f})",
        )
    ax.set_xscale("log")
    ax.set_xlim(floor * 0.8, 1.0)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("mean predicted probability (log scale; groups of near-equal count)")
    ax.set_ylabel("observed failure rate (95% Clopper-Pearson)")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
