"""Normal-distribution helpers shared by the risk models.

Sources (one line each):
- Phi(x) = (1 + erf(x / sqrt 2)) / 2, evaluated as scipy.special.ndtr (accurate in both tails).
- P(|X| > t), X ~ N(mu, s^2) = Phi(-(t + mu)/s) + Phi(-(t - mu)/s) (folded normal tail).
- Union bounds: max_i p_i <= P(any) <= min(1, sum_i p_i) (Boole); independence: 1 - prod(1 - p_i).
- Monte Carlo standard error of a proportion: sqrt(p (1 - p) / n).
- Gauss-Hermite rule: E[f(X)], X ~ N(mu, s^2) = sum_k w_k f(mu + sqrt 2 s x_k) / sqrt(pi)
  (Abramowitz & Stegun 25.4.46).
- P(|mu + e| > t), e ~ N(0, s^2 I_k): the non-central chi-square tail with k degrees of freedom
  and non-centrality |mu|^2 / s^2 at (t / s)^2 (Johnson, Kotz & Balakrishnan, 1995, ch. 29).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtr

__all__ = [
    "McEstimate",
    "ball_exceed_probability",
    "exceed_probability",
    "gauss_hermite_normal",
    "independent_union",
    "normal_cdf",
    "union_bounds",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class McEstimate:
    """A Monte Carlo estimate of a probability: value, its standard error, the sample count."""

    probability: float
    stderr: float
    samples: int


def normal_cdf(x: ArrayLike) -> FloatArray:
    """Standard normal CDF Phi(x), elementwise (scipy.special.ndtr; +-inf map to 1 and 0)."""
    return np.asarray(ndtr(np.asarray(x, dtype=float)), dtype=float)


def exceed_probability(tolerance: ArrayLike, sigma: ArrayLike, mean: ArrayLike = 0.0) -> FloatArray:
    """P(|X| > tolerance) for X ~ N(mean, sigma^2), elementwise.

    sigma == 0 gives the indicator ``|mean| > tolerance``; a negative tolerance gives 1.
    """
    t, s, mu = np.broadcast_arrays(
        np.asarray(tolerance, dtype=float), np.asarray(sigma, dtype=float), np.asarray(mean, dtype=float)
    )
    out = np.where(np.abs(mu) > t, 1.0, 0.0)
    pos = s > 0.0
    if np.any(pos):
        sp = s[pos]
        out[pos] = ndtr(-(t[pos] + mu[pos]) / sp) + ndtr(-(t[pos] - mu[pos]) / sp)
    out = np.where(t < 0.0, 1.0, out)
    return np.asarray(np.clip(out, 0.0, 1.0), dtype=float)


def union_bounds(probabilities: ArrayLike) -> tuple[float, float]:
    """Bounds on P(any of the events): (max p_i, min(1, sum p_i)); (0, 0) for no events."""
    p = np.asarray(probabilities, dtype=float).ravel()
    if p.size == 0:
        return 0.0, 0.0
    return float(np.max(p)), float(min(1.0, float(np.sum(p))))


def independent_union(probabilities: ArrayLike) -> float:
    """P(any of the events) for independent events: 1 - prod(1 - p_i)."""
    p = np.clip(np.asarray(probabilities, dtype=float).ravel(), 0.0, 1.0)
    return float(0.0 - np.expm1(np.sum(np.log1p(-p)))) if np.all(p < 1.0) else 1.0  # 0.0 - x: never -0.0


def gauss_hermite_normal(order: int) -> tuple[FloatArray, FloatArray]:
    """Nodes and weights for E[f(Z)], Z ~ N(0, 1): E ~ sum w_k f(z_k), sum w_k = 1."""
    x, w = np.polynomial.hermite.hermgauss(order)
    return np.sqrt(2.0) * x, w / np.sqrt(np.pi)


def ball_exceed_probability(distance: ArrayLike, sigma: float, tolerance: float, dims: int) -> FloatArray:
    """P(|mu + e| > tolerance) for e ~ N(0, sigma^2 I_dims), per ``distance`` = |mu| (sigma > 0)."""
    from scipy import stats  # here: slow to import, and the rollout processes never need it

    d = np.asarray(distance, dtype=float)
    return np.asarray(stats.ncx2.sf((tolerance / sigma) ** 2, dims, (d / sigma) ** 2), dtype=float)
