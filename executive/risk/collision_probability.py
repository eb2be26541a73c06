"""First-order collision probability under horizontal pose errors of the environment bodies.

:func:`collision_probability` turns the near pairs of every knot (:class:`NearPair`, from
:class:`executive.risk.collision_model.CollisionModel`) into P(collision) over the trajectory,
per knot and per body, with the union bounds. To first order along coal's witness normal ``n``
(from the environment geom to the robot geom), shifting a body by ``delta`` changes a distance
by ``-n . delta``, so one pair collides with ``P = Phi(-d / sqrt(n^T Sigma n))``; per knot the
pairs of one body share its shift, bodies are independent, and over a trajectory the one static
shift per body makes the union over knots an exact 2-D Gaussian integral per body (polar form;
Craig 1991 for one half-plane). Re-exported by :mod:`executive.risk.collision`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from executive.errors import ExecutiveError

__all__ = [
    "CollisionModelError",
    "NearPair",
    "ProbabilityEstimate",
    "collision_probability",
    "gaussian_union_probability",
]

FloatArray = NDArray[np.float64]

_N_ANGLES = 720  # quadrature points of the 2-D Gaussian union integral
_N_BINS = 3600  # direction bins (0.1 degree) for merging events with the same normal


class CollisionModelError(ExecutiveError):
    """A collision query names a geom, body or object the collision model does not have."""


# --- first-order probability ---------------------------------------------------------------------


@functools.cache
def _cos_table(n_angles: int) -> FloatArray:
    """cos(theta_j - a_b) for every direction bin b (rows) and quadrature angle theta_j (columns),
    computed once: events only take the bins' directions."""
    angle = np.arange(_N_BINS) * (2.0 * math.pi / _N_BINS)
    theta = (np.arange(n_angles) + 0.5) * (2.0 * math.pi / n_angles)
    table = np.cos(theta[None, :] - angle[:, None])
    table.flags.writeable = False
    return table


def _union_by_group(
    group: NDArray[np.int_], phi: FloatArray, h: FloatArray, n_groups: int, n_angles: int
) -> FloatArray:
    """Per group g: P(any event ``u(phi_i) . z > h_i`` of g) for ``z ~ N(0, I_2)``, all ``h_i > 0``.

    Polar form: the safe set ``{u_i . z <= h_i}`` ends along direction theta at
    ``r(theta) = min_i h_i / cos(theta - phi_i)``, and ``P(outside) = mean_theta exp(-r^2/2)``
    (midpoint rule; for one event this is Craig's formula for ``Phi(-h)``). Directions are
    snapped to 0.1 degree bins and only the nearest event per bin is kept (a sweep past a
    flat face gives hundreds of events with one normal); the snap moves a boundary by at
    most ``h (1 - cos 0.05 deg)`` ~ ``4e-7 h``.
    """
    out = np.zeros(n_groups)
    if len(h) == 0:
        return out
    bins = np.round(phi * (_N_BINS / (2.0 * math.pi))).astype(int) % _N_BINS
    order = np.lexsort((h, bins, group))
    g, bn, hh = group[order], bins[order], h[order]
    keep = np.ones(len(g), dtype=bool)
    keep[1:] = (g[1:] != g[:-1]) | (bn[1:] != bn[:-1])
    g, hh, bn = g[keep], hh[keep], bn[keep]
    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    sizes = np.diff(np.r_[starts, len(g)])
    # A group of one event is one half-plane: P = Phi(-h) in closed form (what the quadrature
    # below approximates).
    single = starts[sizes == 1]
    out[g[single]] = ndtr(-hh[single])
    multi = np.repeat(sizes > 1, sizes)
    if not np.any(multi):
        return out
    g, hh, bn = g[multi], hh[multi], bn[multi]
    cos = _cos_table(n_angles)[bn]  # (N, M): cos(theta_j - angle of the event's bin)
    reach = np.full(cos.shape, np.inf)
    np.divide(hh[:, None], cos, out=reach, where=cos > 0.0)
    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    r = np.minimum.reduceat(reach, starts, axis=0)
    out[g[starts]] = np.mean(np.exp(-0.5 * r * r), axis=1)
    return out


def gaussian_union_probability(a: FloatArray, b: FloatArray, n_angles: int = _N_ANGLES) -> float:
    """P(any ``a_i . z > b_i``) for ``z ~ N(0, I_2)`` and every ``b_i > 0``, by 2-D quadrature.

    The safe set is the convex polygon ``{a_i . z <= b_i}`` around the origin; along a ray
    at angle theta it ends at ``r(theta) = min_i b_i / (a_i . u)``, and
    ``P(outside) = (1/2pi) * integral exp(-r^2/2) dtheta`` (polar form of the Gaussian;
    for one half-plane this is Craig's formula for ``Phi(-b/|a|)``).
    """
    a = np.asarray(a, dtype=float).reshape(-1, 2)
    b = np.asarray(b, dtype=float).reshape(-1)
    norm = np.hypot(a[:, 0], a[:, 1])
    if np.any(b <= 0.0) or np.any(norm <= 0.0):
        raise CollisionModelError("gaussian_union_probability needs every b_i > 0 and a_i != 0")
    phi = np.arctan2(a[:, 1], a[:, 0])
    return float(_union_by_group(np.zeros(len(b), dtype=int), phi, b / norm, 1, n_angles)[0])


class NearPair(NamedTuple):
    """A robot-environment pair that came within the model's cutoff at one knot."""

    env_body: int
    env_geom: int
    robot_geom: int
    distance: float
    normal: FloatArray  # unit, from the environment geom to the robot geom (coal's o1 -> o2)


class ProbabilityEstimate(NamedTuple):
    """First-order P(collision) of a trajectory."""

    probability: float  # exact union of the linearised events (static error per body)
    lower: float  # max_k P_k
    upper: float  # min(1, sum_k P_k)
    per_knot: FloatArray  # P_k
    # environment body id -> P(that body is touched over the trajectory); bodies no pair came
    # near are missing (P = 0)
    per_body: Mapping[int, float] = {}


class _Events(NamedTuple):
    """Linearised events ``u(phi) . z > h`` (z the body's shift over its sigma), by group."""

    group: NDArray[np.int_]
    phi: FloatArray
    h: FloatArray
    certain: NDArray[np.bool_]  # per group: some pair collides whatever the shift
    worst: FloatArray  # per group: Phi(-min h) (only used when some h <= 0)


def _group_probability(events: _Events, n_groups: int, n_angles: int) -> FloatArray:
    """P(union) per group: 1 if certain; the largest single P (>= 0.5, a lower bound) if the
    estimate already collides (the polar form needs a safe origin); else the polar integral."""
    unsafe = np.zeros(n_groups, dtype=bool)
    np.logical_or.at(unsafe, events.group, events.h <= 0.0)
    ok = ~unsafe[events.group]
    prob = _union_by_group(events.group[ok], events.phi[ok], events.h[ok], n_groups, n_angles)
    prob = np.where(unsafe, events.worst, prob)
    return np.where(events.certain, 1.0, prob)


def collision_probability(
    knots: Sequence[Sequence[NearPair]],
    sigma: Mapping[int, float],
    n_angles: int = _N_ANGLES,
    robot_sigma: Mapping[int, float] | None = None,
) -> ProbabilityEstimate:
    """First-order collision probability per knot and over the trajectory.

    ``knots[k]`` holds the near pairs of knot k; ``sigma`` maps an environment body id to
    its horizontal 1-sigma (missing: 0, exact). A body shifted by ``delta = sigma z`` makes
    pair i collide when ``n_xy,i . z > d_i / sigma`` (first order along coal's normal).
    Bodies are independent; per body the error is one static shift for the whole
    trajectory (as ``world.sample_perturbation`` draws it once per trial). Events with
    ``h > 9`` (P < 1e-19) are dropped.

    ``robot_sigma`` maps a robot-side geom to its own horizontal 1-sigma: a carried object
    sits in the hand wherever it really was (a grasp at the estimated pose does not
    re-centre it), so against an environment body of sigma ``s_e`` it is off by the
    difference of two independent shifts, ``N(0, (s_e^2 + s_o^2) I_2)``. Such pairs form
    their own group (environment body, carried geom); treating that group as independent
    of the environment body's other pairs is the approximation (the union over groups).
    """
    robot_sigma = robot_sigma or {}
    n_knots = len(knots)
    flat = [p for pairs in knots for p in pairs]
    knot = np.repeat(np.arange(n_knots), [len(pairs) for pairs in knots])
    env_body = np.fromiter((p.env_body for p in flat), dtype=int, count=len(flat))
    robot_geom = np.fromiter((p.robot_geom for p in flat), dtype=int, count=len(flat))
    distance = np.fromiter((p.distance for p in flat), dtype=float, count=len(flat))
    normal = np.array([p.normal[:2] for p in flat], dtype=float).reshape(-1, 2)
    # sigma per pair from small lookup tables (ids are small non-negative ints)
    env_table = np.zeros(max([*sigma, *env_body.tolist(), 0]) + 1)
    for b, v in sigma.items():
        env_table[b] = v
    own_table = np.zeros(max([*robot_sigma, *robot_geom.tolist(), 0]) + 1)
    for g, v in robot_sigma.items():
        own_table[g] = v
    s_env, s_own = env_table[env_body], own_table[robot_geom]
    # Groups: the environment body, or (environment body, carried geom) for a geom with its own sigma.
    key = env_body * (len(own_table) + 1) + np.where(s_own > 0.0, robot_geom + 1, 0)
    bodies, column = np.unique(key, return_inverse=True)
    n_bodies = len(bodies)
    gid_all = knot * n_bodies + column.reshape(-1)
    certain = np.zeros(n_knots * n_bodies, dtype=bool)
    worst = np.zeros(n_knots * n_bodies)
    scale = np.hypot(s_env, s_own) * np.hypot(normal[:, 0], normal[:, 1])
    exact = scale <= 1e-12  # no uncertainty along this normal: deterministic
    np.logical_or.at(certain, gid_all[exact], distance[exact] <= 0.0)
    reach = np.divide(distance, scale, out=np.full(len(flat), np.inf), where=~exact)
    keep = ~exact & (reach <= 9.0)
    group, h = gid_all[keep], reach[keep]
    np.maximum.at(worst, group, ndtr(-h))
    phi = np.arctan2(normal[keep, 1], normal[keep, 0])
    per_group = _group_probability(_Events(group, phi, h, certain, worst), n_knots * n_bodies, n_angles)
    miss = np.prod(1.0 - per_group.reshape(n_knots, n_bodies), axis=1) if n_bodies else np.ones(n_knots)
    per_knot = 1.0 - miss
    body_of = group % n_bodies if n_bodies else group
    tcertain = np.asarray(certain.reshape(n_knots, n_bodies).any(axis=0), dtype=bool)
    tworst = worst.reshape(n_knots, n_bodies).max(axis=0) if n_knots else np.zeros(n_bodies)
    per_body = _group_probability(_Events(body_of, phi, h, tcertain, tworst), n_bodies, n_angles)
    lower = float(np.max(per_knot)) if n_knots else 0.0
    upper = float(min(1.0, np.sum(per_knot)))
    point = float(np.clip(1.0 - np.prod(1.0 - per_body), lower, upper))
    return ProbabilityEstimate(
        point, lower, upper, per_knot, _by_env_body(bodies // (len(own_table) + 1), per_body)
    )


def _by_env_body(env_body: NDArray[np.int_], per_group: FloatArray) -> dict[int, float]:
    """P(any group of each environment body) from the groups' probabilities (a body's groups:
    itself, and itself against each carried geom with its own sigma; independent, as above)."""
    miss: dict[int, float] = {}
    for b, p in zip(env_body.tolist(), per_group.tolist(), strict=True):
        miss[b] = miss.get(b, 1.0) * (1.0 - p)
    return {b: 1.0 - m for b, m in miss.items()}
