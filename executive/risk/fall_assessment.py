"""The fall risk of a trajectory: the support point against the support polygon, and the posture.

:func:`assess_fall` builds the ``fall`` RiskReport: per knot the signed margin of the support
point (the CoM, or the ZMP under a hand's force), the seed's circle risk, the exact and Boole
probabilities that the true support point is outside, the capture point's margin; over the
trajectory the persistent-bias probability (:mod:`executive.risk.fall_bias`) combined with the
posture's part. Re-exported by :mod:`executive.risk.fall`.

Sources (one line each):
- Seed (Long et al. 2018, "fall risk"): an uncertainty circle of radius r around the estimated
  CoM; "risk grows as the circle leaves the polygon (m - r)". Here: risk = ((r - m) / (2 r))^b
  for m < r, else 0, clipped to [0, 1] (0 when the circle just touches the edge, 1 once it is
  entirely outside, m = -r); b = FallRiskConfig.exponent.
- Posture: the pelvis, planned at its lowest height z_min, ends e_z ~ N(0, sigma^2) off it, and
  the fall detector calls a pelvis below the safe posture's floor a fall: P_pelvis =
  Phi((floor - z_min) / sigma); a planned torso tilt beyond ``SafePosture.fall_tilt_deg`` is a
  fall for sure. The failures are independent: P(fall) = 1 - (1 - P_support)(1 - P_pelvis)(1 -
  P_tilt), and the same for both bounds.
- Walks: the polygon is the feet's on the floor (the stance sole's on one foot). A walk runs with
  the balance feedback, which takes most of the CoM bias out before a foot lifts: each knot of a
  walk weighs the bias by its gain (:func:`executive.risk.fall_balance.knot_gains`; the
  probabilities taken in the polygons shrunk by it, :func:`executive.risk.fall_balance.shrink_polygons`,
  the margins in the polygons as they are), and a walk that carries an object counts its mass in
  the CoM (docs/stepping.md, "Falls").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from executive.planning.timing import Trajectory
from executive.risk.fall_balance import BalancedPhase, carried_bodies, knot_gains, shrink_polygons
from executive.risk.fall_batch import (
    KnotPolygons,
    edge_probabilities_batch,
    probability_outside_batch,
    signed_margin_batch,
)
from executive.risk.fall_capture import capture_points
from executive.risk.fall_force import ExternalForce, support_points, under_force
from executive.risk.fall_support import FallKnots, fall_knots
from executive.risk.gaussian import independent_union, normal_cdf
from executive.risk.gaussian_polygon import check_covariance
from executive.risk.report import RiskReport
from executive.robot.posture import standing_pelvis_height
from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World
from executive.world.polygon import polygon_area

__all__ = ["assess_fall", "seed_fall_risk"]

FloatArray = NDArray[np.float64]


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


def _per_knot(
    polygons: KnotPolygons, scored: KnotPolygons, mus: FloatArray, xi: FloatArray, cov: FloatArray
) -> dict[str, FloatArray]:
    """Per knot: signed margin of ``mus``, capture margin of ``xi`` (in ``polygons``), exact and
    Boole P(outside) (in ``scored``: the polygons shrunk by the walk's gain on the bias)."""
    count = len(mus)
    out = {name: np.zeros(count) for name in ("margin", "capture", "probability", "lower", "upper")}
    for size, (knots, verts) in polygons.groups.items():
        mu = mus[knots]
        out["margin"][knots] = signed_margin_batch(verts, mu)
        out["capture"][knots] = signed_margin_batch(verts, xi[knots])
        verts = scored.groups[size][1]
        p = edge_probabilities_batch(verts, mu, cov)
        out["lower"][knots] = np.max(p, axis=1)
        out["upper"][knots] = np.minimum(1.0, np.sum(p, axis=1))
        out["probability"][knots] = probability_outside_batch(verts, mu, cov)
    return out


def _with_posture(p: float, posture: dict[str, float]) -> float:
    """1 - (1 - p)(1 - P_pelvis)(1 - P_tilt): the support's and the posture's independent failures."""
    return independent_union([p, posture["probability_pelvis"], posture["probability_tilt"]])


def assess_fall(
    world: World,
    trajectory: Trajectory,
    risk_config: RiskConfig,
    uncertainty: Uncertainty,
    external: ExternalForce | None = None,
    walks: Sequence[BalancedPhase] = (),
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
            (:func:`executive.risk.fall_force.zero_moment_points`) instead of the CoM, and the
            probability is averaged over the force's uncertain scale
            (:func:`executive.risk.fall_force.force_scale_distribution`).
        walks: the phases of the trajectory's walks (:func:`executive.risk.fall_balance.walk_phases`):
            where the balance feedback runs, and what a hand carries through them.

    Returns:
        The ``fall`` report; its details name the minimum margin, the posture's part and, with a
        force, the largest force and ZMP shift.

    Raises:
        ValueError: a trajectory whose qpos do not fit the model, or a CoM not above the ground.
    """
    cfg = risk_config.fall
    radius = cfg.circle_radius if cfg.circle_radius is not None else cfg.sigmas * uncertainty.com
    cov = check_covariance((uncertainty.com**2) * np.eye(2))
    times = np.asarray(trajectory.times, dtype=float)
    knots = fall_knots(world, trajectory, carried_bodies(times, walks) if walks else None)
    xi = capture_points(knots.coms, knots.times, knots.gravity, knots.ground)
    mus = support_points(knots, external)  # the traces at the mean felt force
    gains = knot_gains(world, knots, walks)
    scored = (
        dataclasses.replace(knots, polygons=shrink_polygons(knots.polygons, knots.coms[:, :2], gains))
        if np.any(gains != 1.0)
        else knots
    )
    per = _per_knot(knots.polygons, scored.polygons, mus, xi, cov)
    (probability, lower, upper), force_facts = under_force(scored, external, cov)
    if np.any(gains != 1.0):
        force_facts["max_walk_gain"] = float(np.max(gains))
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
    knots: FallKnots,
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
