"""Combining the per-mode risk reports of one alternative into its total risk.

Three totals:

* the seed's weighted sum of the per-mode seed scores (Long et al. 2018: fall
  weighted above collision);
* the probability of any failure, ``1 - prod(1 - p_i)`` if the modes are
  independent, with the Fréchet bounds ``max p_i <= P <= min(1, sum p_i)``
  that hold whatever their dependence;
* the expected loss ``sum p_i * severity_i`` (risk = probability x severity,
  the seed's equation 1).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from executive.errors import ExecutiveError
from executive.risk.orderings import ordering as ordering_named
from executive.risk.report import RiskReport
from executive.schema.types import RiskConfig

__all__ = ["CombinedRisk", "combine", "probability_of_any"]


def probability_of_any(probabilities: Sequence[float]) -> tuple[float, float, float]:
    """(independent estimate, lower bound, upper bound) of P(at least one failure)."""
    none = 1.0
    for p in probabilities:
        none *= 1.0 - p
    lower = max(probabilities, default=0.0)  # Fréchet lower bound: the likeliest single failure
    upper = min(1.0, sum(probabilities))  # Boole's inequality
    return 1.0 - none, lower, upper


@dataclass(frozen=True)
class CombinedRisk:
    """The total risk of one alternative and the reports it was made from."""

    components: Mapping[str, RiskReport] = field(default_factory=dict)
    weighted_sum: float = 0.0
    probability: float = 0.0
    probability_bounds: tuple[float, float] = (0.0, 0.0)
    expected_loss: float = 0.0
    duration_s: float = 0.0  # the alternative's planned duration
    time_loss: float = 0.0  # risk.loss_per_second x duration_s: what its time costs (ordering loss_and_time)

    def value(self, ordering: str) -> float:
        """The quantity the selector ranks by: the named ordering's (:mod:`executive.risk.orderings`)."""
        return ordering_named(ordering).value(self)

    def as_dict(self) -> dict[str, float]:
        out = {mode: r.probability for mode, r in self.components.items()}
        out.update(
            combined=self.probability,
            combined_lower=self.probability_bounds[0],
            combined_upper=self.probability_bounds[1],
            weighted_sum=self.weighted_sum,
            expected_loss=self.expected_loss,
        )
        if self.time_loss:
            out.update(time_loss=self.time_loss, loss_and_time=self.expected_loss + self.time_loss)
        return out


def combine(reports: Sequence[RiskReport], config: RiskConfig, duration_s: float = 0.0) -> CombinedRisk:
    """Combine one report per failure mode (modes must be distinct) of an alternative planned to
    take ``duration_s`` (s; its time costs ``risk.loss_per_second`` per second)."""
    by_mode: dict[str, RiskReport] = {}
    for report in reports:
        if report.mode in by_mode:
            raise ExecutiveError(f"two reports for the failure mode '{report.mode}'")
        by_mode[report.mode] = report
    weights = dict(config.weights)
    weighted = sum(weights.get(mode, 0.0) * r.seed_score for mode, r in by_mode.items())
    p, lower, upper = probability_of_any([r.probability for r in by_mode.values()])
    loss = sum(r.expected_loss for r in by_mode.values())
    time_loss = config.loss_per_second * duration_s
    return CombinedRisk(by_mode, weighted, p, (lower, upper), loss, duration_s, time_loss)
