"""The seed collision metric (Long et al. 2018, "Collision Risk") over a distance profile.

:func:`instantaneous_risk` scores one minimum robot-environment distance inside a safety
margin, ``(1 - d/d_safety)^b``; :func:`seed_collision_score` combines a trajectory's peak risk
and the fraction of time spent within the margin, ``peak_weight * peak + exposure_weight *
exposure``. Re-exported by :mod:`executive.risk.collision`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from executive.risk.collision_probability import CollisionModelError
from executive.schema.types import CollisionRiskConfig

__all__ = ["SeedScore", "instantaneous_risk", "scalar_risk", "seed_collision_score"]

FloatArray = NDArray[np.float64]


def instantaneous_risk(distance: float | FloatArray, d_safety: float, exponent: float) -> FloatArray:
    """Seed instantaneous risk ``(1 - d/d_safety)^b`` for ``d < d_safety``, 1 for ``d <= 0``, else 0.

    Long et al. 2018, "Collision Risk": the minimum robot-obstacle distance inside a safety margin.
    """
    d = np.asarray(distance, dtype=float)
    ratio = np.clip(1.0 - d / d_safety, 0.0, 1.0)
    return np.where(d < d_safety, ratio**exponent, 0.0)


def scalar_risk(distance: float, d_safety: float, exponent: float) -> float:
    """Scalar :func:`instantaneous_risk` (no numpy overhead per knot)."""
    if distance >= d_safety:
        return 0.0
    if distance <= 0.0:
        return 1.0
    return float((1.0 - distance / d_safety) ** exponent)


class SeedScore(NamedTuple):
    """Seed trajectory score = peak_weight * peak + exposure_weight * exposure."""

    score: float
    peak: float  # instantaneous risk at the trajectory's absolute minimum distance
    exposure: float  # fraction of the duration with d < d_safety


def seed_collision_score(
    times: FloatArray, distances: FloatArray, d_safety: float, config: CollisionRiskConfig
) -> SeedScore:
    """The seed's weighted sum of the peak term and the exposure term over a distance profile.

    Long et al. 2018, "Collision Risk": the absolute minimum distance over the trajectory
    and the time spent in proximity, combined by a weighted sum. Distances are taken as
    linear between knots, so the time within ``d_safety`` counts partial intervals exactly.
    """
    t = np.asarray(times, dtype=float)
    d = np.asarray(distances, dtype=float)
    if t.shape != d.shape or t.ndim != 1 or len(t) == 0:
        raise CollisionModelError(f"times {t.shape} and distances {d.shape} must be equal-length 1-D")
    peak = float(instantaneous_risk(float(np.min(d)), d_safety, config.exponent))
    duration = float(t[-1] - t[0])
    if len(t) == 1 or duration <= 0.0:
        exposure = float(np.mean(d < d_safety))
    else:
        lo, hi = np.minimum(d[:-1], d[1:]), np.maximum(d[:-1], d[1:])
        span = np.where(hi > lo, hi - lo, 1.0)
        frac = np.where(hi > lo, np.clip((d_safety - lo) / span, 0.0, 1.0), (lo < d_safety).astype(float))
        exposure = float(np.sum(frac * np.diff(t)) / duration)
    score = config.peak_weight * peak + config.exposure_weight * exposure
    return SeedScore(float(score), peak, exposure)
