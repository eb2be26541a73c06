"""The collision RiskReport of a trajectory: seed score, P(collision) with its bounds, severity.

:func:`assess_collision` profiles a trajectory with a :class:`CollisionModel` and reports it;
:func:`report_from_profile` reports any distance profile (one trajectory, or several steps
joined); :func:`breach_summary` reads the breach part back out of a report. The probability is
first order along coal's witness normals, over the union of all knots
(:func:`executive.risk.collision_probability.collision_probability`). Re-exported by
:mod:`executive.risk.collision`.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np

from executive.risk.collision_model import CollisionModel, CollisionProfile, TrajectoryLike
from executive.risk.collision_probability import collision_probability
from executive.risk.collision_seed import seed_collision_score
from executive.risk.collision_setup import Allow
from executive.risk.report import RiskReport

__all__ = ["assess_collision", "breach_summary", "report_from_profile"]


def assess_collision(
    model: CollisionModel,
    trajectory: TrajectoryLike,
    *,
    allow: Allow = (),
    broad_phase: bool = True,
) -> RiskReport:
    """Collision risk of ``trajectory``: seed score, first-order P(collision) and severity."""
    return report_from_profile(model, model.profile(trajectory, allow=allow, broad_phase=broad_phase))


def report_from_profile(model: CollisionModel, prof: CollisionProfile) -> RiskReport:
    """The collision RiskReport of a distance profile (one trajectory, or several steps joined).

    Severity = ``severity.collision`` x the body-part factor of the robot body in the
    closest approach (Long et al. 2018, conclusion: more sensitive parts such as cameras
    weigh more); with obstacles of their own severity, the collision severity is the mean of
    the bodies' severities weighted by their probabilities, so that the expected loss is
    ``P x factor x sum_b P_b s_b / sum_b P_b`` (each body's share linear in its severity).
    Probability: first order, union over all knots (see the module doc). With breach
    obstacles, ``details`` adds the probability of touching any of them and its expected loss.
    """
    config = model.risk_config
    distances = prof.distances
    seed = seed_collision_score(prof.times, prof.scaled_distances, config.d_safety, config.collision)
    prob = collision_probability(
        [k.near for k in prof.knots], model.setup.env_sigma, robot_sigma=model.carried_sigma
    )
    k_min = int(np.argmin(distances))
    closest = prof.knots[k_min]
    part, factor = model.body_part(closest.robot_geom)
    details: dict[str, float | str] = {
        "min_distance": float(closest.distance),
        "min_distance_time": float(prof.times[k_min]),
        "closest_robot_geom": closest.robot_geom_name,
        "closest_env_geom": closest.env_geom_name,
        "closest_robot_body": closest.robot_body_name,
        "closest_env_body": closest.env_body_name,
        "body_part": part,
        "body_part_factor": factor,
        "peak_term": seed.peak,
        "exposure_term": seed.exposure,
        "pairs_checked": float(prof.pairs_checked),
        "pairs_skipped": float(prof.pairs_skipped),
        "probability_method": "first-order union over knots (static Gaussian pose error per body, "
        "a carried object's own error included)",
    }
    severity = _weighted_severity(model, prob.per_body, model.setup.env_severity.keys())
    if model.setup.breach_bodies:
        details.update(_breach_details(model, prob.per_body, factor))
    return RiskReport(
        mode="collision",
        probability=prob.probability,
        probability_bounds=(prob.lower, prob.upper),
        severity=severity * factor,
        seed_score=seed.score,
        times=prof.times,
        traces={
            "distance": distances,
            "instantaneous_risk": prof.risks,
            "probability": prob.per_knot,
        },
        details=details,
    )


def _weighted_severity(
    model: CollisionModel, per_body: Mapping[int, float], bodies: Collection[int]
) -> float:
    """The collision severity: ``risk.severity.collision``, or with ``bodies`` (of their own
    severity) in the scene the bodies' severities weighted by their touch probabilities."""
    base = float(model.risk_config.severity.collision)
    total = sum(per_body.values())
    if not bodies or total <= 0.0:
        return base
    return sum(p * model.severity(b) for b, p in per_body.items()) / total


def _breach_details(
    model: CollisionModel, per_body: Mapping[int, float], factor: float
) -> dict[str, float | str]:
    """P(touching any breach obstacle) (independent bodies, as the union over bodies) and its
    expected loss: that probability x the breach bodies' probability-weighted severity x the
    body-part factor."""
    breach = {b: p for b, p in per_body.items() if b in model.setup.breach_bodies}
    miss = 1.0
    for p in breach.values():
        miss *= 1.0 - p
    total = sum(breach.values())
    mean = sum(p * model.severity(b) for b, p in breach.items()) / total if total > 0.0 else 0.0
    # the breach bodies with a probability above 0, most likely first
    touched = sorted(
        (b for b, p in breach.items() if p > 0.0), key=lambda b: (-breach[b], model.body_name(b))
    )
    names = [model.body_name(b) for b in touched]
    return {
        "breach_probability": 1.0 - miss,
        "breach_expected_loss": (1.0 - miss) * mean * factor,
        "breach_bodies": ", ".join(names),
    }


def breach_summary(report: RiskReport) -> dict[str, float | str] | None:
    """The breach part of a collision report, for tables and logs: ``{"probability",
    "expected_loss", "bodies"}`` (the breach bodies of a probability above 0, most likely
    first, comma-separated; empty if none); None when the scene has no breach obstacle."""
    details = report.details
    if "breach_probability" not in details:
        return None
    return {
        "probability": float(details["breach_probability"]),
        "expected_loss": float(details["breach_expected_loss"]),
        "bodies": str(details["breach_bodies"]),
    }
