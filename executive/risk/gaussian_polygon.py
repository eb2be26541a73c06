"""P(a Gaussian point lies outside a convex polygon), X ~ N(mean, cov) in the plane.

:func:`probability_outside` is exact (whitening and signed triangles with Owen's T, or a polar
quadrature to cross-check it); :func:`edge_probabilities` gives the per-edge probabilities whose
maximum and sum bound it (Boole); :func:`probability_outside_mc` samples it. The fall model asks
them of the CoM (or ZMP) and the support polygon; :mod:`executive.risk.fall_batch` evaluates the
same formulas for many knots at once. Re-exported by :mod:`executive.risk.fall`.

Sources (one line each):
- Per-edge probability: p_i = Phi(-(b_i - a_i.mu) / sqrt(a_i^T Sigma a_i)) for X ~ N(mu, Sigma);
  Boole: max p_i <= P(outside) <= min(1, sum p_i).
- Exact P(inside): whiten (z = L^-1 (x - mu), Sigma = L L^T), split the polygon into signed
  triangles (0, v_i, v_i+1), each a difference of right triangles (0, foot, foot + s t) whose
  standard-normal mass is atan(s/h)/(2 pi) - T(h, s/h) with Owen's T (Owen 1956, Ann. Math.
  Stat. 27:1075); cross-check: the polar reduction (1/2 pi) sum_i c_i int (1 - e^{-(c_i^2+s^2)/2})
  / (c_i^2 + s^2) ds along each edge, by composite Gauss-Legendre quadrature.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import owens_t

from executive.risk.gaussian import McEstimate, normal_cdf
from executive.world.polygon import check_polygon, halfplanes, signed_margin

__all__ = ["check_covariance", "edge_probabilities", "probability_outside", "probability_outside_mc"]

FloatArray = NDArray[np.float64]


def check_covariance(cov: ArrayLike) -> FloatArray:
    """``cov`` as a 2x2 covariance matrix (a scalar is that variance times the identity).

    Raises:
        ValueError: a matrix that is not finite, symmetric and positive semi-definite.
    """
    c = np.asarray(cov, dtype=float)
    if c.ndim == 0:
        c = float(c) * np.eye(2)
    c = c.reshape(2, 2)
    if not np.all(np.isfinite(c)) or not np.allclose(c, c.T, atol=1e-15, rtol=1e-9):
        raise ValueError(f"covariance must be a finite symmetric 2x2 matrix, got {c.tolist()}")
    if np.min(np.linalg.eigvalsh(c)) < -1e-15 * max(1.0, float(np.max(np.abs(c)))):
        raise ValueError(f"covariance must be positive semi-definite, got {c.tolist()}")
    return c


def edge_probabilities(polygon: ArrayLike, mean: ArrayLike, cov: ArrayLike) -> FloatArray:
    """Per-edge p_i = P(a_i . X > b_i) = Phi(-(b_i - a_i . mu) / sqrt(a_i^T Sigma a_i)).

    An edge direction with zero variance gives the indicator of the mean being beyond it.
    """
    a, b = halfplanes(polygon)
    mu = np.asarray(mean, dtype=float).reshape(-1)[:2]
    c = check_covariance(cov)
    slack = b - a @ mu
    var = np.einsum("ij,jk,ik->i", a, c, a)
    p = np.where(slack < 0.0, 1.0, 0.0)
    pos = var > 0.0
    p[pos] = normal_cdf(-slack[pos] / np.sqrt(var[pos]))
    return np.asarray(p, dtype=float)


def _whiten(polygon: FloatArray, mean: FloatArray, cov: FloatArray) -> FloatArray | None:
    """Polygon vertices in whitened coordinates z = L^-1 (x - mu); None for a zero covariance."""
    scale = float(np.max(np.abs(cov)))
    if scale == 0.0:
        return None
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:  # singular but non-zero: a negligible isotropic jitter
        chol = np.linalg.cholesky(cov + 1e-12 * scale * np.eye(2))
    return np.asarray(np.linalg.solve(chol, (polygon - mean).T).T, dtype=float)


def _edges_local(z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per edge of a CCW polygon (whitened): signed distance c of the origin to its line along the
    outward normal (c > 0: origin on the inner side) and the edge's end coordinates s_a < s_b along
    its direction, measured from the foot of the perpendicular from the origin."""
    nxt = np.roll(z, -1, axis=0)
    e = nxt - z
    t = e / np.hypot(e[:, 0], e[:, 1])[:, None]
    n = np.column_stack([t[:, 1], -t[:, 0]])
    c = np.einsum("ij,ij->i", n, z)
    return c, np.einsum("ij,ij->i", t, z), np.einsum("ij,ij->i", t, nxt)


def _inside_owens_t(z: FloatArray) -> float:
    """P(inside) for a whitened polygon: the signed triangles' standard-normal mass (Owen's T)."""
    c, sa, sb = _edges_local(z)
    h = np.abs(c)
    keep = h > 0.0
    h, c, sa, sb = h[keep], c[keep], sa[keep], sb[keep]

    def right_triangle(s: FloatArray) -> FloatArray:
        # Mass of the triangle (0, foot, foot + s t): angle/(2 pi) minus the part beyond the
        # distance-h line, Owen's T(h, s/h) = P(X > h, 0 < Y < (s/h) X). Odd in s.
        with np.errstate(over="ignore"):
            ratio = s / h
        return np.arctan2(s, h) / (2.0 * np.pi) - owens_t(h, ratio)

    return float(np.sum(np.sign(c) * (right_triangle(sb) - right_triangle(sa))))


def _outside_owens_t(z: FloatArray) -> float:
    """P(outside) for a whitened polygon strictly around the origin, without 1 - P(inside).

    With the origin inside, the edges' angles sum to 2 pi, so the angular parts of
    :func:`_inside_owens_t` sum to 1 and P(outside) = sum_i [T(h_i, s_b/h_i) - T(h_i, s_a/h_i)]
    (Owen 1956): every term is a non-negative mass beyond edge i in its wedge, so a tail of
    1e-20 keeps its relative accuracy (1 - P(inside) bottoms out at the double's 2.2e-16).
    """
    c, sa, sb = _edges_local(z)
    with np.errstate(over="ignore"):
        return float(np.sum(owens_t(c, sb / c) - owens_t(c, sa / c)))


def _polar_quadrature(z: FloatArray, integrand: str, panel: float = 0.5, order: int = 20) -> float:
    """(1/2 pi) sum_i c_i int g(c_i^2 + s^2) ds along each edge, composite Gauss-Legendre; g(r2) is
    (1 - e^{-r2/2}) / r2 (``inside``) or e^{-r2/2} / r2 (``outside``, origin strictly inside)."""
    c, sa, sb = _edges_local(z)
    x, w = np.polynomial.legendre.leggauss(order)
    total = 0.0
    for ci, lo, hi in zip(c, sa, sb, strict=True):
        if ci == 0.0:
            continue
        panels = max(1, int(np.ceil((hi - lo) / panel)))
        edges = np.linspace(lo, hi, panels + 1)
        half = 0.5 * np.diff(edges)
        mid = 0.5 * (edges[:-1] + edges[1:])
        s = (mid[:, None] + half[:, None] * x[None, :]).ravel()
        weights = (half[:, None] * w[None, :]).ravel()
        r2 = ci * ci + s * s
        if integrand == "inside":
            g = -np.expm1(-0.5 * r2) / r2  # (1 - e^{-r^2/2}) / r^2, smooth (-> 1/2 at r = 0)
        else:
            g = np.exp(-0.5 * r2) / r2
        total += ci * float(np.sum(weights * g))
    return total / (2.0 * np.pi)


def _inside_quadrature(z: FloatArray) -> float:
    """P(inside) for a whitened polygon by :func:`_polar_quadrature`."""
    return _polar_quadrature(z, "inside")


def probability_outside(
    polygon: ArrayLike,
    mean: ArrayLike,
    cov: ArrayLike,
    method: Literal["owens_t", "quadrature"] = "owens_t",
) -> float:
    """Exact P(X outside the polygon), X ~ N(mean, cov), by whitening and signed triangles.

    ``owens_t`` uses the closed form with Owen's T function; ``quadrature`` integrates the
    polar-reduced density along each edge with composite Gauss-Legendre. With
    the mean strictly inside, the tails beyond the edges are summed directly (not 1 - P(inside)),
    so a small probability keeps its relative accuracy down to the smallest doubles.
    A zero covariance gives the indicator of the mean being outside.
    """
    v = check_polygon(polygon)
    mu = np.asarray(mean, dtype=float).reshape(-1)[:2]
    c = check_covariance(cov)
    z = _whiten(v, mu, c)
    if z is None:
        return 1.0 if signed_margin(v, mu) < 0.0 else 0.0
    if method not in ("owens_t", "quadrature"):
        raise ValueError(f"probability_outside: method must be 'owens_t' or 'quadrature', got {method!r}")
    # The mean strictly inside: sum the tails directly. The quadrature's tail integrand
    # e^{-r^2/2} / r^2 peaks with width c along an edge, too sharp for its 0.5-wide panels when
    # an edge is nearer than 1 sigma (then P(outside) > Phi(-1) and 1 - P(inside) is accurate).
    c_min = float(np.min(_edges_local(z)[0]))
    if method == "owens_t" and c_min > 0.0:
        return float(np.clip(_outside_owens_t(z), 0.0, 1.0))
    if method == "quadrature" and c_min >= 1.0:
        return float(np.clip(_polar_quadrature(z, "outside"), 0.0, 1.0))
    inside = _inside_owens_t(z) if method == "owens_t" else _inside_quadrature(z)
    return float(np.clip(1.0 - inside, 0.0, 1.0))


def probability_outside_mc(
    polygon: ArrayLike, mean: ArrayLike, cov: ArrayLike, rng: np.random.Generator, samples: int
) -> McEstimate:
    """Monte Carlo estimate of P(X outside the polygon), X ~ N(mean, cov), with its standard error."""
    if samples < 1:
        raise ValueError(f"probability_outside_mc: samples must be >= 1, got {samples}")
    a, b = halfplanes(polygon)
    mu = np.asarray(mean, dtype=float).reshape(-1)[:2]
    x = rng.multivariate_normal(mu, check_covariance(cov), size=samples, method="cholesky")
    outside = np.any(x @ a.T > b, axis=1)
    p = float(np.mean(outside))
    return McEstimate(p, float(np.sqrt(max(p * (1.0 - p), 0.0) / samples)), samples)
