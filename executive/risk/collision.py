"""Collision risk of a trajectory: coal signed distances, the seed metric, and P(collision).

The public names of the collision model, gathered from the modules that define them:

- :mod:`executive.risk.collision_model`: :class:`CollisionModel`, the closest robot-environment
  approach at every knot (coal signed distances behind a broad phase), and its records
  :class:`KnotDistance`, :class:`CollisionProfile`; the pairs it checks are those of
  :mod:`executive.risk.collision_pairs` over a :class:`CollisionSetup`
  (:mod:`executive.risk.collision_setup`).
- :mod:`executive.risk.collision_seed`: the seed metric (Long et al. 2018, "Collision Risk":
  instantaneous risk ``(1 - d/d_safety)^b``, trajectory score ``peak_weight * peak +
  exposure_weight * exposure``).
- :mod:`executive.risk.collision_probability`: the first-order probability of a collision under
  the environment bodies' horizontal pose errors, over the union of all knots (the union bounds
  ``max_k P_k <= P <= min(1, sum_k P_k)`` alongside).
- :mod:`executive.risk.collision_report`: :func:`assess_collision`, the RiskReport of a
  trajectory.
- :mod:`executive.risk.collision_monte_carlo`: :func:`monte_carlo_collision_probability`, which
  samples the same errors and recomputes coal distances to validate the first order.

Design notes and measurements: docs/risk_models.md.
"""

from __future__ import annotations

from executive.risk.collision_model import CollisionModel, CollisionProfile, KnotDistance, TrajectoryLike
from executive.risk.collision_monte_carlo import MonteCarloResult, monte_carlo_collision_probability
from executive.risk.collision_probability import (
    CollisionModelError,
    NearPair,
    ProbabilityEstimate,
    collision_probability,
    gaussian_union_probability,
)
from executive.risk.collision_report import assess_collision, breach_summary, report_from_profile
from executive.risk.collision_seed import SeedScore, instantaneous_risk, seed_collision_score
from executive.risk.collision_setup import Allow, CollisionSetup

__all__ = [
    "Allow",
    "CollisionModel",
    "CollisionModelError",
    "CollisionProfile",
    "CollisionSetup",
    "KnotDistance",
    "MonteCarloResult",
    "NearPair",
    "ProbabilityEstimate",
    "SeedScore",
    "TrajectoryLike",
    "assess_collision",
    "breach_summary",
    "collision_probability",
    "gaussian_union_probability",
    "instantaneous_risk",
    "monte_carlo_collision_probability",
    "report_from_profile",
    "seed_collision_score",
]
