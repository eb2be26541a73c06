"""Hold risk: will a parallel-jaw grip keep a carried object, given its mass and friction?

A grip holds while the friction its pads supply covers the object's weight and the plan's
accelerations, and while the object does not turn in the jaws far enough to be lost. The
model, per hand and per knot of the planned trajectories while that hand holds the object:

* Grip force: the jaw servo's force on the object, min(kp |q_contact - q_closed|,
  forcerange) per finger (a position servo closing on an object it cannot reach). A hand of
  hinged fingers against a thumb (the G1's Dex3) gives its chains' squeeze instead
  (:func:`executive.risk.hand_grip.dexterous_squeeze`), its pads their contact geoms.
* Contact friction as MuJoCo mixes it (MuJoCo docs, "Contact parameters"): the geom of higher
  ``priority`` gives its parameters; equal priorities take the element-wise maximum friction
  and the solmix-weighted solref/solimp. The truth's friction factor scales the object's
  friction only, so a pad of higher priority makes the grip blind to it.
* Contact patch: the overlap of each pad's face with the object's section across the jaws;
  MuJoCo's box-box collision puts one contact at each corner of the overlap (4 per pad), each
  carrying a quarter of the pad's normal force.
* Slip (Coulomb friction with the ellipsoidal limit surface of a planar patch, Howe &
  Cutkosky 1996, "Practical force-motion models for sliding manipulation"):
  (f_t / f_max)^2 + (tau / tau_max)^2 > 1, with f_t the load across the jaws' normal,
  m |a - g| projected on the pad plane, tau its moment about the closing axis through the
  patch centre, f_max = mu sum f_n and tau_max = sum f_n,i (mu r_i + mu_torsion) (MuJoCo's
  condim 4 elliptic cone adds the torsional coefficient mu_torsion, a length).
* Creep (MuJoCo's soft constraints, docs "Computation / Soft constraints"): inside the cone a
  frictional constraint still slides at v = R f / b, R = (1 - d)/d A_ii / impratio per
  friction row (elliptic cones; torsional rows R mu^2 / mu_torsion^2), b = 2 / (dmax
  timeconst), A_ii MuJoCo's diagonal approximation body_invweight0 of the two bodies and d the
  solimp impedance at the contact's resting penetration. Under a moment tau the object turns
  about the closing axis at omega = tau / (b sum_i (r_i^2 / R_t + 1 / R_tor)).
* Squaring (:func:`squaring_turn`): jaws closed on an object resting on the table leave its yaw
  error; lifted, the jaws square it, and while its faces slide along the pads the weight's
  moment turns it about the closing axis (elliptic-cone friction linearised about the slide,
  capped by the edge contacts' kinematic bound w / (2 h_z) per radian of yaw).
* Handover: the turns accumulated while the giver holds the object alone, and the giving
  arm's servo sag and turn under the object's weight, dx = J Kp^-1 J^T m g (servos without
  feed-forward of the object's weight), lower the face where the receiver closes its jaws:
  the receiver misses when that drop reaches the planned depth of its pads on the object, or
  when its pads do not overlap the object along the jaws, and loses it later when its
  shallower patch slips on its own carry.

Uncertainty, as :func:`executive.world.model.sample_perturbation` draws the truth: mass m = m0
max(0.2, 1 + s_m z), the object's friction mu0 max(0.2, 1 + s_f z'), the object's position
error e ~ N(0, s_p^2) along the grip's lateral axis (it moves the grasp point on the object)
and its yaw error ~ N(0, s_yaw^2). Every failure above grows with m at fixed (e, yaw, mu), so
each has one critical mass m_c (the smallest over hands, knots and handovers: the union of
the failures is exact), and P = E_{e, yaw, mu}[P(m >= m_c)], closed form in m, Gauss-Hermite
quadrature over the others. Neglected: the object's rotational inertia, the creep's
dependence on the truth mass through A_ii, moments about the axes across the jaws (taken by
the pads' pressure), and how the turn changes the load's lever while it grows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from executive.errors import ExecutiveError
from executive.planning.timing import Trajectory
from executive.risk.gaussian import gauss_hermite_normal
from executive.risk.grasp import half_extent
from executive.risk.hand_grip import dexterous_squeeze
from executive.risk.hand_span import posed_hand
from executive.risk.report import RiskReport
from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World

__all__ = [
    "CarrySpan",
    "ContactParameters",
    "Grip",
    "HoldModelUnavailable",
    "HoldProblem",
    "Patch",
    "ReceiverMiss",
    "assess_hold",
    "contact_parameters",
    "creep_compliance",
    "creep_tilt_per_kg",
    "critical_mass",
    "grip",
    "hold_capacity",
    "hold_probability",
    "object_pose_at",
    "patch",
    "servo_sag",
    "site_pose_at",
    "slip_critical_mass",
    "squaring_turn",
]

FloatArray = NDArray[np.float64]
GRAVITY = np.array([0.0, 0.0, -9.81])
#: The truth sampler's floor on its mass and friction factors (executive.world.model.sample_perturbation).
SCALE_FLOOR = 0.2


class HoldModelUnavailable(ExecutiveError):
    """The hold model cannot describe this hand (e.g. no parallel jaws on slide joints)."""


# --- contact parameters as MuJoCo mixes them -----------------------------------------------


@dataclass(frozen=True)
class ContactParameters:
    """Parameters of one geom pair's contacts: mu (sliding), mu_torsion (m), timeconst, dmax."""

    mu: float
    mu_torsion: float
    condim: int
    timeconst: float
    dampratio: float
    dmax: float
    solimp: tuple[float, ...] = (0.9, 0.95, 0.001, 0.5, 2.0)


def contact_parameters(
    model: mujoco.MjModel, geom_a: int, geom_b: int, friction_scale_b: float = 1.0
) -> ContactParameters:
    """The parameters MuJoCo gives contacts between two geoms (MuJoCo docs, "Contact parameters").

    Args:
        model: the compiled model.
        geom_a: a geom id (e.g. a pad).
        geom_b: a geom id (e.g. the object); its friction is scaled by ``friction_scale_b``
            (how a truth world scales the object's friction).
        friction_scale_b: factor on geom_b's friction.

    Returns:
        The mixed parameters; timeconst is clamped to 2 timesteps as MuJoCo's refsafe does.
    """
    fa = np.array(model.geom_friction[geom_a], dtype=float)
    fb = np.array(model.geom_friction[geom_b], dtype=float) * friction_scale_b
    pa, pb = int(model.geom_priority[geom_a]), int(model.geom_priority[geom_b])
    if pa != pb:
        win = geom_a if pa > pb else geom_b
        friction = fa if pa > pb else fb
        condim = int(model.geom_condim[win])
        solref = np.array(model.geom_solref[win], dtype=float)
        solimp = np.array(model.geom_solimp[win], dtype=float)
    else:
        friction = np.maximum(fa, fb)
        condim = max(int(model.geom_condim[geom_a]), int(model.geom_condim[geom_b]))
        ma, mb = float(model.geom_solmix[geom_a]), float(model.geom_solmix[geom_b])
        w = 0.5 if ma + mb <= 0.0 else ma / (ma + mb)
        solref = w * model.geom_solref[geom_a] + (1.0 - w) * model.geom_solref[geom_b]
        solimp = w * model.geom_solimp[geom_a] + (1.0 - w) * model.geom_solimp[geom_b]
    timeconst = max(float(solref[0]), 2.0 * float(model.opt.timestep)) if solref[0] > 0 else 0.0
    return ContactParameters(
        mu=float(friction[0]),
        mu_torsion=float(friction[1]) if condim >= 4 else 0.0,
        condim=condim,
        timeconst=timeconst,
        dampratio=float(solref[1]),
        dmax=float(solimp[1]),
        solimp=tuple(float(v) for v in solimp),
    )


def impedance(solimp: tuple[float, ...], penetration: float) -> float:
    """MuJoCo's constraint impedance d(r) (docs, "Solver parameters"): dmin..dmax over the width."""
    dmin, dmax, width, mid, power = solimp
    x = min(1.0, abs(penetration) / width) if width > 0 else 1.0
    if power == 1.0 or x >= 1.0:
        y = x
    elif x <= mid:
        y = x**power / mid ** (power - 1.0)
    else:
        y = 1.0 - (1.0 - x) ** power / (1.0 - mid) ** (power - 1.0)
    return float(np.clip(dmin + y * (dmax - dmin), 1e-4, 0.9999))


def contact_impedance(c: ContactParameters, inv_weight: float, normal_force: float) -> tuple[float, float]:
    """The impedance d and penetration r (m) of a resting contact carrying ``normal_force`` (N).

    At rest MuJoCo's soft normal constraint balances f = k d r / R with k = 1 / (dmax tc dr)^2 and
    R = (1 - d)/d A: f = d(r)^2 r / ((1 - d(r)) A (dmax tc dr)^2), solved for the penetration r
    by bisection (f grows with r).
    """
    if c.timeconst <= 0.0:
        return c.dmax, 0.0
    scale = inv_weight * (c.dmax * c.timeconst * c.dampratio) ** 2

    def force(r: float) -> float:
        d = impedance(c.solimp, r)
        return d * d * r / ((1.0 - d) * scale)

    lo, hi = 0.0, max(c.solimp[2], 1e-6)
    while force(hi) < normal_force and hi < 1.0:
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if force(mid) < normal_force else (lo, mid)
    r = 0.5 * (lo + hi)
    return impedance(c.solimp, r), r


# --- the gripper ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Grip:
    """One hand's parallel jaw closed on an object.

    force: N, normal force of each pad on the object; pads: the pad geom ids; pad_centre /
    pad_half: each pad's centre and half extents along the hand site's x (lateral) and z
    (approach) axes, in the site frame (m); contact: the pad-object contact parameters at
    nominal friction; inv_weight: MuJoCo's body_invweight0 (translation) of pad body + object.
    """

    side: str
    force: float
    pads: tuple[int, ...]
    pad_centre: FloatArray  # (2,) x z
    pad_half: FloatArray  # (2,) x z
    contact: ContactParameters
    inv_weight: float
    impratio: float
    half_width: float  # m, the object's half width across the jaws
    pad_friction_wins: bool  # the pad's priority is higher: the object's friction never counts


def _pad_geom(model: mujoco.MjModel, body: int) -> int:
    """The collidable geom of a finger body with the highest priority (then condim): its pad."""
    geoms = [
        g
        for g in range(model.ngeom)
        if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]
    if not geoms:
        raise HoldModelUnavailable(f"finger body {body} has no collidable geom")
    return max(geoms, key=lambda g: (int(model.geom_priority[g]), int(model.geom_condim[g]), -g))


def _servo_force(model: mujoco.MjModel, actuator: int, q_contact: float, q_closed: float) -> float:
    """Force of a position servo holding at q_contact while told q_closed: kp |error|, clipped."""
    kp = float(model.actuator_gainprm[actuator, 0])
    force = kp * abs(q_contact - q_closed)
    if model.actuator_forcelimited[actuator]:
        force = min(force, float(np.max(np.abs(model.actuator_forcerange[actuator]))))
    return force


def _geom_half_extent(model: mujoco.MjModel, geom: int, axis_body: FloatArray) -> float:
    """Half the extent of a geom along a unit axis of its body's frame."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[geom])
    return half_extent(model, geom, rot.reshape(3, 3).T @ axis_body)


def grip(world: World, side: str, obj: str, closing_axis_object: FloatArray) -> Grip:
    """The ``side`` hand's jaw closed on ``obj`` across ``closing_axis_object`` (object frame).

    Args:
        world: the estimate world (its data places the pads in the hand; any pose will do).
        side: an arm of the profile.
        obj: an object of the scene.
        closing_axis_object: unit vector, the jaws' closing axis in the object's body frame.

    Returns:
        The :class:`Grip`.

    Raises:
        HoldModelUnavailable: the gripper's actuators are not position servos on joints, or a
            hand without slide jaws has no thumb opposing its fingers, so no grip force can be
            read off the model.

    A hand whose servos drive hinge joints (the G1's Dex3) is a thumb against fingers: its
    force is their squeeze at the closed targets (:func:`executive.risk.hand_grip.dexterous_squeeze`)
    and its pads the chains' contact geoms (:func:`_dexterous_grip`).
    """
    model, data = world.model, world.data
    acts = world.ids.gripper_actuators[side]
    joints = [int(model.actuator_trnid[a, 0]) for a in acts]
    if not acts or any(
        model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT
        or model.actuator_biastype[a] != mujoco.mjtBias.mjBIAS_AFFINE
        for a in acts
    ):
        raise HoldModelUnavailable(
            f"the {side} gripper's actuators are not position servos on joints; "
            "the hold model does not cover it"
        )
    if any(model.jnt_type[j] != mujoco.mjtJoint.mjJNT_SLIDE for j in joints):
        return _dexterous_grip(world, side, obj, np.asarray(closing_axis_object, dtype=float))
    geom = world.ids.object_geoms[obj]
    width = 2.0 * _geom_half_extent(model, geom, np.asarray(closing_axis_object, dtype=float))
    closed = world.profile.arms[side].gripper.closed
    force = min(_servo_force(model, a, width / 2.0, c) for a, c in zip(acts, closed, strict=True))
    pads = tuple(_pad_geom(model, int(model.jnt_bodyid[j])) for j in joints)
    site = world.ids.hand_sites[side]
    rot = data.site_xmat[site].reshape(3, 3)
    centres, halves = [], []
    for pad in pads:
        rel = rot.T @ data.geom_xmat[pad].reshape(3, 3)
        centres.append(rot.T @ (data.geom_xpos[pad] - data.site_xpos[site]))
        halves.append(np.abs(rel) @ model.geom_size[pad])
    centre, half = np.mean(centres, axis=0), np.min(halves, axis=0)
    body_pad, body_obj = int(model.geom_bodyid[pads[0]]), int(model.geom_bodyid[geom])
    pa, pb = int(model.geom_priority[pads[0]]), int(model.geom_priority[geom])
    wins = pa > pb
    return Grip(
        side=side,
        force=force,
        pads=pads,
        pad_centre=np.array([centre[0], centre[2]]),
        pad_half=np.array([half[0], half[2]]),
        contact=contact_parameters(model, pads[0], geom),
        inv_weight=float(model.body_invweight0[body_pad, 0] + model.body_invweight0[body_obj, 0]),
        impratio=float(model.opt.impratio),
        half_width=width / 2.0,
        pad_friction_wins=bool(wins),
    )


def _dexterous_grip(world: World, side: str, obj: str, closing_axis_object: FloatArray) -> Grip:
    """A thumb-against-fingers hand's :class:`Grip` on ``obj``: the squeeze of its chains.

    The pads are the chains' contact geoms at the closed targets; the patch the object's
    overlap with their contact points' spread across the site's x and z (each point widened
    by its geom's half extent along those axes, the thumb's and the fingers' the smaller).
    """
    model = world.model
    geom = world.ids.object_geoms[obj]
    width = 2.0 * _geom_half_extent(model, geom, closing_axis_object)
    try:
        squeeze = dexterous_squeeze(world, side, width)
    except ValueError as exc:
        raise HoldModelUnavailable(str(exc)) from exc
    data = posed_hand(world, side, tuple(world.profile.arms[side].gripper.closed))
    rot = data.site_xmat[world.ids.hand_sites[side]].reshape(3, 3)
    sides = []
    for thumb in (True, False):
        chains = [c for c in squeeze.chains if c.thumb == thumb]
        points = np.array([[c.point[0], c.point[2]] for c in chains])
        reach = np.array(
            [
                (np.abs(rot.T @ data.geom_xmat[c.geom].reshape(3, 3)) @ model.geom_aabb[c.geom, 3:])
                for c in chains
            ]
        )
        lo = np.min(points - reach[:, [0, 2]], axis=0)
        hi = np.max(points + reach[:, [0, 2]], axis=0)
        sides.append(((lo + hi) / 2.0, (hi - lo) / 2.0))
    pads = tuple(c.geom for c in squeeze.chains)
    body_pad, body_obj = int(model.geom_bodyid[pads[0]]), int(model.geom_bodyid[geom])
    return Grip(
        side=side,
        force=squeeze.force,
        pads=pads,
        pad_centre=np.mean([c for c, _ in sides], axis=0),
        pad_half=np.min([h for _, h in sides], axis=0),
        contact=contact_parameters(model, pads[0], geom),
        inv_weight=float(model.body_invweight0[body_pad, 0] + model.body_invweight0[body_obj, 0]),
        impratio=float(model.opt.impratio),
        half_width=width / 2.0,
        pad_friction_wins=bool(int(model.geom_priority[pads[0]]) > int(model.geom_priority[geom])),
    )


# --- contact patch, capacity and creep ------------------------------------------------------


@dataclass(frozen=True)
class Patch:
    """The pads' overlap with the object, per lateral offset: centre (x, z) and half sizes (m)."""

    centre: FloatArray  # (n, 2)
    half: FloatArray  # (n, 2), 0 where the pad misses the object

    @property
    def radius(self) -> FloatArray:
        """Distance of the patch's corner contacts from its centre."""
        return np.asarray(np.hypot(self.half[:, 0], self.half[:, 1]), dtype=float)

    @property
    def touches(self) -> NDArray[np.bool_]:
        return np.asarray((self.half > 0.0).all(axis=1))


def patch(g: Grip, object_centre: FloatArray, object_half: FloatArray) -> Patch:
    """Overlap of the pad face with the object's section, in the hand site's (x, z).

    Args:
        g: the grip.
        object_centre: (n, 2) the object's centre (x, z) in the site frame, one row per offset.
        object_half: (2,) the object's half extents along site x and z.

    Returns:
        The :class:`Patch` per row (an empty overlap has half sizes 0).
    """
    oc = np.atleast_2d(np.asarray(object_centre, dtype=float))
    lo = np.maximum(g.pad_centre - g.pad_half, oc - object_half)
    hi = np.minimum(g.pad_centre + g.pad_half, oc + object_half)
    half = np.clip((hi - lo) / 2.0, 0.0, None)
    return Patch(centre=(lo + hi) / 2.0, half=half)


def hold_capacity(g: Grip, p: Patch, mu: float | FloatArray) -> tuple[FloatArray, FloatArray]:
    """Largest force across the pad normal and moment about the closing axis the grip resists.

    f_max = mu 2F (two pads); tau_max = 2F (mu r + mu_torsion), r the corner contacts' radius
    (Coulomb friction per contact; MuJoCo's condim 4 torsional friction mu_torsion f_n).
    """
    total = 2.0 * g.force * p.touches
    f_max = np.asarray(mu, dtype=float) * total
    tau_max = total * (np.asarray(mu, dtype=float) * p.radius + g.contact.mu_torsion)
    return np.asarray(f_max, dtype=float), np.asarray(tau_max, dtype=float)


def creep_compliance(g: Grip, p: Patch, mu: float | None = None, per_pad: int = 4) -> FloatArray:
    """rad/s per N m: the soft-contact creep rate of the object's turn about the closing axis.

    omega = tau / (b sum_i (r_i^2 / R_t + 1 / R_tor)) over the 4 corner contacts of each pad, with
    MuJoCo's R_n = (1 - d)/d A_ii, R_t = R_n / impratio, R_tor = R_t (mu / mu_torsion)^2 and
    b = 2 / (dmax timeconst) (MuJoCo docs, "Soft constraints"); d is the impedance at the resting
    penetration of a corner contact carrying a quarter of the pad's force
    (:func:`contact_impedance`).
    """
    c = g.contact
    if c.timeconst <= 0.0 or not 0.0 < c.dmax < 1.0:
        return np.zeros(len(p.half))
    mu_s = c.mu if mu is None else mu
    d, _ = contact_impedance(c, g.inv_weight, g.force / per_pad)
    r_n = (1.0 - d) / d * g.inv_weight
    r_t = r_n / g.impratio
    b = 2.0 / (c.dmax * c.timeconst)
    stiff = p.radius**2 / r_t
    if c.mu_torsion > 0.0:
        stiff = stiff + 1.0 / (r_t * (mu_s / c.mu_torsion) ** 2)
    resist = b * 2.0 * per_pad * stiff  # per_pad corner contacts on each of the 2 pads
    out = np.where(p.touches & (resist > 0.0), 1.0 / np.where(resist > 0.0, resist, 1.0), 0.0)
    return np.asarray(out, dtype=float)


# --- the plan: who holds the object at which knot -----------------------------------------


@dataclass
class CarrySpan:
    """The knots at which one hand holds the object: times (s), object rotations and COM path.

    grasp_rotation / grasp_centre: the object's centre (COM) and rotation in the hand site
    frame at the grasp (fixed while held); object_half: its half extents along site x and z.
    alone: per knot, True when no other hand holds it.
    """

    side: str
    grasp_rotation: FloatArray  # (3, 3) object frame -> site frame
    grasp_centre: FloatArray  # (3,) object COM in the site frame
    object_half: FloatArray  # (2,) the object's half extents along site x and z
    times: list[float] = field(default_factory=list)
    rotations: list[FloatArray] = field(default_factory=list)  # object rotation per knot
    positions: list[FloatArray] = field(default_factory=list)  # object COM per knot
    alone: list[bool] = field(default_factory=list)
    _forces: tuple[FloatArray, FloatArray] | None = field(default=None, repr=False)

    def add(self, t: float, rotation: FloatArray, position: FloatArray, alone: bool) -> None:
        if self.times and t <= self.times[-1] + 1e-9:
            return
        self.times.append(t)
        self.rotations.append(rotation)
        self.positions.append(position)
        self.alone.append(alone)

    def grip_forces(self) -> tuple[FloatArray, FloatArray]:
        """Per knot, the grip force per unit mass a - g in the site frame (K, 3), and dt weights."""
        if self._forces is None or len(self._forces[0]) != len(self.times):
            self._forces = self._compute_forces()
        return self._forces

    def _compute_forces(self) -> tuple[FloatArray, FloatArray]:
        t = np.asarray(self.times)
        pos = np.asarray(self.positions).reshape(-1, 3)
        if len(t) >= 3:
            acc = np.gradient(np.gradient(pos, t, axis=0), t, axis=0)  # finite differences
        else:
            acc = np.zeros_like(pos)
        site_rot = np.asarray(self.rotations) @ self.grasp_rotation.T  # world <- site
        force = np.einsum("kji,kj->ki", site_rot, acc - GRAVITY)
        dt = np.gradient(t) if len(t) >= 2 else np.zeros_like(t)
        return force, dt


@dataclass
class ReceiverMiss:
    """A handover's receiver closing its jaws on the object the giver holds.

    giver: the giver's span up to the receiver's grasp (plus the jaws' closing time);
    depth: m the receiver's pads reach past the object's face along its approach axis (plan);
    lever_cross / lever_cross2: y x r and y x (y x r) (world) for r from the giver's patch centre
    to the receiver's site, y the giver's closing axis (Rodrigues: the point moves by
    sin(t) y x r + (1 - cos t) y x (y x r) when the object turns t about y);
    approach: the receiver's approach axis (world); sag: how far the object's point under the
    receiver moves per kg held, by the giving arm's servo compliance (world, m/kg); receiver:
    the receiver's grip; receiver_centre: the object's centre in the receiver's site frame
    (plan); lateral_shift: how much of the object's lateral error along the giver's x shows
    along the receiver's x; closing_s: the receiver's closing time; squaring: the giver's turn
    about its closing axis per radian of yaw squared out of its jaws at most, w / (2 h_z), and
    patch_half_height its h_z (see :func:`squaring_turn`); receiver_span: the receiver's own
    hold (set once the walk reaches it).
    """

    giver: CarrySpan
    depth: float
    lever_cross: FloatArray
    lever_cross2: FloatArray
    approach: FloatArray
    sag: FloatArray
    receiver: Grip
    receiver_centre: FloatArray
    receiver_half: FloatArray
    lateral_shift: float
    closing_s: float
    squaring: float
    patch_half_height: float
    receiver_span: CarrySpan | None = None


def servo_sag(
    world: World, qpos: FloatArray, side: str, load_point: FloatArray, probe_point: FloatArray
) -> FloatArray:
    """Displacement (world, m per kg) of a point held by the ``side`` hand under a held weight.

    The servos do not feed the held object's weight forward, so the weight m g at
    ``load_point`` (the object's COM) bends each servoed joint by tau / kp (a stiffness model
    of position servos): dq = Kp^-1 J_load^T m g, and a point rigidly held by the hand moves
    by J_probe dq, which includes the hand's turn under the weight's moment. Dofs without a
    servo and the gripper's own (force-saturated) slides are taken as rigid.

    Args:
        world: the world (its model); qpos: the configuration.
        side: the holding hand.
        load_point: world point where the weight acts; probe_point: world point to follow.

    Returns:
        (3,) the probe point's displacement per kg of held mass.
    """
    model = world.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    body = int(model.site_bodyid[world.ids.hand_sites[side]])
    jac_load, jac_probe = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    mujoco.mj_jac(model, data, jac_load, None, np.asarray(load_point, dtype=float), body)
    mujoco.mj_jac(model, data, jac_probe, None, np.asarray(probe_point, dtype=float), body)
    grippers = {a for acts in world.ids.gripper_actuators.values() for a in acts}
    compliance = np.zeros(model.nv)
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or a in grippers:
            continue
        joint = int(model.actuator_trnid[a, 0])
        kp = float(model.actuator_gainprm[a, 0])
        kind = int(model.jnt_type[joint])
        if kind in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)) and kp > 0:
            compliance[model.jnt_dofadr[joint]] = 1.0 / kp
    return np.asarray(jac_probe @ (compliance * (jac_load.T @ GRAVITY)), dtype=float)


@dataclass
class HoldProblem:
    """Everything the hold probability needs from one planned alternative."""

    obj: str
    mass: float
    spans: list[tuple[CarrySpan, Grip]] = field(default_factory=list)
    misses: list[ReceiverMiss] = field(default_factory=list)


def _object_poses(world: World, qpos: FloatArray, obj: str) -> tuple[FloatArray, FloatArray]:
    """The object's rotations (K, 3, 3) and COMs (K, 3) in configurations ``qpos`` (K, nq)."""
    adr = world.ids.object_qpos[obj]
    rows = np.atleast_2d(np.asarray(qpos, dtype=float))
    q = rows[:, adr + 3 : adr + 7]
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rot = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )  # unit quaternion (w, x, y, z) to rotation matrix
    com = rows[:, adr : adr + 3] + rot @ world.model.body_ipos[world.ids.object_bodies[obj]]
    return rot, com


def object_pose_at(world: World, qpos: FloatArray, obj: str) -> tuple[FloatArray, FloatArray]:
    """The object's rotation and COM (world) in one configuration ``qpos``."""
    rot, com = _object_poses(world, qpos, obj)
    return rot[0], com[0]


def site_pose_at(world: World, qpos: FloatArray, side: str) -> tuple[FloatArray, FloatArray]:
    """The ``side`` hand site's position and rotation (world) in a configuration ``qpos``."""
    data = mujoco.MjData(world.model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(world.model, data)
    site = world.ids.hand_sites[side]
    return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()


def _object_half(world: World, obj: str, obj_rot: FloatArray, site_rot: FloatArray) -> FloatArray:
    """The object's half extents along the site's x and z axes (object body frame conversion)."""
    geom = world.ids.object_geoms[obj]
    axes = obj_rot.T @ site_rot
    return np.array([_geom_half_extent(world.model, geom, axes[:, i]) for i in (0, 2)])


def _receiver_miss(
    world: World, qpos: FloatArray, obj: str, giver: tuple[CarrySpan, Grip], side: str, closing_s: float
) -> ReceiverMiss:
    """The geometry of the receiver ``side`` closing on the object ``giver`` holds at ``qpos``."""
    span, g = giver
    obj_rot, com = object_pose_at(world, qpos, obj)
    giver_rot = obj_rot @ span.grasp_rotation.T
    giver_pos = com - giver_rot @ span.grasp_centre
    half_g = _object_half(world, obj, obj_rot, giver_rot)
    pg = patch(g, span.grasp_centre[[0, 2]][None, :], half_g)
    centre_world = giver_pos + giver_rot @ np.array([pg.centre[0, 0], 0.0, pg.centre[0, 1]])
    rec_pos, rec_rot = site_pose_at(world, qpos, side)
    axis = giver_rot[:, 1]
    lever = rec_pos - centre_world
    rec_half = _object_half(world, obj, obj_rot, rec_rot)
    rec_centre = rec_rot.T @ (com - rec_pos)
    receiver = grip(world, side, obj, obj_rot.T @ rec_rot[:, 1])
    depth = receiver.pad_centre[1] + receiver.pad_half[1] - (rec_centre[2] - rec_half[1])
    return ReceiverMiss(
        giver=span,
        depth=float(depth),
        lever_cross=np.cross(axis, lever),
        lever_cross2=np.cross(axis, np.cross(axis, lever)),
        approach=rec_rot[:, 2].copy(),
        sag=servo_sag(world, qpos, g.side, com, rec_pos),
        receiver=receiver,
        receiver_centre=rec_centre[[0, 2]],
        receiver_half=rec_half,
        lateral_shift=float(giver_rot[:, 0] @ rec_rot[:, 0]),
        closing_s=closing_s,
        squaring=g.half_width / float(pg.half[0, 1]) if pg.half[0, 1] > 0.0 else 0.0,
        patch_half_height=float(pg.half[0, 1]),
    )


def hold_problem(world: World, plan: object, closing_s: float = 0.5) -> HoldProblem:
    """Walk a planned alternative's steps: who holds the object when, and each handover.

    Args:
        world: the estimate world the plan was made on.
        plan: an :class:`executive.planning.plan.AlternativePlan` (steps with kind, name, side;
            trajectories by step name; task.object).
        closing_s: time a grasp's jaws take to close and settle (the Grasp behaviour's settle
            time), spent with the object at rest in the hands that already hold it.

    Returns:
        The :class:`HoldProblem`.

    Raises:
        HoldModelUnavailable: a grasping hand is not a parallel jaw (see :func:`grip`).
    """
    from executive.planning.plan import held_at_start

    obj: str = plan.task.object  # type: ignore[attr-defined]
    body = world.ids.object_bodies[obj]
    problem = HoldProblem(obj=obj, mass=float(world.model.body_mass[body]))
    holding: dict[str, tuple[CarrySpan, Grip]] = {}
    qpos, t_now = world.data.qpos.copy(), 0.0
    trajectories: dict[str, Trajectory] = plan.trajectories  # type: ignore[attr-defined]
    held = held_at_start(plan.steps)  # type: ignore[attr-defined]
    for step in plan.steps:  # type: ignore[attr-defined]
        traj = trajectories.get(step.name)
        if traj is not None and held.get(step.side) == obj and not problem.spans:
            # Held from the start (a place after a pick): the grip is as the plan starts.
            holding[step.side] = _start_span(world, traj.qpos[0], obj, step.side, t_now)
            problem.spans.append(holding[step.side])
        if traj is not None:
            if holding:
                rots, coms = _object_poses(world, traj.qpos, obj)
                for k, t in enumerate(traj.times):
                    for span, _ in holding.values():
                        span.add(t_now + float(t), rots[k], coms[k], len(holding) == 1)
            t_now, qpos = t_now + traj.duration, traj.qpos[-1]
        elif step.kind == "grasp" and step.side not in holding:
            rot, com = object_pose_at(world, qpos, obj)
            t_now += closing_s
            for span, _ in holding.values():
                span.add(t_now, rot, com, len(holding) == 1)
            if holding:
                giver = next(iter(holding.values()))
                problem.misses.append(_receiver_miss(world, qpos, obj, giver, step.side, closing_s))
            site_pos, site_rot = site_pose_at(world, qpos, step.side)
            g = grip(world, step.side, obj, rot.T @ site_rot[:, 1])
            half = _object_half(world, obj, rot, site_rot)
            span = CarrySpan(step.side, site_rot.T @ rot, site_rot.T @ (com - site_pos), half)
            span.add(t_now, rot, com, not holding)
            holding[step.side] = (span, g)
            if problem.misses and problem.misses[-1].receiver_span is None and len(holding) > 1:
                problem.misses[-1].receiver_span = span
            problem.spans.append((span, g))
        elif step.kind == "release" and step.side in holding:
            del holding[step.side]
    return problem


def _start_span(world: World, qpos: FloatArray, obj: str, side: str, t: float) -> tuple[CarrySpan, Grip]:
    """The span of ``side`` holding ``obj`` in configuration ``qpos`` (its grip as it is there)."""
    rot, com = object_pose_at(world, qpos, obj)
    site_pos, site_rot = site_pose_at(world, qpos, side)
    g = grip(world, side, obj, rot.T @ site_rot[:, 1])
    half = _object_half(world, obj, rot, site_rot)
    span = CarrySpan(side, site_rot.T @ rot, site_rot.T @ (com - site_pos), half)
    span.add(t, rot, com, True)
    return span, g


# --- critical masses and the probability ---------------------------------------------------


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

    with np.errstate(divide="ignore"):
        room = np.maximum(0.5 * np.pi - np.abs(yaws) * miss.squaring, 0.0)
        hi = np.minimum(mass_cap, np.where(tilt != 0.0, room / np.abs(tilt), mass_cap))
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
        return RiskReport("hold", 0.0, (0.0, 0.0), severity, 0.0, details={"hold_model": "nothing held"})
    try:
        problem = hold_problem(world, plan)
    except HoldModelUnavailable as exc:
        details: dict[str, float | str] = {"hold_model": f"unavailable: {exc}"}
        return RiskReport("hold", 0.0, (0.0, 1.0), severity, 0.0, details=details)
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
    return RiskReport("hold", p, (p, p), severity, p, details=details)
