"""Fall risk: the CoM against the support polygon, in the ground plane.

Sources (one line each):
- Seed (Long et al. 2018, "fall risk"): an uncertainty circle of radius r around the estimated
  CoM; "risk grows as the circle leaves the polygon (m - r)". Here: risk = ((r - m) / (2 r))^b
  for m < r, else 0, clipped to [0, 1] (0 when the circle just touches the edge, 1 once it is
  entirely outside, m = -r); b = FallRiskConfig.exponent.
- Convex hull: Andrew's monotone chain (A. M. Andrew, Inf. Process. Lett. 9(5):216-219, 1979).
- Per-edge probability: p_i = Phi(-(b_i - a_i.mu) / sqrt(a_i^T Sigma a_i)) for CoM ~ N(mu, Sigma);
  Boole: max p_i <= P(outside) <= min(1, sum p_i).
- Exact P(inside): whiten (z = L^-1 (x - mu), Sigma = L L^T), split the polygon into signed
  triangles (0, v_i, v_i+1), each a difference of right triangles (0, foot, foot + s t) whose
  standard-normal mass is atan(s/h)/(2 pi) - T(h, s/h) with Owen's T (Owen 1956, Ann. Math.
  Stat. 27:1075); cross-check: the polar reduction (1/2 pi) sum_i c_i int (1 - e^{-(c_i^2+s^2)/2})
  / (c_i^2 + s^2) ds along each edge, by composite Gauss-Legendre quadrature.
- Capture point (Pratt et al. 2006; Koolen et al. 2012, IJRR 31(9)): xi = c + c_dot / omega,
  omega = sqrt(g / h), h the CoM height above the ground.

Trajectory probability. The CoM estimate's error is a bias e ~ N(0, Sigma) that persists over
the motion (a model error, not independent noise per knot), so the motion fails iff at some
knot mu_k + e leaves that knot's polygon P_k, i.e. iff e lies outside the intersection
S = cap_k (P_k - mu_k). That intersection is again a convex polygon, so the point estimate
``probability`` is exact: P(e not in S). When the shifted polygons nest (the CoM heads towards
one edge), S is the worst knot's shifted polygon and the probability is the worst knot's;
in general it is at least that. Bounds: lower = max over knots of the exact per-knot
probability (``details["probability_worst_knot"]``), upper = min(1, Boole sum over the
edges of S).

Posture. The same persistent-bias model holds for the vertical: the pelvis, planned at its
lowest height z_min, ends e_z ~ N(0, sigma^2) off it (sigma the CoM uncertainty, taken
isotropic, so e_z is independent of the horizontal error), and the fall detector calls a
pelvis below the safe posture's floor (standing less ``SafePosture.fall_pelvis_drop``) a
fall: P_pelvis = Phi((floor - z_min) / sigma). A planned torso tilt beyond
``SafePosture.fall_tilt_deg`` is a fall for sure. The three failures are independent:
P(fall) = 1 - (1 - P_support)(1 - P_pelvis)(1 - P_tilt), and the same for both bounds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import owens_t

from executive.planning.timing import Trajectory
from executive.risk.fall_batch import (
    KnotPolygons,
    edge_probabilities_batch,
    halfplanes_batch,
    hulls,
    probability_outside_batch,
    signed_margin_batch,
)
from executive.risk.gaussian import McEstimate, normal_cdf, union_bounds
from executive.risk.report import RiskReport
from executive.robot.posture import standing_pelvis_height
from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World
from executive.world.polygon import (
    check_polygon,
    clip_polygon,
    convex_hull,
    halfplanes,
    polygon_area,
    signed_margin,
)

__all__ = [
    "ExternalForce",
    "assess_fall",
    "capture_point",
    "clip_polygon",
    "convex_hull",
    "edge_probabilities",
    "force_scale_distribution",
    "halfplanes",
    "persistent_bias_probability",
    "polygon_area",
    "probability_outside",
    "probability_outside_mc",
    "seed_fall_risk",
    "signed_margin",
    "support_polygon",
    "zero_moment_points",
]

FloatArray = NDArray[np.float64]


# --- the seed's uncertainty circle ------------------------------------------------------------


def seed_fall_risk(margin: float, radius: float, exponent: float) -> float:
    """Seed risk of a CoM uncertainty circle of ``radius`` whose centre has signed ``margin``.

    0 while the circle is inside (m >= r); ((r - m) / (2 r))^exponent as it leaves, reaching 1
    when the whole circle is outside (m <= -r). radius 0: 1 if m < 0 else 0.
    """
    if radius < 0.0 or exponent <= 0.0:
        raise ValueError(f"seed_fall_risk: need radius >= 0 and exponent > 0, got {radius}, {exponent}")
    if margin >= radius:
        return 0.0
    if radius == 0.0:
        return 1.0
    return float(np.clip((radius - margin) / (2.0 * radius), 0.0, 1.0) ** exponent)


# --- probabilities for CoM ~ N(mu, Sigma) -----------------------------------------------------


def _covariance(cov: ArrayLike) -> FloatArray:
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
    c = _covariance(cov)
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
    return _polar_quadrature(z, "inside")


def probability_outside(
    polygon: ArrayLike,
    mean: ArrayLike,
    cov: ArrayLike,
    method: Literal["owens_t", "quadrature"] = "owens_t",
) -> float:
    """Exact P(X outside the polygon), X ~ N(mean, cov), by whitening and signed triangles.

    ``owens_t`` uses the closed form with Owen's T function; ``quadrature`` integrates the
    polar-reduced density along each edge with composite Gauss-Legendre (both ~1e-12). With
    the mean strictly inside, the tails beyond the edges are summed directly (not 1 - P(inside)),
    so a small probability keeps its relative accuracy down to the smallest doubles.
    A zero covariance gives the indicator of the mean being outside.
    """
    v = check_polygon(polygon)
    mu = np.asarray(mean, dtype=float).reshape(-1)[:2]
    c = _covariance(cov)
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
    x = rng.multivariate_normal(mu, _covariance(cov), size=samples, method="cholesky")
    outside = np.any(x @ a.T > b, axis=1)
    p = float(np.mean(outside))
    return McEstimate(p, float(np.sqrt(max(p * (1.0 - p), 0.0) / samples)), samples)


# --- capture point ----------------------------------------------------------------------------


def capture_point(
    com: ArrayLike, com_velocity: ArrayLike, gravity: float = 9.81, ground_height: float = 0.0
) -> FloatArray:
    """Instantaneous capture point xi = c + c_dot / omega (xy), omega = sqrt(g / h), h = c_z - ground."""
    c = np.asarray(com, dtype=float).reshape(3)
    cd = np.asarray(com_velocity, dtype=float).reshape(-1)
    height = float(c[2] - ground_height)
    if gravity <= 0.0 or height <= 0.0:
        raise ValueError(
            f"capture_point: need g > 0 and the CoM above the ground, got g={gravity}, h={height}"
        )
    omega = float(np.sqrt(gravity / height))
    return np.asarray(c[:2] + cd[:2] / omega, dtype=float)


# --- the robot's support polygon -------------------------------------------------------------


def _ground_height(world: World, data: mujoco.MjData) -> float:
    floor = world.ids.floor_geom
    return float(data.geom_xpos[floor][2]) if floor >= 0 else 0.0


def _foot_points(world: World, data: mujoco.MjData) -> FloatArray:
    """Candidate ground-contact points (3D) of the foot geoms: box soles' bottom-face corners."""
    model = world.model
    points: list[FloatArray] = []
    for geoms in world.ids.foot_geoms.values():
        for g in geoms:
            centre = data.geom_xpos[g]
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
                rot = data.geom_xmat[g].reshape(3, 3)
                size = model.geom_size[g]
                k = int(np.argmax(np.abs(rot[2])))  # local axis closest to the vertical
                sign = -np.sign(rot[2, k]) if rot[2, k] != 0.0 else -1.0
                others = [i for i in range(3) if i != k]
                for s1 in (-1.0, 1.0):
                    for s2 in (-1.0, 1.0):
                        local = np.zeros(3)
                        local[k] = sign * size[k]
                        local[others[0]] = s1 * size[others[0]]
                        local[others[1]] = s2 * size[others[1]]
                        points.append(centre + rot @ local)
            else:
                points.append(centre.copy())
    return np.array(points, dtype=float).reshape(-1, 3)


def support_polygon(
    world: World, data: mujoco.MjData, from_contacts: bool, *, ground_tolerance: float = 0.01
) -> FloatArray:
    """Support polygon (V, 2), counter-clockwise: convex hull of the feet's ground contacts.

    from_contacts: the positions of the physics contacts between foot geoms and the floor
    (any non-robot geom when the world has no floor) in ``data.contact``.
    Otherwise (planning): the foot geometry in ``data`` (needs its kinematics): box soles'
    bottom-face corners, other foot geoms' centres; points higher than ``ground_tolerance``
    above the floor (a lifted foot) are left out.
    Raises ValueError when fewer than 3 non-collinear points remain.
    """
    feet = {g for geoms in world.ids.foot_geoms.values() for g in geoms}
    if from_contacts:
        floor = world.ids.floor_geom
        robot = set(world.ids.robot_geoms)
        pts = []
        for i in range(data.ncon):
            g1, g2 = int(data.contact.geom[i][0]), int(data.contact.geom[i][1])
            other = g2 if g1 in feet else g1 if g2 in feet else None
            if other is None or (other != floor if floor >= 0 else other in robot):
                continue
            pts.append(data.contact.pos[i][:2].copy())
        xy = np.array(pts, dtype=float).reshape(-1, 2)
        what = "physics contacts between the feet and the floor"
    else:
        p3 = _foot_points(world, data)
        p3 = p3[p3[:, 2] <= _ground_height(world, data) + ground_tolerance]
        xy = p3[:, :2]
        what = "foot geometry points on the ground"
    hull = convex_hull(xy)
    if len(hull) < 3:
        raise ValueError(f"support_polygon: {len(xy)} {what} do not span a polygon")
    return hull


# --- trajectory assessment --------------------------------------------------------------------


def _com_covariance(uncertainty: Uncertainty) -> FloatArray:
    return (uncertainty.com**2) * np.eye(2)


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


def _foot_points_batch(world: World, xpos: FloatArray, xmat: FloatArray) -> FloatArray:
    """:func:`_foot_points` for K knots at once: xpos (K, G, 3), xmat (K, G, 3, 3) of the foot geoms
    (in ``world.ids.foot_geoms`` order); returns (K, P, 3) in the same point order."""
    model = world.model
    geoms = [g for gs in world.ids.foot_geoms.values() for g in gs]
    parts = []
    signs = np.array([[-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]])  # (s1, s2) as in the loop
    for i, g in enumerate(geoms):
        centre, rot = xpos[:, i], xmat[:, i]
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX:
            parts.append(centre[:, None, :])
            continue
        size = model.geom_size[g]
        up = rot[:, 2, :]  # (K, 3): the world z row
        k = np.argmax(np.abs(up), axis=1)  # local axis closest to the vertical
        vert = up[np.arange(len(k)), k]
        sign = np.where(vert != 0.0, -np.sign(vert), -1.0)
        others = np.array([[1, 2], [0, 2], [0, 1]])[k]  # (K, 2), increasing
        local = np.zeros((len(k), 4, 3))
        rows = np.arange(len(k))
        local[rows, :, k] = (sign * size[k])[:, None]
        local[rows[:, None], np.arange(4)[None, :], others[:, 0:1]] = (
            signs[None, :, 0] * size[others[:, 0]][:, None]
        )
        local[rows[:, None], np.arange(4)[None, :], others[:, 1:2]] = (
            signs[None, :, 1] * size[others[:, 1]][:, None]
        )
        parts.append(centre[:, None, :] + np.einsum("kij,kcj->kci", rot, local))
    return np.concatenate(parts, axis=1)


def _seed_batch(margins: FloatArray, radius: float, exponent: float) -> FloatArray:
    """:func:`seed_fall_risk` elementwise."""
    seed_fall_risk(0.0, radius, exponent)  # validates radius and exponent
    if radius == 0.0:
        return np.where(margins >= 0.0, 0.0, 1.0)
    risk = np.clip((radius - margins) / (2.0 * radius), 0.0, 1.0) ** exponent
    return np.asarray(np.where(margins >= radius, 0.0, risk), dtype=float)


def _posture_probability(
    world: World, pelvis: FloatArray, upright: FloatArray, sigma: float
) -> dict[str, float]:
    """The safe posture's part of P(fall) (module doc, "Posture") and its numbers, for the details.

    ``pelvis``: the planned pelvis heights (m) per knot; ``upright``: the torso z axis' vertical
    component per knot; ``sigma``: the 1-sigma vertical error (m).
    """
    posture = world.profile.safe_posture
    ids = world.ids
    floor = standing_pelvis_height(world.model, ids.keyframe, ids.base_body) - posture.fall_pelvis_drop
    lowest = float(np.min(pelvis))
    if sigma > 0.0:
        p_pelvis = float(normal_cdf((floor - lowest) / sigma))
    else:
        p_pelvis = 1.0 if lowest < floor else 0.0
    tilt = float(np.degrees(np.arccos(np.clip(np.min(upright), -1.0, 1.0))))
    return {
        "min_pelvis_height": lowest,
        "pelvis_floor": floor,
        "probability_pelvis": float(p_pelvis),
        "max_trunk_tilt_deg": tilt,
        "probability_tilt": 1.0 if tilt > posture.fall_tilt_deg else 0.0,
    }


@dataclass(frozen=True)
class ExternalForce:
    """The force a hand exerts on the world at each knot (a push or a press); the robot feels its reaction.

    ``force``: (K, 3) N in the world frame, what the hand applies (:attr:`executive.planning.plan.Step.force`;
    zero rows where it applies none); ``point``: (K, 3) m, where it acts (the hand site).
    ``mass_sigma``, ``friction_sigma``: relative 1-sigma errors of the object's mass and friction;
    the force scales with their product (Coulomb: ``mu m g``), each factor floored at
    :data:`SCALE_FLOOR` as the truth sampler draws them. ``limit``: the largest force (N) the
    robot feels (a push that needs more stalls, :class:`executive.risk.push.PushLimits`);
    ``limit_low``: when given, the force at which it stalls is uniform in ``[limit_low, limit]``
    (how far the hand lags when its move gives up). ``com_yield``: (K, 3) m per newton, how far
    the CoM gives way under the force (the servos yield, :func:`executive.risk.push.yielding`).
    """

    force: FloatArray
    point: FloatArray
    mass_sigma: float = 0.0
    friction_sigma: float = 0.0
    limit: float = float("inf")
    limit_low: float | None = None
    com_yield: FloatArray | None = None


#: The truth sampler's floor on its mass and friction factors (executive.world.model.sample_perturbation).
SCALE_FLOOR = 0.2
#: Gauss-Hermite order per factor of the force's scale, and the grid P(fall | scale) is evaluated on.
_SCALE_ORDER = 40
_SCALE_GRID = 33


def zero_moment_points(
    coms: FloatArray, force: FloatArray, point: FloatArray, mass: float, gravity: float, ground: float
) -> FloatArray:
    """ZMP (K, 2) of a robot holding still while its hand exerts ``force`` (K, 3) at ``point`` (K, 3).

    The reaction ``f = -force`` acts on the robot; the moments about the ZMP on the ground balance:
    ``zmp (m g - f_z) = m g c_xy + h f_xy - p_xy f_z`` with ``h = p_z - ground``. A horizontal
    push F at hand height h moves the ZMP by ``-F h / (m g)``, against the push.
    """
    # Kajita et al., Introduction to Humanoid Robotics (Springer 2014), sec. 3.2: ZMP with external forces.
    f = -np.asarray(force, dtype=float)
    p = np.asarray(point, dtype=float)
    weight = mass * gravity
    height = p[:, 2] - ground
    num = weight * coms[:, :2] + height[:, None] * f[:, :2] - p[:, :2] * f[:, 2:3]
    return np.asarray(num / (weight - f[:, 2:3]), dtype=float)


def force_scale_distribution(mass_sigma: float, friction_sigma: float) -> tuple[FloatArray, FloatArray]:
    """Nodes and weights of the force's scale ``max(.2, 1 + s_m z) max(.2, 1 + s_f z')``, z, z' ~ N(0, 1).

    Gauss-Hermite (probabilists') in each factor; one node of weight 1 when both sigmas are 0.
    """
    x, w = np.polynomial.hermite_e.hermegauss(_SCALE_ORDER)
    w = w / np.sum(w)

    def factor(sigma: float) -> tuple[FloatArray, FloatArray]:
        if sigma <= 0.0:
            return np.ones(1), np.ones(1)
        return np.maximum(SCALE_FLOOR, 1.0 + sigma * x), w

    a, wa = factor(mass_sigma)
    b, wb = factor(friction_sigma)
    return np.outer(a, b).ravel(), np.outer(wa, wb).ravel()


@dataclass(frozen=True)
class _Knots:
    """Per knot of a trajectory: CoM, the feet's support polygons, pelvis height, torso uprightness."""

    times: FloatArray
    coms: FloatArray  # (K, 3)
    polygons: KnotPolygons
    pelvis: FloatArray
    upright: FloatArray  # the torso z axis' vertical component
    ground: float
    gravity: float
    mass: float  # the robot's


def _knots(world: World, trajectory: Trajectory) -> _Knots:
    """The robot's CoM, support polygon and posture at every knot (MuJoCo kinematics, robot bodies only)."""
    model = world.model
    times = np.asarray(trajectory.times, dtype=float)
    qpos = np.asarray(trajectory.qpos, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq or len(times) != len(qpos) or len(times) == 0:
        raise ValueError(
            f"assess_fall: trajectory '{trajectory.name}' has qpos {qpos.shape} and {len(times)} "
            f"times; the world's model needs (K, {model.nq}) with K = len(times) >= 1"
        )
    data = mujoco.MjData(model)
    base, torso = world.ids.base_body, world.ids.torso_body
    count = len(times)
    feet = [g for gs in world.ids.foot_geoms.values() for g in gs]
    coms = np.zeros((count, 3))
    xpos = np.zeros((count, len(feet), 3))
    xmat = np.zeros((count, len(feet), 9))
    pelvis, upright = np.zeros(count), np.zeros(count)
    for k in range(count):
        data.qpos[:] = qpos[k]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        coms[k] = data.subtree_com[base]
        xpos[k] = data.geom_xpos[feet]
        xmat[k] = data.geom_xmat[feet]
        pelvis[k] = data.xpos[base][2]
        upright[k] = data.xmat[torso][8]
    ground = _ground_height(world, data)
    points = _foot_points_batch(world, xpos, xmat.reshape(count, len(feet), 3, 3))
    polygons = hulls(points[..., :2], points[..., 2] <= ground + 0.01)
    gravity = float(np.linalg.norm(model.opt.gravity))
    mass = float(model.body_subtreemass[base])
    return _Knots(times, coms, polygons, pelvis, upright, ground, gravity, mass)


def _capture_points(knots: _Knots) -> FloatArray:
    """Capture point (K, 2) of each knot, the CoM velocity by finite differences."""
    coms, times, gravity = knots.coms, knots.times, knots.gravity
    velocity = np.asarray(np.gradient(coms, times, axis=0)) if len(times) >= 2 else np.zeros_like(coms)
    height = coms[:, 2] - knots.ground
    if gravity <= 0.0 or np.any(height <= 0.0):
        raise ValueError(
            f"capture_point: need g > 0 and the CoM above the ground, got g={gravity}, "
            f"h={float(np.min(height))}"
        )
    return np.asarray(coms[:, :2] + velocity[:, :2] / np.sqrt(gravity / height)[:, None], dtype=float)


def _per_knot(
    polygons: KnotPolygons, mus: FloatArray, xi: FloatArray, cov: FloatArray
) -> dict[str, FloatArray]:
    """Per knot: signed margin of ``mus``, capture margin of ``xi``, exact and Boole P(outside)."""
    count = len(mus)
    out = {name: np.zeros(count) for name in ("margin", "capture", "probability", "lower", "upper")}
    for knots, verts in polygons.groups.values():
        mu = mus[knots]
        out["margin"][knots] = signed_margin_batch(verts, mu)
        out["capture"][knots] = signed_margin_batch(verts, xi[knots])
        p = edge_probabilities_batch(verts, mu, cov)
        out["lower"][knots] = np.max(p, axis=1)
        out["upper"][knots] = np.minimum(1.0, np.sum(p, axis=1))
        out["probability"][knots] = probability_outside_batch(verts, mu, cov)
    return out


def _support_probability(
    polygons: KnotPolygons, mus: FloatArray, cov: FloatArray
) -> tuple[float, float, float]:
    """P(the persistent bias takes some knot's support point outside its polygon), with bounds.

    S = P_0 - mu_0 cut by every other knot's shifted half-planes (module doc); the point estimate
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


def _under_force(
    knots: _Knots, external: ExternalForce | None, cov: FloatArray
) -> tuple[tuple[float, float, float], dict[str, float]]:
    """The support probability (and bounds) over the force's scale, and the force's numbers.

    Without a force: the CoM's. With one: the ZMP's with the force the robot feels, the push's
    (scaled by the object's mass and friction factors) up to the force at which it stalls
    (:func:`_felt_scales`); P(fall | felt scale) on a grid between the extreme scales,
    interpolated at the nodes and averaged with their weights.
    """
    if external is None or not np.any(external.force):
        return _support_probability(knots.polygons, knots.coms[:, :2], cov), {}
    scales, weights = _felt_scales(external)
    low, high = float(np.min(scales)), float(np.max(scales))
    grid = np.linspace(low, high, _SCALE_GRID) if high > low else np.array([low])
    values = np.array(
        [_support_probability(knots.polygons, _zmps(knots, external, float(scale)), cov) for scale in grid]
    )
    expected = tuple(float(np.sum(weights * np.interp(scales, grid, values[:, j]))) for j in range(3))
    peak = float(np.max(np.linalg.norm(external.force, axis=1)))
    most = min(1.0, external.limit / peak)
    shift = np.linalg.norm(_zmps(knots, external, most) - knots.coms[:, :2], axis=1)
    facts = {
        "max_external_force": peak,
        "max_zmp_shift": float(np.max(shift)),
        "felt_force_mean": float(np.sum(weights * scales) * peak),
        "probability_support_most_felt": float(np.interp(most, grid, values[:, 0])),
        "arm_force_limit": float(external.limit),
        "force_to_tip": _tipping_force(knots, external),
    }
    return (expected[0], expected[1], expected[2]), facts


def _felt_scales(external: ExternalForce) -> tuple[FloatArray, FloatArray]:
    """Nodes and weights of the felt force's scale: ``min(s, stall / F)``.

    ``s``: the push's scale (:func:`force_scale_distribution`); ``stall``: ``limit``, or uniform in
    ``[limit_low, limit]`` (16 equal bins' midpoints); ``F``: the push's largest force.
    """
    nodes, weights = force_scale_distribution(external.mass_sigma, external.friction_sigma)
    peak = float(np.max(np.linalg.norm(external.force, axis=1)))
    if external.limit_low is None or external.limit_low >= external.limit:
        stalls = np.array([external.limit])
    else:
        stalls = external.limit_low + (np.arange(16) + 0.5) / 16 * (external.limit - external.limit_low)
    scales = np.minimum(nodes[:, None], stalls[None, :] / peak).ravel()
    return scales, (weights[:, None] * np.full(len(stalls), 1.0 / len(stalls))[None, :]).ravel()


def _tipping_force(knots: _Knots, external: ExternalForce) -> float:
    """N of the largest hand force (uncapped) that takes the ZMP to the support polygon's edge.

    Bisection on the force's scale (the margin falls as the push grows); inf when even 1000
    times the push leaves the ZMP inside.
    """

    def margin(scale: float) -> float:
        mus = _zmps(knots, external, scale)
        return min(
            float(np.min(signed_margin_batch(verts, mus[idx])))
            for idx, verts in knots.polygons.groups.values()
        )

    low, high = 0.0, 1000.0
    if margin(high) > 0.0:
        return float("inf")
    if margin(low) <= 0.0:
        return 0.0
    for _ in range(50):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if margin(mid) > 0.0 else (low, mid)
    return float(high * np.max(np.linalg.norm(external.force, axis=1)))


def _zmps(knots: _Knots, external: ExternalForce, scale: float) -> FloatArray:
    """The ZMPs with the force scaled by ``scale`` (no cap), the CoM given way by ``com_yield``."""
    force = scale * external.force
    coms = knots.coms
    if external.com_yield is not None:
        coms = coms + external.com_yield * np.linalg.norm(force, axis=1)[:, None]
    return zero_moment_points(coms, force, external.point, knots.mass, knots.gravity, knots.ground)


def _with_posture(p: float, posture: dict[str, float]) -> float:
    """1 - (1 - p)(1 - P_pelvis)(1 - P_tilt), as -expm1(sum log1p(-p_i)): a 1e-30 keeps its digits."""
    terms = np.array([p, posture["probability_pelvis"], posture["probability_tilt"]])
    with np.errstate(divide="ignore"):
        return float(-np.expm1(np.sum(np.log1p(-terms))))


def assess_fall(
    world: World,
    trajectory: Trajectory,
    risk_config: RiskConfig,
    uncertainty: Uncertainty,
    external: ExternalForce | None = None,
) -> RiskReport:
    """Fall risk of a trajectory on ``world``'s model (see the module doc for the formulas).

    Per knot: the robot's CoM (recomputed with MuJoCo from the knot's qpos, robot bodies only),
    the support polygon from the foot geometry, the signed margin, the seed's circle risk, the
    exact and Boole probabilities that the true support point (N(., uncertainty.com^2 I)) is
    outside, and the capture point's margin (finite-difference CoM velocity). The knots are
    evaluated together (:mod:`executive.risk.fall_batch`).

    Args:
        world: the estimate world whose model the trajectory's qpos index.
        trajectory: the motion (e.g. an alternative's steps concatenated).
        risk_config: the scenario's ``risk`` (the seed circle's radius and exponent, the severity).
        uncertainty: the scenario's 1-sigma errors (the CoM's).
        external: the forces the hands exert per knot: the support point is then the ZMP
            (:func:`zero_moment_points`) instead of the CoM, and the probability is averaged
            over the force's uncertain scale (:func:`force_scale_distribution`).

    Returns:
        The ``fall`` report; its details name the minimum margin, the posture's part and, with a
        force, the largest force and ZMP shift.

    Raises:
        ValueError: a trajectory whose qpos do not fit the model, or a CoM not above the ground.
    """
    cfg = risk_config.fall
    radius = cfg.circle_radius if cfg.circle_radius is not None else cfg.sigmas * uncertainty.com
    cov = _covariance(_com_covariance(uncertainty))
    knots = _knots(world, trajectory)
    xi = _capture_points(knots)
    mus = knots.coms[:, :2]
    if external is not None and np.any(external.force):  # the traces at the mean felt force
        scales, weights = _felt_scales(external)
        mus = _zmps(knots, external, float(np.sum(weights * scales)))
    per = _per_knot(knots.polygons, mus, xi, cov)
    (probability, lower, upper), force_facts = _under_force(knots, external, cov)
    posture = _posture_probability(world, knots.pelvis, knots.upright, float(uncertainty.com))
    return _report(
        world,
        trajectory,
        risk_config,
        knots,
        per,
        (probability, lower, upper),
        radius,
        {**posture, **force_facts, "com_sigma": float(uncertainty.com)},
    )


def _report(
    world: World,
    trajectory: Trajectory,
    risk_config: RiskConfig,
    knots: _Knots,
    per: dict[str, FloatArray],
    support: tuple[float, float, float],
    radius: float,
    facts: dict[str, float],
) -> RiskReport:
    """The fall report from the per-knot numbers and the support probability with its bounds."""
    times, coms, margins = knots.times, knots.coms, per["margin"]
    seed = _seed_batch(margins, radius, risk_config.fall.exponent)
    k_min, k_cap = int(np.argmin(margins)), int(np.argmin(per["capture"]))
    k_worst = int(np.argmax(per["probability"]))
    mismatch = (
        float(np.max(np.linalg.norm(np.asarray(trajectory.com_path, dtype=float) - coms, axis=1)))
        if np.shape(trajectory.com_path) == coms.shape
        else float("nan")
    )
    probability, lower, upper = support
    return RiskReport(
        mode="fall",
        probability=_with_posture(probability, facts),
        probability_bounds=(_with_posture(lower, facts), _with_posture(upper, facts)),
        severity=float(risk_config.severity.fall),
        seed_score=float(np.max(seed)),
        times=times.copy(),
        traces={
            "margin": margins,
            "seed_risk": seed,
            "probability": per["probability"],
            "probability_lower": per["lower"],
            "probability_upper": per["upper"],
            "capture_margin": per["capture"],
            "com_x": coms[:, 0].copy(),
            "com_y": coms[:, 1].copy(),
            "pelvis_height": knots.pelvis,
        },
        details={
            "min_margin": float(margins[k_min]),
            "min_margin_time": float(times[k_min]),
            "min_capture_margin": float(per["capture"][k_cap]),
            "min_capture_margin_time": float(times[k_cap]),
            "probability_worst_knot": float(per["probability"][k_worst]),
            "worst_knot_time": float(times[k_worst]),
            "circle_radius": float(radius),
            "com_path_mismatch": mismatch,
            "support_area": polygon_area(knots.polygons.polygon(k_min)),
            "probability_support": probability,
            **facts,
        },
    )
