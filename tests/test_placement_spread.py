"""Where a set-down leaves an object: the grip's error along the jaws with the execution's bias and
spread, against sampling; the approach window moved by the hand's error; a dry run's measured
placement in the drop mode."""

from __future__ import annotations

import numpy as np
import pytest

from executive.decision.drop_model import drop_measured
from executive.risk.gaussian import exceed_probability
from executive.risk.grasp_approach import ApproachEnvelope, approach_miss_probability
from executive.risk.pinch import placement_tolerance
from executive.risk.placement_spread import (
    MEASURED_PLACEMENT_SIGMA,
    ExecutionSpread,
    gaussian_exceed,
    misplace_probability,
)
from executive.risk.report import RiskReport

TOL = 0.02


def _sampled(
    mean: float,
    sigma: float,
    lateral_tol: float,
    axis: np.ndarray,
    shift: np.ndarray,
    spread: ExecutionSpread,
) -> tuple[float, float]:
    """P(|l| > lateral_tol or |l axis + shift + h| > TOL) by sampling, and its standard error."""
    rng = np.random.default_rng(11)
    n = 1_000_000
    ell = rng.normal(mean, sigma, n)
    h = spread.bias + rng.normal(0.0, spread.sigma, (n, 2))
    rest = ell[:, None] * axis + shift + h
    failed = (np.abs(ell) > lateral_tol) | (np.linalg.norm(rest, axis=1) > TOL)
    p = float(failed.mean())
    return p, float(np.sqrt(p * (1 - p) / n))


@pytest.mark.parametrize(
    ("mean", "sigma", "lateral_tol", "shift", "bias", "spread"),
    [
        (0.0, 0.01, 0.05, (0.0, 0.0), (0.003, -0.001), 0.002),  # the bundled book: a small bias
        (0.002, 0.005, 0.012, (0.0, 0.004), (-0.013, 0.0), 0.002),  # the glovebox's measured 13 mm short
        (0.0, 0.008, 0.03, (0.0, 0.0039), (0.005, 0.006), 0.0),  # a pinch and a bias, no spread
    ],
)
def test_the_placement_is_the_sampled_one(
    mean: float,
    sigma: float,
    lateral_tol: float,
    shift: tuple[float, float],
    bias: tuple[float, float],
    spread: float,
) -> None:
    axis = np.array([1.0, 0.0])
    execution = ExecutionSpread(np.array(bias), spread)
    p = misplace_probability(mean, sigma, lateral_tol, axis, np.array(shift), execution, TOL)
    expected, se = _sampled(mean, sigma, lateral_tol, axis, np.array(shift), execution)
    print(f"quadrature {p:.5f}, sampled {expected:.5f} +- {se:.5f}")
    assert p == pytest.approx(expected, abs=4 * se + 1e-4)


def test_without_execution_error_it_is_the_pinch_s_closed_form() -> None:
    """No bias, no spread, the pinch across the jaws: nested events of one Gaussian, exactly."""
    shift = np.array([0.0, 0.0039])
    p = misplace_probability(
        0.001, 0.01, 0.03, np.array([1.0, 0.0]), shift, ExecutionSpread(np.zeros(2), 0.0), TOL
    )
    bound = min(0.03, placement_tolerance(TOL, 0.0039))
    assert p == float(exceed_probability(bound, 0.01, 0.001))


def test_an_isotropic_grip_with_a_bias_is_the_rice_tail() -> None:
    rng = np.random.default_rng(5)
    e = np.array([0.008, -0.004]) + rng.normal(0.0, 0.006, (1_000_000, 2))
    expected = float((np.linalg.norm(e, axis=1) > TOL).mean())
    assert gaussian_exceed(np.array([0.008, -0.004]), 0.006, TOL) == pytest.approx(expected, abs=5e-4)


def test_the_hand_s_error_moves_the_approach_window_as_the_hand_s_geoms_would() -> None:
    """A hand h_c along the closing axis and h_l along the lateral one misses the object as an
    envelope whose corners are moved by (h_l, h_c) does; its spread adds to the object's."""
    a = np.array([[-0.05, 0.07], [0.0, 0.065], [0.05, 0.07]])
    b = np.array([[-0.05, -0.07], [0.04, -0.068]])
    env = ApproachEnvelope(a, b, 0.055)
    hand = (0.004, -0.006)
    offset = np.array([hand[1], hand[0]])
    moved = ApproachEnvelope(a + offset, b + offset, 0.055)
    p, _, _ = approach_miss_probability(env, 0.01, 0.05, hand=hand)
    assert p == pytest.approx(approach_miss_probability(moved, 0.01, 0.05)[0], rel=1e-9)
    spread, _, _ = approach_miss_probability(env, 0.01, 0.05, hand=hand, hand_sigma=0.005)
    wider, _, _ = approach_miss_probability(moved, float(np.hypot(0.01, 0.005)), 0.05)
    assert spread == pytest.approx(wider, rel=1e-9)
    assert approach_miss_probability(env, 0.01, 0.05) == approach_miss_probability(
        env, 0.01, 0.05, hand=(0.0, 0.0)
    )


def test_a_dry_run_s_measured_placement_replaces_the_predicted_one() -> None:
    """The drop report's final placement, 13 mm short as the dry run measured it: the rest of the
    mode stays, the placement's probability is the sampled one with that bias."""
    axis = np.array([1.0, 0.0])
    before = misplace_probability(
        0.0, 0.005, 0.012, axis, np.zeros(2), ExecutionSpread(np.zeros(2), 0.002), TOL
    )
    other = 0.01
    total = 1.0 - (1.0 - other) * (1.0 - before)
    details = {
        "placement_probability": before,
        "placement_lateral_mean": 0.0,
        "placement_lateral_sigma": 0.005,
        "placement_lateral_tolerance": 0.012,
        "placement_axis_x": 1.0,
        "placement_axis_y": 0.0,
    }
    report = RiskReport("drop", total, (before, total), 2.0, total, details=details)
    assert drop_measured(report, {"outcome": "success"}) is report  # nothing measured: unchanged
    refined = drop_measured(report, {"outcome": "success", "placement_offset": [-0.013, 0.0]})
    spread = ExecutionSpread(np.array([-0.013, 0.0]), MEASURED_PLACEMENT_SIGMA)
    placed, se = _sampled(0.0, 0.005, 0.012, axis, np.zeros(2), spread)
    print(
        f"before {before:.4f}, measured {refined.details['placement_probability']:.4f} (sampled {placed:.4f})"
    )
    assert refined.details["placement_probability"] == pytest.approx(placed, abs=4 * se + 1e-4)
    assert refined.probability == pytest.approx(1.0 - (1.0 - other) * (1.0 - placed), abs=4 * se + 1e-4)
    assert refined.probability > 4 * report.probability
