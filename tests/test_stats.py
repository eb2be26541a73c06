"""Campaign statistics against closed forms, brute force and Monte Carlo."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as scipy_stats

from executive.validation.stats import (
    brier,
    calibration_bins,
    clopper_pearson,
    expected_calibration_error,
    quantile_groups,
    rank,
    reliability_diagram,
    roc_auc,
    spearman,
)


def test_clopper_pearson_closed_forms_at_the_ends() -> None:
    # k = 0: upper = 1 - (a/2)^(1/n); k = n: lower = (a/2)^(1/n) (P(X=0) = (1-p)^n).
    n = 10
    assert clopper_pearson(0, n) == (0.0, pytest.approx(1 - 0.025 ** (1 / n), abs=1e-12))
    assert clopper_pearson(n, n) == (pytest.approx(0.025 ** (1 / n), abs=1e-12), 1.0)
    assert clopper_pearson(0, n)[1] == pytest.approx(0.30850, abs=1e-5)


@pytest.mark.parametrize(("k", "n"), [(5, 10), (3, 100), (40, 100), (1, 7)])
def test_clopper_pearson_tails_are_alpha_over_two(k: int, n: int) -> None:
    # The defining property: P(X >= k | p_low) = 0.025 and P(X <= k | p_high) = 0.025.
    low, high = clopper_pearson(k, n)
    assert scipy_stats.binom.sf(k - 1, n, low) == pytest.approx(0.025, abs=1e-9)
    assert scipy_stats.binom.cdf(k, n, high) == pytest.approx(0.025, abs=1e-9)
    assert low < k / n < high


def test_clopper_pearson_textbook_value() -> None:
    # 5 of 10: (0.1871, 0.8129) (e.g. Agresti & Coull 1998, Table 1 region).
    low, high = clopper_pearson(5, 10)
    assert (low, high) == (pytest.approx(0.18709, abs=1e-5), pytest.approx(0.81291, abs=1e-5))


def test_clopper_pearson_rejects_impossible_counts() -> None:
    with pytest.raises(ValueError, match="failures must be in"):
        clopper_pearson(11, 10)
    assert clopper_pearson(0, 0) == (0.0, 1.0)


def test_rank_averages_ties() -> None:
    assert rank([10, 20, 20, 5]).tolist() == [2.0, 3.5, 3.5, 1.0]


def test_spearman_without_ties_is_the_closed_form() -> None:
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=30), rng.normal(size=30)
    d = rank(x) - rank(y)
    n = len(x)
    assert spearman(x, y) == pytest.approx(1 - 6 * np.sum(d**2) / (n * (n**2 - 1)), abs=1e-12)
    assert spearman(x, 3 * x + 1) == pytest.approx(1.0)
    assert spearman(x, -np.exp(x)) == pytest.approx(-1.0)


def test_spearman_with_ties_matches_scipy_and_constant_is_undefined() -> None:
    rng = np.random.default_rng(2)
    x, y = rng.integers(0, 4, 50), rng.integers(0, 3, 50)
    assert spearman(x, y) == pytest.approx(scipy_stats.spearmanr(x, y).statistic, abs=1e-12)
    assert np.isnan(spearman([1, 2, 3], [5, 5, 5]))


def test_roc_auc_is_the_pairwise_probability() -> None:
    rng = np.random.default_rng(3)
    scores = np.round(rng.random(80), 1)  # many ties
    labels = rng.random(80) < scores
    pos, neg = scores[labels], scores[~labels]
    brute = np.mean([1.0 if a > b else 0.5 if a == b else 0.0 for a, b in itertools.product(pos, neg)])
    assert roc_auc(scores, labels) == pytest.approx(brute, abs=1e-12)
    assert roc_auc([0.1, 0.2, 0.9], [False, False, True]) == 1.0
    assert roc_auc([0.5, 0.5], [False, True]) == 0.5
    assert np.isnan(roc_auc([0.1, 0.2], [False, False]))


def test_roc_auc_of_a_binormal_model_matches_its_closed_form() -> None:
    # Scores N(0,1) for negatives, N(d,1) for positives: AUC = Phi(d / sqrt(2)).
    rng = np.random.default_rng(4)
    d = 1.0
    scores = np.concatenate([rng.normal(0, 1, 20000), rng.normal(d, 1, 20000)])
    labels = np.concatenate([np.zeros(20000, bool), np.ones(20000, bool)])
    assert roc_auc(scores, labels) == pytest.approx(scipy_stats.norm.cdf(d / np.sqrt(2)), abs=0.01)


def test_brier_closed_form() -> None:
    assert brier([0.0, 1.0, 0.5, 0.2], [0, 1, 1, 1]) == pytest.approx((0 + 0 + 0.25 + 0.64) / 4)
    # A constant forecast p of a Bernoulli(q) outcome: E = (p - q)^2 + q (1 - q).
    rng = np.random.default_rng(5)
    y = rng.random(200000) < 0.3
    assert brier(np.full(len(y), 0.1), y) == pytest.approx(0.04 + 0.21, abs=0.004)


def test_calibration_bins_and_ece_by_hand() -> None:
    p = [0.05, 0.05, 0.95, 0.95, 0.55]
    y = [0, 1, 1, 1, 0]
    table = calibration_bins(p, y, bins=10)
    assert [b.count for b in table] == [2, 0, 0, 0, 0, 1, 0, 0, 0, 2]
    assert table[0].observed_rate == 0.5 and np.isnan(table[1].mean_predicted)
    # 2/5 |0.05 - 0.5| + 1/5 |0.55 - 0| + 2/5 |0.95 - 1|
    assert expected_calibration_error(p, y) == pytest.approx(0.4 * 0.45 + 0.2 * 0.55 + 0.4 * 0.05)
    assert calibration_bins([1.0], [1], bins=4)[-1].count == 1  # 1.0 falls in the last bin


def test_ece_monte_carlo_calibrated_vs_miscalibrated() -> None:
    rng = np.random.default_rng(6)
    p = rng.random(100000)
    calibrated = rng.random(len(p)) < p
    overconfident = rng.random(len(p)) < p**2  # the truth is p^2: ECE -> E|p - p^2| = 1/6
    assert expected_calibration_error(p, calibrated) < 0.01
    assert expected_calibration_error(p, overconfident) == pytest.approx(1 / 6, abs=0.01)


def test_reliability_diagram_writes_a_png(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    p = rng.random(500)
    curves = [("collision", p, rng.random(500) < p), ("fall", p * 0, p * 0)]
    out = reliability_diagram(curves, tmp_path / "r.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 10000


def test_quantile_groups_keep_ties_together_and_cover_every_trial() -> None:
    p = [0.3, 0.01, 0.01, 0.01, 0.2, 0.01, 0.5, 0.3]
    groups = quantile_groups(p, groups=4)
    assert sorted(int(i) for g in groups for i in g) == list(range(8))
    values = [sorted({p[i] for i in g}) for g in groups]
    assert values[0] == [0.01]  # the four equal values stay in one group
    assert all(max(a) <= min(b) for a, b in itertools.pairwise(values))
