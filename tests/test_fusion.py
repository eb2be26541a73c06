"""The fusion of analytic risk with rollout counts, and the stopping rule, against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, stats

from executive.risk.combine import combine
from executive.risk.fusion import ModePosterior, choice_confidence, fuse, posteriors
from executive.risk.report import RiskReport
from executive.schema.types import RiskConfig


def _analytic(collision: float, fall: float, grasp: float) -> object:
    reports = [
        RiskReport("collision", collision, (collision, collision), 3.0, 0.0),
        RiskReport("fall", fall, (fall, fall), 10.0, 0.0),
        RiskReport("drop", grasp, (grasp, grasp), 2.0, 0.0),
    ]
    return combine(reports, RiskConfig())


def test_fused_mean_is_the_posterior_mean_of_a_binomial_with_the_analytic_prior() -> None:
    """Monte Carlo of the generative model: p ~ Beta(w p_a, w (1 - p_a)), k ~ Bin(n, p).

    Among the draws with k failures, the mean of p is the fused probability (conjugacy,
    checked by simulation, not by the formula)."""
    w, p_a, n, k = 10.0, 0.2, 12, 5
    rng = np.random.default_rng(7)
    p = rng.beta(w * p_a, w * (1 - p_a), 2_000_000)
    kept = p[rng.binomial(n, p) == k]
    analytic = _analytic(0.01, 0.0, p_a)
    fused = fuse(analytic, {"drop": k, "success": n - k}, n, w, 0.95, RiskConfig())
    grasp = fused.components["drop"]
    se = kept.std() / np.sqrt(kept.size)
    assert grasp.probability == pytest.approx(kept.mean(), abs=4 * se)
    low, high = grasp.probability_bounds
    assert np.mean(kept < low) == pytest.approx(0.025, abs=0.003)
    assert np.mean(kept > high) == pytest.approx(0.025, abs=0.003)
    assert grasp.details["failures"] == k and grasp.details["rollouts"] == n
    assert grasp.details["analytic"] == p_a
    # the combination is made of the fused modes; expected loss keeps each mode's severity
    parts = [r.probability for r in fused.components.values()]
    assert fused.probability == pytest.approx(1 - np.prod([1 - q for q in parts]), rel=1e-12)
    assert fused.expected_loss == pytest.approx(
        sum(r.probability * r.severity for r in fused.components.values())
    )


def test_counts_map_to_their_modes_and_unstable_is_a_fall() -> None:
    analytic = _analytic(0.1, 0.0, 0.1)
    counts = {"collision": 2, "unstable": 1, "drop": 3, "timeout": 1, "success": 13}
    post = {m.mode: m for m in posteriors(analytic, counts, 20, 0.0)}
    assert post["collision"].mean == pytest.approx(2 / 20)
    assert post["fall"].mean == pytest.approx(1 / 20)
    assert post["drop"].mean == pytest.approx(3 / 20)
    # no prior and no data: the analytic value stands
    assert posteriors(analytic, {}, 0, 0.0)[0].mean == pytest.approx(0.1)


def test_choice_confidence_of_two_alternatives_against_quadrature() -> None:
    """P(p_best <= p_other + delta) for independent Beta posteriors, by numerical integration."""
    a = [ModePosterior("drop", 3.0, 27.0, 1.0)]
    b = [ModePosterior("drop", 9.0, 21.0, 1.0)]
    delta = 0.02
    best, confidence, cost = choice_confidence({"a": a, "b": b}, "probability", delta, draws=200_000, seed=1)
    exact, _ = integrate.quad(
        lambda x: stats.beta.pdf(x, 3.0, 27.0) * stats.beta.sf(x - delta, 9.0, 21.0), 0.0, 1.0
    )
    assert best == "a"
    assert confidence == pytest.approx(exact, abs=0.004)
    # expected opportunity cost E[max(0, X_a - X_b)] = int int max(0, x - y) f_a(x) f_b(y)
    eoc, _ = integrate.dblquad(
        lambda y, x: max(0.0, x - y) * stats.beta.pdf(x, 3.0, 27.0) * stats.beta.pdf(y, 9.0, 21.0),
        0.0,
        1.0,
        0.0,
        lambda x: x,
    )
    assert cost == pytest.approx(eoc, rel=0.05)


def test_choice_confidence_ranks_by_expected_loss_with_severities() -> None:
    """A likelier but cheap failure against a rarer but costly one: the loss decides."""
    cheap = [ModePosterior("drop", 20.0, 80.0, 1.0)]  # 0.20 x 1
    costly = [ModePosterior("fall", 10.0, 90.0, 10.0)]  # 0.10 x 10
    best, confidence, _ = choice_confidence({"cheap": cheap, "costly": costly}, "expected_loss", 0.0, seed=3)
    assert best == "cheap" and confidence > 0.95
    best, _, _ = choice_confidence({"cheap": cheap, "costly": costly}, "probability", 0.0, seed=3)
    assert best == "costly"
