"""The seed's grasp risk: a logistic in the pre-grasp error (Long et al. 2018, eq. 2).

Usage::

    r = seed_grasp_risk(position_error=0.01, angle_error=0.05, config=GraspRiskConfig())
    e = expected_seed_risk(error, config, position_sigma=0.01, yaw_sigma=0.05)
"""

from __future__ import annotations

import numpy as np
from scipy.special import expit

from executive.risk.gaussian import gauss_hermite_normal
from executive.risk.grasp_tolerance import GraspError
from executive.schema.types import GraspRiskConfig

__all__ = ["expected_seed_risk", "logistic_risk", "seed_grasp_risk"]


def logistic_risk(error: float, scale: float, x_max: float, steepness: float) -> float:
    """Seed eq. 2 for one error: 1 / (1 + exp(-a d / (x_max - d) + b)), guarded.

    d = |error|; b = steepness; a = b (x_max - scale) / scale (risk 1/2 at d = scale).
    d >= x_max (including inf) gives 1 (the limit of the formula as d -> x_max). Needs
    0 < scale < x_max and steepness > 0. Long et al. 2018, eq. 2; note that its form gives
    1 / (1 + e^b) > 0 at zero error.
    """
    if not (0.0 < scale < x_max) or not steepness > 0.0 or not np.isfinite(x_max):
        raise ValueError(
            f"logistic_risk: need 0 < scale < x_max < inf and steepness > 0, got scale={scale}, "
            f"x_max={x_max}, steepness={steepness}"
        )
    if np.isnan(error):
        raise ValueError("logistic_risk: the error is NaN")
    d = abs(float(error))
    if d >= x_max:
        return 1.0
    a = steepness * (x_max - scale) / scale
    z = a * d / (x_max - d) - steepness  # x_max - d > 0 here; may be huge near x_max
    return float(expit(z))


def seed_grasp_risk(position_error: float, angle_error: float, config: GraspRiskConfig) -> float:
    """The seed's weighted sum of the positional (m) and angular (rad) logistic risks, in [0, 1]."""
    total = config.position_weight + config.angle_weight
    if config.position_weight < 0.0 or config.angle_weight < 0.0 or total <= 0.0:
        raise ValueError(
            f"seed_grasp_risk: weights must be >= 0 with a positive sum, got "
            f"{config.position_weight}, {config.angle_weight}"
        )
    rp = logistic_risk(position_error, config.position_scale, config.position_max, config.steepness)
    ra = logistic_risk(angle_error, config.angle_scale_rad, config.angle_max_rad, config.steepness)
    return float(np.clip((config.position_weight * rp + config.angle_weight * ra) / total, 0.0, 1.0))


def expected_seed_risk(
    error: GraspError, config: GraspRiskConfig, position_sigma: float, yaw_sigma: float, order: int = 32
) -> float:
    """E[seed risk] over the object pose error (Gauss-Hermite in closing, lateral and yaw)."""
    z, w = gauss_hermite_normal(order)
    closing = error.closing + position_sigma * z
    lateral = error.lateral + position_sigma * z
    yaw = error.yaw + yaw_sigma * z
    pos_risk = np.array(
        [
            [
                logistic_risk(
                    float(np.hypot(c, lat)), config.position_scale, config.position_max, config.steepness
                )
                for lat in lateral
            ]
            for c in closing
        ]
    )
    ang_risk = np.array(
        [logistic_risk(float(a), config.angle_scale_rad, config.angle_max_rad, config.steepness) for a in yaw]
    )
    total = config.position_weight + config.angle_weight
    expected = (
        config.position_weight * float(w @ pos_risk @ w) + config.angle_weight * float(w @ ang_risk)
    ) / total
    return float(np.clip(expected, 0.0, 1.0))
