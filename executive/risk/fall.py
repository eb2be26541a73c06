"""Fall risk: the CoM (or the ZMP under a hand's force) against the support polygon, in the ground plane.

The public names of the fall model, gathered from the modules that define them:

- :mod:`executive.risk.fall_assessment`: :func:`assess_fall`, the ``fall`` RiskReport of a
  trajectory, and the seed's circle risk :func:`seed_fall_risk` (Long et al. 2018, "fall risk").
- :mod:`executive.risk.gaussian_polygon`: P(a Gaussian point is outside a convex polygon):
  :func:`edge_probabilities` (Boole bounds), :func:`probability_outside` (exact, Owen's T),
  :func:`probability_outside_mc`.
- :mod:`executive.risk.fall_bias`: :func:`persistent_bias_probability`, P(fall) over knots when
  the CoM error is one bias shared by every knot.
- :mod:`executive.risk.fall_support`: :func:`support_polygon`, the convex hull of the feet's
  ground contacts.
- :mod:`executive.risk.fall_balance`: what the stepping balance feedback leaves of the CoM bias at
  each knot of a walk (:func:`knot_gains`), and the walks of a plan (:func:`walk_phases`).
- :mod:`executive.risk.fall_capture`: :func:`capture_point` (Pratt et al. 2006; Koolen et al. 2012).
- :mod:`executive.risk.fall_force`: :class:`ExternalForce`, :func:`zero_moment_points`,
  :func:`force_scale_distribution`: a hand's push or press in the model.
- :mod:`executive.world.polygon`: the polygon geometry (:func:`convex_hull`, :func:`halfplanes`,
  :func:`signed_margin`, :func:`clip_polygon`, :func:`polygon_area`).

The batched per-knot forms: :mod:`executive.risk.fall_batch`. Design notes and measurements:
docs/risk_models.md.
"""

from __future__ import annotations

from executive.risk.fall_assessment import assess_fall, seed_fall_risk
from executive.risk.fall_bias import persistent_bias_probability
from executive.risk.fall_capture import capture_point
from executive.risk.fall_force import (
    SCALE_FLOOR,
    ExternalForce,
    force_scale_distribution,
    zero_moment_points,
)
from executive.risk.fall_support import support_polygon
from executive.risk.gaussian_polygon import edge_probabilities, probability_outside, probability_outside_mc
from executive.world.polygon import clip_polygon, convex_hull, halfplanes, polygon_area, signed_margin

__all__ = [
    "SCALE_FLOOR",
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
