"""What the stepping balance leaves of the CoM's model error at each knot of a plan's walks.

A step runs with the balance feedback on (:mod:`executive.planning.balance_law`,
:class:`executive.execution.balance.AnkleBalance`). The fall model's persistent CoM bias ``e``
(the truth's CoM off the robot's model) is then not what stands on the feet at every knot:

* on two feet the pelvis shift takes it out as the CoM estimate learns it: at a knot ``tau``
  seconds of two-foot phases after the walk began, ``r(tau) e`` is left
  (:func:`executive.planning.balance_law.residual_fractions`: from the balance's gains, the
  pendulum's ``omega = sqrt(g / h)`` at the walk's mean CoM height, and the CoM's move per metre
  of pelvis shift, :func:`~executive.planning.balance_law.shift_com_ratio`, from the legs'
  kinematics); the CoM ``mu + r e`` must stay over the feet (gain ``r``; ``r = 1`` where the
  walk starts, so the two-foot polygon holds the whole bias there);
* on one foot the shift is held, and the ankle's capture-point law asks a centre of pressure
  ``(1 + convergence) r e`` off the planned CoM for the error at rest (the DCM law, Englsberger
  et al. 2015; the capture point ``xi = c + c_dot / omega`` of Pratt et al. 2006): the sole must
  hold it (gain ``(1 + convergence) r``).

Outside a walk (arm motions on two feet, the balance off) the bias stands as it is (gain 1).
A knot whose support point ``mu`` takes the bias through a gain ``G`` keeps ``mu + G e`` inside
its polygon ``P`` iff ``mu + e`` is inside ``mu + (P - mu) / G`` (:func:`shrink_polygons`), so the
fall model's Gaussian and persistent-bias probabilities apply unchanged. :func:`walk_phases`
reads a plan's walks as :class:`BalancedPhase` spans of the assessed trajectory's clock;
:func:`knot_gains` gives each knot's gain; :func:`carried_bodies` the object each knot's walk
carries (its mass counts in the CoM: :class:`executive.planning.loaded_com.LoadedCoM`).
Measurements: docs/stepping.md ("Falls").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from executive.planning.balance_law import STEPPING_GAINS, BalanceGains, residual_fractions, shift_com_ratio
from executive.planning.plan import AlternativePlan
from executive.risk.fall_batch import KnotPolygons
from executive.risk.fall_support import FallKnots
from executive.world.model import World

__all__ = ["BalancedPhase", "carried_bodies", "knot_gains", "shift_ratio", "shrink_polygons", "walk_phases"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BalancedPhase:
    """One phase of a walk as the balance runs it, in the assessed trajectory's clock.

    Attributes:
        start, end: its span (s).
        feet: how many feet it holds on the floor (the balance's support).
        walk: which walk it belongs to (the balance's estimate and shift start anew with each).
        carried: (hand side, object) of the object a hand carries through it, or None.
    """

    start: float
    end: float
    feet: int
    walk: int
    carried: tuple[str, str] | None = None


def walk_phases(plan: AlternativePlan) -> tuple[BalancedPhase, ...]:
    """The phases of every walk of ``plan`` in the clock of its steps' trajectories end to end
    (:meth:`AlternativePlan.ordered_trajectories`, as the fall model assesses them)."""
    out: list[BalancedPhase] = []
    offset, walk = 0.0, 0
    for step in plan.steps:
        trajectory = plan.trajectories.get(step.name)
        if trajectory is None:
            continue
        if step.kind == "step" and plan.walks.get(step.name):
            t = offset
            for footstep in plan.walks[step.name]:
                for phase in footstep.phases:
                    end = t + phase.trajectory.duration
                    out.append(BalancedPhase(t, end, len(phase.support), walk, step.carried))
                    t = end
            walk += 1
        offset += trajectory.duration
    return tuple(out)


def _phase_of(times: FloatArray, phases: Sequence[BalancedPhase]) -> NDArray[np.int_]:
    """Per time, the index of the phase it lies in (a phase's end is its own), or -1."""
    if not phases:
        return np.full(len(times), -1, dtype=int)
    starts = np.array([p.start for p in phases])
    ends = np.array([p.end for p in phases])
    index = np.minimum(np.searchsorted(ends + 1e-9, times, side="left"), len(phases) - 1)
    inside = (times >= starts[index] - 1e-9) & (times <= ends[index] + 1e-9)
    return np.where(inside, index, -1)


def shift_ratio(world: World) -> float:
    """The CoM's move over the feet per metre of the balance's pelvis shift, at the robot's
    standing keyframe (:func:`~executive.planning.balance_law.shift_com_ratio`)."""
    model = world.model
    legs = {
        int(model.body(foot.body).id): [
            int(model.jnt_dofadr[model.joint(name).id]) for name in world.profile.leg_joints.get(side, ())
        ]
        for side, foot in world.profile.feet.items()
    }
    return shift_com_ratio(model, world.home_qpos(), world.ids.base_body, legs)


def knot_gains(
    world: World, knots: FallKnots, phases: Sequence[BalancedPhase], gains: BalanceGains = STEPPING_GAINS
) -> FloatArray:
    """Per knot, the gain on the CoM bias (module doc): ``r`` on two feet, ``(1 + convergence) r``
    on one, 1 outside the walks.

    Args:
        world: the estimate world (its robot's legs give the shift's CoM ratio).
        knots: the trajectory's knots (:func:`executive.risk.fall_support.fall_knots`).
        phases: the walks' phases in the knots' clock (:func:`walk_phases`).
        gains: the balance's gains.
    """
    out = np.ones(len(knots.times))
    which = _phase_of(knots.times, phases)
    if not np.any(which >= 0):
        return out
    beta = shift_ratio(world)
    for walk in sorted({p.walk for p in phases}):
        members = [i for i, p in enumerate(phases) if p.walk == walk]
        at = np.isin(which, members)
        if not np.any(at):
            continue
        omega = float(np.sqrt(knots.gravity / max(float(np.mean(knots.coms[at, 2])) - knots.ground, 1e-3)))
        spans = [(phases[i].start, phases[i].end, phases[i].feet > 1) for i in members]
        r = residual_fractions(knots.times[at], spans, omega, gains, beta)
        one_foot = np.array([phases[i].feet == 1 for i in which[at]])
        out[at] = np.where(one_foot, gains.cop_gain * r, r)
    return out


def carried_bodies(times: FloatArray, phases: Sequence[BalancedPhase]) -> list[tuple[str, str] | None]:
    """Per knot time, (hand side, object) of the object its walk carries, or None."""
    which = _phase_of(np.asarray(times, dtype=float), phases)
    return [phases[i].carried if i >= 0 else None for i in which.tolist()]


def shrink_polygons(polygons: KnotPolygons, mus: FloatArray, gains: FloatArray) -> KnotPolygons:
    """Each knot's polygon scaled about its planned support point: ``mu_k + (P_k - mu_k) / G_k``.

    A bias e keeps mu_k + G_k e inside P_k iff mu_k + e is inside the scaled polygon (a gain
    below 1 widens it). Knots with gain 1 keep their vertices as they are.
    """
    groups = {}
    for m, (knots, verts) in polygons.groups.items():
        g = gains[knots][:, None, None]
        mu = mus[knots][:, None, :]
        groups[m] = (knots, np.where(g == 1.0, verts, mu + (verts - mu) / g))
    return KnotPolygons(groups)
