"""A hand's force on the world (a push or a press) in the fall model: the ZMP and its uncertain scale.

The robot feels the reaction of what its hand applies: its support point is then the zero
moment point (:func:`zero_moment_points`) instead of the CoM. The force's scale is uncertain
(the object's mass and friction, :func:`force_scale_distribution`) and capped where the push
stalls; :func:`under_force` averages the persistent-bias P(fall)
(:func:`executive.risk.fall_bias.support_probability`) over that scale. ``ExternalForce``,
``SCALE_FLOOR``, ``zero_moment_points`` and ``force_scale_distribution`` are re-exported by
:mod:`executive.risk.fall`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from executive.risk.fall_batch import signed_margin_batch
from executive.risk.fall_bias import support_probability
from executive.risk.fall_support import FallKnots

__all__ = [
    "SCALE_FLOOR",
    "ExternalForce",
    "force_scale_distribution",
    "support_points",
    "under_force",
    "zero_moment_points",
]

FloatArray = NDArray[np.float64]


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


def support_points(knots: FallKnots, external: ExternalForce | None) -> FloatArray:
    """The support point (K, 2) per knot: the CoM's, or with a force the ZMP at the mean felt force."""
    if external is None or not np.any(external.force):
        return knots.coms[:, :2]
    scales, weights = _felt_scales(external)
    return _zmps(knots, external, float(np.sum(weights * scales)))


def under_force(
    knots: FallKnots, external: ExternalForce | None, cov: FloatArray
) -> tuple[tuple[float, float, float], dict[str, float]]:
    """The support probability (and bounds) over the force's scale, and the force's numbers.

    Without a force: the CoM's. With one: the ZMP's with the force the robot feels, the push's
    (scaled by the object's mass and friction factors) up to the force at which it stalls
    (:func:`_felt_scales`); P(fall | felt scale) on a grid between the extreme scales,
    interpolated at the nodes and averaged with their weights.
    """
    if external is None or not np.any(external.force):
        return support_probability(knots.polygons, knots.coms[:, :2], cov), {}
    scales, weights = _felt_scales(external)
    low, high = float(np.min(scales)), float(np.max(scales))
    grid = np.linspace(low, high, _SCALE_GRID) if high > low else np.array([low])
    values = np.array(
        [support_probability(knots.polygons, _zmps(knots, external, float(scale)), cov) for scale in grid]
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


def _tipping_force(knots: FallKnots, external: ExternalForce) -> float:
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


def _zmps(knots: FallKnots, external: ExternalForce, scale: float) -> FloatArray:
    """The ZMPs with the force scaled by ``scale`` (no cap), the CoM given way by ``com_yield``."""
    force = scale * external.force
    coms = knots.coms
    if external.com_yield is not None:
        coms = coms + external.com_yield * np.linalg.norm(force, axis=1)[:, None]
    return zero_moment_points(coms, force, external.point, knots.mass, knots.gravity, knots.ground)
