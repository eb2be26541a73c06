"""Hold risk: will a grip keep a carried object, given its mass and friction?

Per hand and per knot of the planned trajectories while that hand holds the object, the grip
slips when its pads' friction (an ellipsoidal limit surface over the contact patch) no longer
covers the object's weight and the plan's accelerations; at a handover, the receiver misses
when the object has turned and sagged in the giver's hand as far as the receiver's pads reach
on it. Each failure grows with the mass, so each has one critical mass; :func:`hold_probability`
integrates P(mass >= critical mass) over the truth sampler's errors. The model and its
references are in docs/hold_and_grasp.md.

The parts: contact parameters (:mod:`executive.risk.hold_contact`), the grip
(:mod:`executive.risk.hold_grip`), the contact patch and creep (:mod:`executive.risk.hold_patch`),
who holds the object when (:mod:`executive.risk.hold_carry`); this module keeps their names
importable.

Usage::

    report = assess_hold(world, plan, risk_config, uncertainty)
    report.probability, report.details["hold_critical_mass_kg"]
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from executive.risk.gaussian import gauss_hermite_normal
from executive.risk.hold_carry import (
    GRAVITY,
    CarrySpan,
    HoldProblem,
    ReceiverMiss,
    hold_problem,
    object_pose_at,
    servo_sag,
)
from executive.risk.hold_contact import ContactParameters, contact_impedance, contact_parameters, impedance
from executive.risk.hold_grip import Grip, HoldModelUnavailable, grip
from executive.risk.hold_patch import Patch, creep_compliance, hold_capacity, patch
from executive.risk.model_geometry import site_pose_at
from executive.risk.report import RiskReport
from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World

__all__ = [
    "GRAVITY",
    "CarrySpan",
    "ContactParameters",
    "Grip",
    "HoldModelUnavailable",
    "HoldProblem",
    "Patch",
    "ReceiverMiss",
    "assess_hold",
    "contact_impedance",
    "contact_parameters",
    "creep_compliance",
    "creep_tilt_per_kg",
    "critical_mass",
    "grip",
    "hold_capacity",
    "hold_probability",
    "hold_problem",
    "impedance",
    "object_pose_at",
    "patch",
    "servo_sag",
    "site_pose_at",
    "slip_critical_mass",
    "squaring_turn",
]

FloatArray = NDArray[np.float64]
#: The truth sampler's floor on its mass and friction factors (executive.world.model.sample_perturbation).
SCALE_FLOOR = 0.2


# --- critical masses -----------------------------------------------------------------------


def _span_moments(
    span: CarrySpan, g: Grip, offsets: FloatArray, z_shift: FloatArray | None = None
) -> tuple[Patch, FloatArray, FloatArray, FloatArray]:
    """Per offset: the patch, and per knot the tangential force and grip moment per kg, dt.

    z_shift: (n,) how much farther along the approach the object sits in the hand than planned.
    """
    force, dt = span.grip_forces()
    centres = np.tile(span.grasp_centre[[0, 2]], (len(offsets), 1))
    centres[:, 0] += offsets
    if z_shift is not None:
        centres[:, 1] += z_shift
    p = patch(g, centres, span.object_half)
    lever = centres - p.centre  # (n, 2): COM minus patch centre, site x and z
    tangential = np.hypot(force[:, 0], force[:, 2])
    moment = lever[:, 1:2] * force[None, :, 0] - lever[:, 0:1] * force[None, :, 2]  # (r x F)_y
    return p, tangential, moment, dt


def slip_critical_mass(
    span: CarrySpan, g: Grip, offsets: FloatArray, mu: float, z_shift: FloatArray | None = None
) -> FloatArray:
    """The smallest mass (kg) that slips somewhere on ``span``, per lateral offset (inf: none).

    Ellipsoidal limit surface per knot (Howe & Cutkosky 1996): the load per kg (f_t, tau) slips
    a mass m when m^2 ((f_t / f_max)^2 + (tau / tau_max)^2) > 1; 0 where the pads miss.
    z_shift: see :func:`_span_moments` (a handed-over object the receiver took lower).
    """
    p, tangential, moment, _ = _span_moments(span, g, offsets, z_shift)
    alone = np.asarray(span.alone, dtype=bool)
    f_max, tau_max = hold_capacity(g, p, mu)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (tangential[None, :] / f_max[:, None]) ** 2 + (moment / tau_max[:, None]) ** 2
    ratio = np.where(alone[None, :], ratio, 0.0)
    worst = ratio.max(axis=1) if ratio.shape[1] else np.zeros(len(offsets))
    with np.errstate(divide="ignore"):
        out = np.where(worst > 0.0, 1.0 / np.sqrt(worst), np.inf)
    return np.asarray(np.where(p.touches, out, 0.0), dtype=float)


def creep_tilt_per_kg(
    miss: ReceiverMiss, g: Grip, offsets: FloatArray, mu: float
) -> tuple[FloatArray, FloatArray]:
    """Per offset: the giver's creep turn about its closing axis per kg (rad/kg), and the
    weight's moment about that axis per kg at the handover (N m/kg)."""
    p, _, moment, dt = _span_moments(miss.giver, g, offsets)
    compliance = creep_compliance(g, p, mu)
    tilt = -compliance * (moment @ dt)  # the load moment is -(grip moment)
    return np.asarray(tilt, dtype=float), np.asarray(np.abs(moment[:, -1]), dtype=float)


def squaring_turn(
    g: Grip, half_height: float, moment_per_kg: FloatArray, mass: FloatArray, yaw: FloatArray
) -> FloatArray:
    """Turn (rad) about the closing axis while a lifted object's yaw error is squared in the jaws.

    Jaws closed on an object resting on the table leave its yaw error (the table holds it);
    lifted, the jaws' couple squares it, its faces sliding along the pads by |yaw| w/2 on the
    two edge contacts of each pad (normal force F/2 each). While they slide, the weight's moment
    M about the closing axis is taken by the contacts' friction, which opposes the generalised
    slip on MuJoCo's elliptic cone (f_j proportional to mu_j^2 v_j): linearised about the squaring
    slide, the spin omega gives 4 (F/2) mu_t^2 cos(a) omega / (mu v) of moment, sin(a) = m g /
    (4 mu F/2) the share of the cone the weight takes. So the turn per yaw is w/2 M mu /
    (4 (F/2) mu_t^2 cos a), at most w / (2 h_z), where the contacts above and below the patch
    centre slide apart (kinematic bound; the only way without torsional friction).

    Args:
        g: the giver's grip; half_height: the patch's half height h_z (m).
        moment_per_kg: |M| / m per row (N m / kg); mass: kg per row; yaw: rad per row.

    Returns:
        The turn per row (rad, >= 0).
    """
    bound = g.half_width / half_height if half_height > 0.0 else 0.0
    normal, mu, mu_t = g.force / 2.0, g.contact.mu, g.contact.mu_torsion
    sin_a = np.clip(np.asarray(mass) * 9.81 / (4.0 * mu * normal), 0.0, 1.0) if normal > 0 else np.ones(1)
    cos_a = np.sqrt(1.0 - sin_a**2)
    if mu_t <= 0.0:
        return np.asarray(np.abs(yaw) * bound, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        linear = g.half_width * np.asarray(mass) * moment_per_kg * mu / (4.0 * normal * mu_t**2 * cos_a)
    rate = np.where(cos_a > 0.0, np.minimum(bound, linear), bound)
    return np.asarray(np.abs(yaw) * rate, dtype=float)


def receiver_critical_mass(
    miss: ReceiverMiss,
    g: Grip,
    offsets: FloatArray,
    mu: float,
    mass_cap: float,
    yaw: FloatArray | None = None,
) -> FloatArray:
    """The smallest mass at which the handover fails, per offset (inf: none).

    The giver's object turns about the closing axis by its creep (growing with m) and while
    a yaw error is squared out of its jaws (:func:`squaring_turn`). The face under the
    receiver moves by that turn (Rodrigues) plus the giving arm's sag (growing with m); the
    receiver misses when that motion along its approach
    reaches the pads' planned depth, and it loses the object later when its shallower patch
    slips on its own carry (:func:`slip_critical_mass` with the object that much lower). Solved
    by bisection on m in [0, mass_cap] (the turn is kept below a quarter turn, where the drop
    grows with it).
    """
    tilt, moment = creep_tilt_per_kg(miss, g, offsets, mu)
    yaws = np.zeros(len(offsets)) if yaw is None else np.asarray(yaw, dtype=float)
    sign = np.sign(tilt)
    rc = np.tile(miss.receiver_centre, (len(offsets), 1))
    rc[:, 0] += offsets * miss.lateral_shift
    lands = patch(miss.receiver, rc, miss.receiver_half).touches

    def drop(m: FloatArray) -> FloatArray:
        theta = m * tilt + sign * squaring_turn(g, miss.patch_half_height, moment, m, yaws)
        move = (
            np.sin(theta)[:, None] * miss.lever_cross
            + (1.0 - np.cos(theta))[:, None] * miss.lever_cross2
            + m[:, None] * miss.sag
        )
        return np.asarray(move @ miss.approach, dtype=float)

    room = np.maximum(0.5 * np.pi - np.abs(yaws) * miss.squaring, 0.0)
    turning = tilt != 0.0  # divided only where the object turns: no 0/0 where it does not
    hi = np.minimum(mass_cap, np.divide(room, np.abs(tilt), out=np.full_like(room, mass_cap), where=turning))
    lo = np.zeros(len(offsets))
    rec = miss.receiver_span
    rec_offsets = offsets * miss.lateral_shift

    def fails(m: FloatArray) -> NDArray[np.bool_]:
        sink = drop(m)
        out = sink >= miss.depth
        if rec is not None:
            out |= m >= slip_critical_mass(rec, miss.receiver, rec_offsets, mu, np.maximum(sink, 0.0))
        return np.asarray(out)

    reached = fails(hi)
    for _ in range(32):  # mass_cap / 2^32: far below any mass that matters
        mid = 0.5 * (lo + hi)
        over = fails(mid)
        hi = np.where(over, mid, hi)
        lo = np.where(over, lo, mid)
    out = np.where(reached, hi, np.inf)
    if miss.depth <= 0.0:
        out = np.zeros(len(offsets))
    return np.asarray(np.where(lands, out, 0.0), dtype=float)


def critical_mass(
    world: World,
    problem: HoldProblem,
    offsets: FloatArray,
    friction_scale: float = 1.0,
    yaw: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Per lateral offset (and yaw error, rad, same length): the smallest failing mass, its cause.

    Returns:
        (masses (n,), causes (n,) as 0 = a hand slips, 1 = a handover fails).
    """
    geom = world.ids.object_geoms[problem.obj]
    slip = np.full(len(offsets), np.inf)
    for span, g in problem.spans:
        mu = contact_parameters(world.model, g.pads[0], geom, friction_scale).mu
        slip = np.minimum(slip, slip_critical_mass(span, g, offsets, mu))
    miss = np.full(len(offsets), np.inf)
    for m in problem.misses:
        g = next(gr for sp, gr in problem.spans if sp is m.giver)
        mu = contact_parameters(world.model, g.pads[0], geom, friction_scale).mu
        miss = np.minimum(miss, receiver_critical_mass(m, g, offsets, mu, 20.0 * problem.mass, yaw))
    return np.minimum(slip, miss), (miss < slip).astype(float)


# --- the probability and the report ------------------------------------------------------


def exceed_mass_probability(critical: FloatArray, mass: float, sigma: float) -> FloatArray:
    """P(m >= critical) for m = mass max(0.2, 1 + sigma z), z ~ N(0, 1) (the truth sampler's law)."""
    ratio = np.asarray(critical, dtype=float) / mass
    if sigma <= 0.0:
        return np.asarray(ratio <= 1.0, dtype=float)
    with np.errstate(invalid="ignore"):
        p = ndtr(-(ratio - 1.0) / sigma)
    return np.asarray(np.where(ratio <= SCALE_FLOOR, 1.0, np.where(np.isinf(ratio), 0.0, p)), dtype=float)


def hold_probability(
    world: World, problem: HoldProblem, uncertainty: Uncertainty, order: int = 16
) -> tuple[float, float]:
    """P(hold failure) over mass, friction and lateral offset, and the receiver-miss share of it.

    Gauss-Hermite over the lateral offset (``order`` nodes; one when its sigma is 0), the yaw
    error (when a handover turns on it) and the friction factor (when the object's friction
    reaches the contacts), closed form in the mass.
    """
    if uncertainty.object_position > 0.0:
        z, we = gauss_hermite_normal(order)
        offsets = uncertainty.object_position * z
    else:
        offsets, we = np.zeros(1), np.ones(1)
    blind = all(g.pad_friction_wins for _, g in problem.spans)
    if uncertainty.friction > 0.0 and not blind:
        zf, wf = gauss_hermite_normal(max(4, order // 2))
        scales = np.maximum(SCALE_FLOOR, 1.0 + uncertainty.friction * zf)
    else:
        scales, wf = np.ones(1), np.ones(1)
    if uncertainty.object_yaw_rad > 0.0 and problem.misses:
        zy, wy = gauss_hermite_normal(max(4, order // 2))
        yaws = uncertainty.object_yaw_rad * zy
    else:
        yaws, wy = np.zeros(1), np.ones(1)
    rows_e, rows_y = np.repeat(offsets, len(yaws)), np.tile(yaws, len(offsets))
    weights = np.repeat(we, len(yaws)) * np.tile(wy, len(offsets))
    total, missed = 0.0, 0.0
    for s, w in zip(scales, wf, strict=True):
        crit, cause = critical_mass(world, problem, rows_e, float(s), rows_y)
        p = exceed_mass_probability(crit, problem.mass, uncertainty.object_mass)
        total += float(w * (weights @ p))
        missed += float(w * (weights @ (p * cause)))
    return float(np.clip(total, 0.0, 1.0)), float(np.clip(missed, 0.0, 1.0))


def _nominal_facts(world: World, problem: HoldProblem) -> dict[str, float | str]:
    """Scalar facts of the nominal truth (no offset, no yaw error, nominal friction) for the report."""
    zero = np.zeros(1)
    facts: dict[str, float | str] = {"hold_mass_kg": problem.mass}
    crit, cause = critical_mass(world, problem, zero, 1.0, zero)
    facts["hold_critical_mass_kg"] = float(crit[0])
    facts["hold_critical_cause"] = "handover" if cause[0] else "slip"
    if problem.spans:
        g = problem.spans[0][1]
        facts["hold_grip_force_n"] = g.force
        facts["hold_contact_mu"] = g.contact.mu
    for miss in problem.misses:
        g = next(gr for sp, gr in problem.spans if sp is miss.giver)
        tilt, moment = creep_tilt_per_kg(miss, g, zero, g.contact.mu)
        facts["handover_creep_tilt_deg"] = float(np.degrees(tilt[0] * problem.mass))
        mass = np.full(1, problem.mass)
        turn = squaring_turn(g, miss.patch_half_height, moment, mass, np.ones(1))
        facts["handover_squaring_tilt_per_yaw"] = float(turn[0])
        facts["handover_sag_m"] = float(problem.mass * (miss.sag @ miss.approach))
        facts["handover_receiver_depth_m"] = miss.depth
    return facts


def assess_hold(world: World, plan: object, risk_config: RiskConfig, uncertainty: Uncertainty) -> RiskReport:
    """Hold risk of a planned alternative: a hand's grip slips, or a handover's receiver misses.

    Args:
        world: the estimate world the plan was made on (its object mass is the estimate).
        plan: an :class:`executive.planning.plan.AlternativePlan`.
        risk_config: the scenario's risk settings (severity of a drop).
        uncertainty: the scenario's 1-sigma errors (object_mass, friction, object_position).

    Returns:
        A report of mode "hold": probability, Fréchet bounds of its two causes, and details
        (critical mass, grip force, contact friction, handover tilt and sag, the cause). A hand
        the model does not cover gives probability 0 with bounds (0, 1) and the reason in
        ``details["hold_model"]``.
    """
    severity = risk_config.severity.drop
    if not getattr(getattr(plan, "task", None), "object", ""):  # a task that holds nothing (a press)
        return RiskReport("drop", 0.0, (0.0, 0.0), severity, 0.0, details={"hold_model": "nothing held"})
    try:
        problem = hold_problem(world, plan)
    except HoldModelUnavailable as exc:
        details: dict[str, float | str] = {"hold_model": f"unavailable: {exc}"}
        return RiskReport("drop", 0.0, (0.0, 1.0), severity, 0.0, details=details)
    p, missed = hold_probability(world, problem, uncertainty)
    slides = all(
        world.model.jnt_type[int(world.model.actuator_trnid[a, 0])] == mujoco.mjtJoint.mjJNT_SLIDE
        for acts in world.ids.gripper_actuators.values()
        for a in acts
    )
    details = {
        "hold_model": "parallel jaw" if slides else "thumb against fingers",
        **_nominal_facts(world, problem),
    }
    details["hold_probability"] = p
    details["hold_receiver_miss_probability"] = missed
    return RiskReport("drop", p, (p, p), severity, p, details=details)
