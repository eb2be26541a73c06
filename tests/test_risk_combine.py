"""Combining risks: closed forms and a Monte Carlo check of the independence formula and its bounds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from executive.errors import ExecutiveError
from executive.risk.combine import combine, probability_of_any
from executive.risk.report import RiskReport
from executive.schema.types import RiskConfig


def report(mode: str, p: float, severity: float, seed: float) -> RiskReport:
    return RiskReport(mode, p, (p, p), severity, seed)


def test_closed_form_values() -> None:
    cfg = RiskConfig()  # weights collision 1, fall 2, grasp 1
    total = combine(
        [report("collision", 0.2, 3.0, 0.5), report("fall", 0.1, 10.0, 0.4), report("drop", 0.05, 2.0, 0.1)],
        cfg,
    )
    assert total.probability == pytest.approx(1 - 0.8 * 0.9 * 0.95)  # 0.316
    assert total.probability_bounds == pytest.approx((0.2, 0.35))
    assert total.expected_loss == pytest.approx(0.2 * 3 + 0.1 * 10 + 0.05 * 2)  # 1.7
    assert total.weighted_sum == pytest.approx(1 * 0.5 + 2 * 0.4 + 1 * 0.1)  # 1.4
    assert total.value("expected_loss") == total.expected_loss
    with pytest.raises(ExecutiveError, match="valid"):
        total.value("median")


def test_independent_formula_matches_monte_carlo() -> None:
    rng = np.random.default_rng(3)
    p = np.array([0.2, 0.1, 0.05])
    n = 200_000
    any_failure = (rng.random((n, 3)) < p).any(axis=1).mean()
    estimate, lower, upper = probability_of_any(list(p))
    assert abs(any_failure - estimate) < 4 * np.sqrt(estimate * (1 - estimate) / n)
    assert lower <= any_failure <= upper


def test_bounds_hold_for_fully_dependent_failures() -> None:
    """Comonotone failures (one uniform draw) reach the lower bound, exclusive ones the upper."""
    rng = np.random.default_rng(4)
    p = np.array([0.2, 0.1, 0.05])
    u = rng.random(100_000)
    comonotone = (u[:, None] < p).any(axis=1).mean()
    exclusive = (u < p.sum()).mean()  # disjoint intervals [0, .2), [.2, .3), [.3, .35)
    _, lower, upper = probability_of_any(list(p))
    assert comonotone == pytest.approx(lower, abs=0.005)
    assert exclusive == pytest.approx(upper, abs=0.005)


@given(st.lists(st.floats(0.0, 1.0), min_size=0, max_size=6))
def test_estimate_between_bounds(ps: list[float]) -> None:
    estimate, lower, upper = probability_of_any(ps)
    assert 0.0 <= lower <= estimate + 1e-12 <= upper + 2e-12 <= 1.0 + 2e-12


def test_duplicate_mode_is_an_error() -> None:
    with pytest.raises(ExecutiveError, match="fall"):
        combine([report("fall", 0.1, 1, 0), report("fall", 0.2, 1, 0)], RiskConfig())
