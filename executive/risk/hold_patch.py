"""The pads' contact patch on a held object, the load it can take and how fast it creeps.

A patch is the overlap of the pad faces with the object's section across the jaws (MuJoCo's
box-box collision puts a contact at each of its corners). :func:`hold_capacity` gives the
largest force and moment its friction resists; :func:`creep_compliance` how fast MuJoCo's
soft contacts let the object turn inside that limit.

Usage::

    p = patch(g, object_centre, object_half)  # one row per lateral offset
    f_max, tau_max = hold_capacity(g, p, mu)
    omega_per_nm = creep_compliance(g, p, mu)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from executive.risk.hold_contact import contact_impedance
from executive.risk.hold_grip import Grip

__all__ = ["Patch", "creep_compliance", "hold_capacity", "patch"]

FloatArray = NDArray[np.float64]


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
