"""P(fall) over a trajectory when the CoM estimate's error is one bias shared by every knot.

The error e ~ N(0, Sigma) is a model error that persists over the motion, not independent
noise per knot, so the motion fails iff at some knot mu_k + e leaves that knot's polygon P_k,
i.e. iff e lies outside the convex polygon S = cap_k (P_k - mu_k). P(e not in S) is then exact
(:func:`executive.risk.gaussian_polygon.probability_outside`); it is at least the worst knot's
probability, and at most the Boole sum over S's edges. :func:`persistent_bias_probability`
takes explicit polygons (re-exported by :mod:`executive.risk.fall`); :func:`support_probability`
takes a trajectory's :class:`executive.risk.fall_batch.KnotPolygons`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from executive.risk.fall_batch import (
    KnotPolygons,
    edge_probabilities_batch,
    halfplanes_batch,
    probability_outside_batch,
)
from executive.risk.gaussian import union_bounds
from executive.risk.gaussian_polygon import edge_probabilities, probability_outside
from executive.world.polygon import check_polygon, clip_polygon, polygon_area

__all__ = ["persistent_bias_probability", "support_probability"]

FloatArray = NDArray[np.float64]


def _intersect_halfplanes(safe: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray | None:
    """The convex polygon ``safe`` cut by every half-plane ``a_i . x <= b_i``; None once it is empty.

    The most violated half-plane first, one clip at a time (Sutherland-Hodgman), until every
    vertex satisfies every half-plane: the same intersection as clipping by all of them in turn,
    without visiting the (many) half-planes that do not cut it.
    """
    done = np.zeros(len(b), dtype=bool)
    while True:
        excess = np.max(safe @ a.T, axis=0) - b
        excess[done] = -np.inf
        j = int(np.argmax(excess)) if len(b) else 0
        if len(b) == 0 or excess[j] <= 0.0:
            return safe
        done[j] = True
        safe = clip_polygon(safe, a[j], float(b[j]))
        if len(safe) < 3 or polygon_area(safe) <= 0.0:
            return None


def _shifted_halfplanes(polygons: list[FloatArray], mus: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Half-planes (A, b) of every polygon P_k - mu_k, stacked; polygons of one size at once."""
    by_size: dict[int, list[int]] = {}
    for k, poly in enumerate(polygons):
        by_size.setdefault(len(poly), []).append(k)
    a_parts, b_parts = [], []
    for ks in by_size.values():
        v = np.stack([check_polygon(polygons[k]) for k in ks])
        a, b = halfplanes_batch(v)
        a_parts.append(a.reshape(-1, 2))
        b_parts.append((b - np.einsum("nij,nj->ni", a, mus[ks])).reshape(-1))
    return np.concatenate(a_parts), np.concatenate(b_parts)


def persistent_bias_probability(
    polygons: list[FloatArray], means: ArrayLike, cov: ArrayLike
) -> tuple[float, float]:
    """P(fall) over knots when the CoM error e ~ N(0, cov) is one bias shared by every knot.

    The motion fails iff mu_k + e leaves P_k at some knot k, i.e. iff e is outside
    S = cap_k (P_k - mu_k), a convex polygon (clipped half-plane by half-plane). Returns
    (exact P(e not in S), Boole upper bound over S's edges); (1, 1) when S is empty.
    """
    mus = np.asarray(means, dtype=float).reshape(len(polygons), -1)[:, :2]
    if len(polygons) == 0:
        raise ValueError("persistent_bias_probability: no polygons")
    safe: FloatArray | None = check_polygon(polygons[0]) - mus[0]
    if len(polygons) > 1:
        a, b = _shifted_halfplanes(polygons[1:], mus[1:])
        safe = _intersect_halfplanes(np.asarray(safe), a, b)
    if safe is None:
        return 1.0, 1.0
    zero = np.zeros(2)
    return probability_outside(safe, zero, cov), union_bounds(edge_probabilities(safe, zero, cov))[1]


def support_probability(
    polygons: KnotPolygons, mus: FloatArray, cov: FloatArray
) -> tuple[float, float, float]:
    """P(the persistent bias takes some knot's support point outside its polygon), with bounds.

    S = P_0 - mu_0 cut by every other knot's shifted half-planes (see the module doc); the point estimate
    is clipped into [max over knots of the exact and Boole-lower per-knot P, the Boole sum over S].
    """
    a_parts, b_parts, worst = [], [], 0.0
    for knots, verts in polygons.groups.values():
        a, b = halfplanes_batch(verts)
        a_parts.append(a.reshape(-1, 2))
        b_parts.append((b - np.einsum("nij,nj->ni", a, mus[knots])).reshape(-1))
        worst = max(worst, float(np.max(probability_outside_batch(verts, mus[knots], cov))))
        worst = max(worst, float(np.max(edge_probabilities_batch(verts, mus[knots], cov))))
    safe = _intersect_halfplanes(
        polygons.polygon(0) - mus[0], np.concatenate(a_parts), np.concatenate(b_parts)
    )
    if safe is None:
        return 1.0, 1.0, 1.0
    zero = np.zeros(2)
    probability = probability_outside(safe, zero, cov)
    upper = max(union_bounds(edge_probabilities(safe, zero, cov))[1], worst)
    return float(np.clip(probability, worst, upper)), worst, upper
