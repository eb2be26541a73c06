"""The value every risk model returns: a frozen :class:`RiskReport`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["RiskReport"]


@dataclass(frozen=True)
class RiskReport:
    """One failure mode's predicted risk for one trajectory (or one instant).

    probability: point estimate of P(failure) in [0, 1], the number used for ranking.
    probability_bounds: (lower, upper) bounds on that probability (e.g. union bounds).
    severity: cost of this failure if it happens (scenario ``risk.severity``).
    seed_score: the seed study's dimensionless metric for this mode (Long et al. 2018).
    times: (K,) knot times of the traces; traces: per-knot arrays for plots
        (e.g. "distance", "instantaneous_risk", "margin", "probability").
    details: scalar facts worth reporting (closest pair, minimum margin, ...).
    """

    mode: str
    probability: float
    probability_bounds: tuple[float, float]
    severity: float
    seed_score: float
    times: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    traces: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)
    details: Mapping[str, float | str] = field(default_factory=dict)

    @property
    def expected_loss(self) -> float:
        """probability x severity (the seed's equation 1: risk = P(failure) x severity)."""
        return self.probability * self.severity
