"""Where a set-down leaves an object: the grip's error along the jaws plus what execution adds.

A grasp leaves the object's error along the jaws ``l`` in the hand (closing does not correct
it), and a pinch shifts it across them (:mod:`executive.risk.pinch`). Execution adds the
hand's error at the end of the place move and what the release and the moves before it do to
the object (:class:`ExecutionSpread`: a bias and an isotropic spread in the table plane). The
object then rests at ``l a + shift + h`` from its target (``a`` the jaws' axis in the table
plane), misplaced beyond the detector's tolerance.

:func:`misplace_probability` gives P(|l| > the grasp's lateral tolerance, or misplaced): the
grasp's lateral failure and the misplacement are one event of ``l`` and ``h``, integrated over
``l`` (composite Gauss-Legendre inside the lateral tolerance, broken where ``|l a + c|`` crosses
the tolerance) with ``h``'s part a non-central chi-square tail of 2 degrees of freedom (the Rice
distribution; Johnson, Kotz & Balakrishnan, 1995, ch. 29); without spread the event is an
interval of ``l`` (normal tails, exact), and without any execution error the closed form of
:mod:`executive.risk.pinch`.

Usage::

    spread = ExecutionSpread(np.array([0.003, -0.001]), 0.003)
    p = misplace_probability(0.0, 0.01, 0.05, np.array([1.0, 0.0]), np.zeros(2), spread, 0.02)
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from executive.risk.gaussian import ball_exceed_probability, exceed_probability, normal_cdf
from executive.risk.pinch import placement_tolerance

__all__ = [
    "MEASURED_PLACEMENT_SIGMA",
    "SET_DOWN_SIGMA",
    "ExecutionSpread",
    "gaussian_exceed",
    "misplace_probability",
]

FloatArray = NDArray[np.float64]

#: m per axis: where a set-down leaves the object beyond the hand's predicted error at the place
#: (the release, the retreat, the moves' unmodelled errors), which a later grasp of it meets (a
#: regrasp); docs/risk_models.md, "Placement spread".
SET_DOWN_SIGMA = 0.002
#: m per axis: where a set-down leaves the object from truth to truth about where the dry run
#: left it, beyond the grip's error along the jaws (docs/risk_models.md, "Placement spread").
MEASURED_PLACEMENT_SIGMA = 0.002


@dataclass(frozen=True)
class ExecutionSpread:
    """What execution adds to an object's resting place, in the table plane (world x, y).

    bias: (2,) m, systematic (the hand's predicted end error at the place, or the offset a dry
        run measured); sigma: m per axis, isotropic, from truth to truth.
    """

    bias: FloatArray
    sigma: float

    @property
    def none(self) -> bool:
        """No execution error at all (the grip's error alone places the object)."""
        return self.sigma == 0.0 and not np.any(self.bias)


def misplace_probability(
    lateral_mean: float,
    lateral_sigma: float,
    lateral_tolerance: float,
    axis: FloatArray,
    shift: FloatArray,
    spread: ExecutionSpread,
    tolerance: float,
    order: int = 64,
) -> float:
    """P(|l| > lateral_tolerance, or |l axis + shift + h| > tolerance).

    Args:
        lateral_mean, lateral_sigma: the grip's error along the jaws, ``l ~ N(mean, sigma^2)`` (m).
        lateral_tolerance: beyond it the grasp itself fails (m; inf: it does not).
        axis: (2,) unit vector of the jaws' axis in the table plane.
        shift: (2,) the pinch's shift of the object in the table plane (m).
        spread: the execution's bias and spread (``h ~ N(bias, sigma^2 I_2)``).
        tolerance: the detector's placement tolerance (m).
        order: Gauss-Legendre nodes over ``l`` within the lateral tolerance.
    """
    axis = np.asarray(axis, dtype=float)
    shift = np.asarray(shift, dtype=float)
    if spread.none and abs(float(axis @ shift)) < 1e-12:  # nested events of one Gaussian: exact
        mu = float(np.linalg.norm(shift))
        bound = min(lateral_tolerance, placement_tolerance(tolerance, mu))
        return float(exceed_probability(bound, lateral_sigma, lateral_mean))
    centre = shift + spread.bias
    if lateral_sigma == 0.0:
        if abs(lateral_mean) > lateral_tolerance:
            return 1.0
        return float(_misplaced(lateral_mean * axis + centre, spread.sigma, tolerance)[0])
    grasp = float(exceed_probability(lateral_tolerance, lateral_sigma, lateral_mean))
    low = max(-lateral_tolerance, lateral_mean - 9.0 * lateral_sigma)
    high = min(lateral_tolerance, lateral_mean + 9.0 * lateral_sigma)
    if high <= low:
        return min(1.0, grasp)
    roots = _crossings(axis, centre, tolerance)
    if spread.sigma == 0.0:  # misplaced iff l is outside the crossings: normal tails, exact
        inside = 0.0
        if roots is not None:
            a, b = max(low, roots[0]), min(high, roots[1])
            if b > a:
                inside = float(
                    normal_cdf((b - lateral_mean) / lateral_sigma)
                    - normal_cdf((a - lateral_mean) / lateral_sigma)
                )
        kept = float(
            normal_cdf((high - lateral_mean) / lateral_sigma)
            - normal_cdf((low - lateral_mean) / lateral_sigma)
        )
        return float(np.clip(grasp + kept - inside, 0.0, 1.0))
    return float(
        np.clip(
            grasp
            + _inside(
                lateral_mean, lateral_sigma, low, high, axis, centre, spread.sigma, tolerance, roots, order
            ),
            0.0,
            1.0,
        )
    )


def _crossings(axis: FloatArray, centre: FloatArray, tolerance: float) -> tuple[float, float] | None:
    """The l where |l axis + centre| = tolerance (``axis`` a unit vector), or None: never within."""
    along = float(axis @ centre)
    gap = along * along - float(centre @ centre) + tolerance * tolerance
    if gap < 0.0:
        return None
    return -along - float(np.sqrt(gap)), -along + float(np.sqrt(gap))


def _inside(
    mean: float,
    sigma: float,
    low: float,
    high: float,
    axis: FloatArray,
    centre: FloatArray,
    spread: float,
    tolerance: float,
    roots: tuple[float, float] | None,
    order: int,
) -> float:
    """The integral over l in [low, high] of its density times P(misplaced | l): composite
    Gauss-Legendre, with breaks about the crossings, where the Rice tail turns from 0 to 1."""
    cuts = {low, high}
    for root in roots or ():
        cuts |= {root - 6.0 * spread, root, root + 6.0 * spread}
    edges = sorted(c for c in cuts if low <= c <= high)
    x, w = np.polynomial.legendre.leggauss(max(8, order // 2))
    total = 0.0
    for a, b in itertools.pairwise(edges):
        ell = 0.5 * (b - a) * x + 0.5 * (b + a)
        density = np.exp(-0.5 * ((ell - mean) / sigma) ** 2) / (sigma * np.sqrt(2.0 * np.pi))
        placed = _misplaced(ell[:, None] * axis[None, :] + centre[None, :], spread, tolerance)
        total += 0.5 * (b - a) * float(w @ (density * placed))
    return total


def _misplaced(centre: FloatArray, sigma: float, tolerance: float) -> FloatArray:
    """P(|c + h| > tolerance) for h ~ N(0, sigma^2 I_2), per row of ``centre`` (the Rice tail)."""
    distance = np.linalg.norm(np.atleast_2d(centre), axis=-1)
    if sigma == 0.0:
        return (distance > tolerance).astype(float)
    return ball_exceed_probability(distance, sigma, tolerance, 2)


def gaussian_exceed(mean: FloatArray, sigma: float, tolerance: float) -> float:
    """P(|m + e| > tolerance) for e ~ N(0, sigma^2 I_2) (a grip's isotropic error and the bias)."""
    return float(_misplaced(np.asarray(mean, dtype=float), sigma, tolerance)[0])
