"""Contact parameters of a geom pair as MuJoCo mixes them, and a resting contact's impedance.

The hold model (:mod:`executive.risk.hold`) reads the pads' friction and soft-contact
parameters from here; :func:`contact_parameters` also gives the friction a push meets.

Usage::

    c = contact_parameters(model, pad_geom, object_geom, friction_scale_b=0.8)
    d, r = contact_impedance(c, inv_weight, normal_force=15.0)
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["ContactParameters", "contact_impedance", "contact_parameters", "impedance"]


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
