"""The tracking mode: a hand that ends a move farther from its planned end than the move allows.

A move (:class:`behaviours.move_hand.MoveHand`) fails with the verdict ``tracking`` when a hand
settles more than :data:`~executive.planning.plan.MOVE_TOLERANCE` from its planned end. Per move
the model predicts where each hand ends from the servos' statics
(:class:`executive.risk.servo.ServoSet`: a clipped joint target, a carried object's weight or a
pushed object's friction, the body held on its feet; a servo short of torque stalls), with
:data:`UNMODELLED_SIGMA` for what the statics miss, or the end errors the decision's dry run
measured (:meth:`TrackingPrediction.measured`). The model, its probability and its
measurements: docs/risk_models.md, "Tracking".

Usage::

    prediction = predict_tracking(world, plan)
    report = tracking_report(prediction, severity)
    report = tracking_report(prediction.measured(dry_run["tracking"]), severity)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import MOVE_TOLERANCE, AlternativePlan, Step
from executive.planning.timing import Trajectory
from executive.risk.fall_force import force_scale_distribution
from executive.risk.gaussian import ball_exceed_probability, gauss_hermite_normal
from executive.risk.report import RiskReport
from executive.risk.servo import Hold, ServoSet
from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = [
    "MEASURED_SIGMA",
    "RESIDUAL_SCALE",
    "UNMODELLED_SIGMA",
    "HandEnd",
    "MoveEnd",
    "TrackingPrediction",
    "TrackingReport",
    "predict_tracking",
    "tracking_report",
]

FloatArray = NDArray[np.float64]

#: m per axis: a hand's end error the statics do not predict, before a physics run measured it
#: (the base's lag, a move's settling; docs/risk_models.md, "Tracking").
UNMODELLED_SIGMA = 0.003
#: m per axis: a hand's end error from truth to truth about what the dry run measured.
MEASURED_SIGMA = 0.0005
#: The truth-to-truth spread of the measured residual (dry run less statics), as a fraction of it.
RESIDUAL_SCALE = 0.16
#: Step kinds whose end the tracking model does not check (a press and a walk have behaviours of
#: their own); a push is checked where it pushes (:func:`_pushed`), not on its way down.
_UNTRACKED = ("push", "press", "step", "grasp", "release")
_GRAVITY = np.array([0.0, 0.0, -9.81])
#: Every third knot's torques (the minimum-jerk timing's accelerations change smoothly between them).
_KNOT_STRIDE = 3


@dataclass(frozen=True)
class HandEnd:
    """One hand at the end of one move.

    error: (3,) where it ends less its planned end (m, world): the statics' prediction at the
        carried object's nominal mass, or the dry run's measurement.
    per_kg: (3,) m per kg the carried object weighs beyond its nominal mass.
    residual: (3,) the measured error less the statics' (zeros before a dry run).
    """

    side: str
    error: FloatArray
    per_kg: FloatArray
    residual: FloatArray


@dataclass(frozen=True)
class MoveEnd:
    """The end of one move: its hands, its tolerance, and the masses its servos hold.

    mass_range: (low, high) kg of the carried object for which every servo holds the end pose
        within its force limit ((-inf, inf): no carried object, every servo within it).
    peak_ratio: the largest |torque| / limit a servo needs along the move (gravity, the plan's
        accelerations and the object's load; above 1 it lags there and catches up by the end).
    measured: the hands' errors are the dry run's.
    push_mass: kg of the object the move pushes (0: it pushes none). Its hands' ``per_kg`` and its
        ``mass_range`` are then per kg of that object at its nominal friction (a truth's mass
        and friction factors scale the kilograms alike: the load is ``mu m g``).
    """

    name: str
    tolerance: float
    hands: tuple[HandEnd, ...]
    mass_range: tuple[float, float]
    peak_ratio: float
    measured: bool = False
    push_mass: float = 0.0


@dataclass(frozen=True)
class TrackingPrediction:
    """Every tracked move of an alternative and the carried object's mass (nominal, 1-sigma).

    push_sigmas: a pushed object's relative 1-sigma mass and friction errors (the scenario's
    ``uncertainty.object_mass`` and ``uncertainty.friction``).
    """

    moves: tuple[MoveEnd, ...]
    mass: float
    mass_sigma: float
    push_sigmas: tuple[float, float] = (0.0, 0.0)

    def measured(self, record: Mapping[str, Mapping[str, Sequence[float]]] | None) -> TrackingPrediction:
        """This prediction with the hands' end errors a dry run measured (``record``: per move, per
        hand, executed less planned, as :func:`executive.execution.runner.end_errors` gives);
        moves the run did not end keep the statics'."""
        if not record:
            return self
        moves = []
        for move in self.moves:
            found = record.get(move.name)
            if found is None:
                moves.append(move)
                continue
            hands = []
            for hand in move.hands:
                seen = np.asarray(found.get(hand.side, hand.error), dtype=float)
                hands.append(replace(hand, error=seen, residual=seen - hand.error))
            moves.append(replace(move, hands=tuple(hands), measured=True))
        return replace(self, moves=tuple(moves))

    def hand_at(self, move: str, side: str) -> tuple[FloatArray, float] | None:
        """The ``side`` hand at the end of ``move``: its mean error (3,) and how much it varies
        from truth to truth per axis (m: the mass's share, the measured residual's share, the
        noise about a measurement); None if the move is not tracked. What the statics do not
        see before a dry run (:data:`UNMODELLED_SIGMA`) is left to the caller."""
        found = next((m for m in self.moves if m.name == move), None)
        hand = next((h for h in found.hands if h.side == side), None) if found is not None else None
        if found is None or hand is None:
            return None
        spread = np.hypot(MEASURED_SIGMA, RESIDUAL_SCALE * float(np.linalg.norm(hand.residual)))
        kg = self.mass_sigma
        if found.push_mass > 0.0:
            scale, weight = force_scale_distribution(*self.push_sigmas)
            kg = found.push_mass * float(np.sqrt(weight @ (scale - weight @ scale) ** 2))
        spread = np.hypot(spread, kg * float(np.linalg.norm(hand.per_kg)) / np.sqrt(3.0))
        return hand.error, float(spread)

    def probabilities(self, order: int = 12) -> tuple[float, FloatArray]:
        """P(some move fails) and each move's own P(fails) (the union's bounds: max and sum)."""
        if not self.moves:
            return 0.0, np.zeros(0)
        shared, w_shared = _nodes(order, any(m.measured for m in self.moves))
        mass, w_mass = _mass_nodes(self.mass, self.mass_sigma, order)
        pushes = any(m.push_mass > 0.0 for m in self.moves)
        scale, w_scale = force_scale_distribution(*self.push_sigmas) if pushes else (np.ones(1), np.ones(1))
        ok = np.ones((len(shared), len(mass), len(scale)))
        each = np.zeros(len(self.moves))
        for k, move in enumerate(self.moves):
            # A pushed object's kilograms (times its friction's factor) or the carried object's.
            kg = (move.push_mass * scale)[None, None, :] if move.push_mass > 0.0 else mass[None, :, None]
            nominal = move.push_mass if move.push_mass > 0.0 else self.mass
            stays = ((kg >= move.mass_range[0]) & (kg <= move.mass_range[1])).astype(float)
            sigma = MEASURED_SIGMA if move.measured else UNMODELLED_SIGMA
            for hand in move.hands:
                mean = (
                    hand.error
                    + (kg - nominal)[..., None] * hand.per_kg
                    + (RESIDUAL_SCALE * shared)[:, None, None, None] * hand.residual
                )
                stays = stays * (1.0 - _beyond(np.linalg.norm(mean, axis=-1), sigma, move.tolerance))
            stays = np.broadcast_to(stays, ok.shape)
            each[k] = 1.0 - float(w_shared @ (stays @ w_scale) @ w_mass)
            ok = ok * stays
        p = 1.0 - float(w_shared @ (ok @ w_scale) @ w_mass)
        return float(np.clip(p, 0.0, 1.0)), np.clip(each, 0.0, 1.0)


def _nodes(order: int, measured: bool) -> tuple[FloatArray, FloatArray]:
    """The shared residual factor's quadrature nodes (one node at 0 before a dry run)."""
    if not measured:
        return np.zeros(1), np.ones(1)
    return gauss_hermite_normal(order)


def _mass_nodes(mass: float, sigma: float, order: int) -> tuple[FloatArray, FloatArray]:
    """The truth's object mass at quadrature nodes: ``mass max(0.2, 1 + s z)`` (the sampler's)."""
    if mass <= 0.0 or sigma <= 0.0:
        return np.array([mass]), np.ones(1)
    z, w = gauss_hermite_normal(order)
    return mass * np.maximum(0.2, 1.0 + (sigma / mass) * z), w


def _beyond(distance: FloatArray, sigma: float, tolerance: float) -> FloatArray:
    """P(|mu + e| > tolerance) for e ~ N(0, sigma^2 I_3) and |mu| = ``distance``: the non-central
    chi-square tail with 3 degrees of freedom (Johnson, Kotz & Balakrishnan, 1995, ch. 29)."""
    return ball_exceed_probability(distance, sigma, tolerance, 3)


def predict_tracking(
    world: World, plan: AlternativePlan, servos: ServoSet | None = None
) -> TrackingPrediction:
    """Each tracked move's hands at its end, from the servos' statics on the estimate ``world``.

    Args:
        world: the estimate the plan was made on (its model's masses are the nominal ones).
        plan: the alternative.
        servos: the robot's servos (read off ``world`` when None).

    Returns:
        The prediction; :func:`tracking_report` turns it into the mode's report.
    """
    servos = servos or ServoSet.of(world)
    mass, moves = 0.0, []
    for step in plan.steps:
        traj = plan.trajectories.get(step.name)
        pushed = _pushed(step)
        if traj is None or (step.kind in _UNTRACKED and pushed is None):
            continue
        carried = None if pushed is not None else (traj.carried or step.carried)
        obj = pushed or (carried[1] if carried else None)
        obj_mass = float(world.model.body_mass[world.ids.object_bodies[obj]]) if obj else 0.0
        if pushed is None:
            mass = max(mass, obj_mass)
        moves.append(_move_end(world, servos, step, traj, carried, obj_mass))
    u = world.scenario.uncertainty
    return TrackingPrediction(tuple(moves), mass, u.object_mass * mass, (u.object_mass, u.friction))


def _pushed(step: Step) -> str | None:
    """The object ``step`` pushes with a force (None: it pushes none, as on the way down)."""
    if step.kind != "push" or step.force is None or not np.any(step.force) or not step.carried:
        return None
    return step.carried[1]


def _move_end(
    world: World,
    servos: ServoSet,
    step: Step,
    traj: Trajectory,
    carried: tuple[str, str] | None,
    mass: float,
) -> MoveEnd:
    """One move's end: the hold of its last knot, each hand's error, the masses its servos hold
    (``carried``: what the hand carries, None for a push; ``mass``: kg of the carried or pushed object)."""
    model = world.model
    q = traj.qpos[-1]
    # A place ends with the object resting on its support: the hand holds none of its weight.
    held = carried if step.kind != "place" else None
    pushes = _pushed(step) is not None and mass > 0.0
    loaded = bool(held) or pushes
    hands = []
    with scratch_data(model) as data:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        if pushes:
            load = _push_load(world, data, step, mass)
        else:
            load = _object_load(world, data, held) if held else np.zeros((0, model.nv))
        hold = servos.hold(model, q, load)
        scale = np.array([mass]) if loaded else np.zeros(0)
        dq = hold.total(servos.dofs, scale)
        for side in traj.hand_paths:
            jac = np.zeros((3, model.nv))
            mujoco.mj_jacSite(model, data, jac, None, world.ids.hand_sites[side])
            per_kg = jac @ hold.deflection[1] if loaded else np.zeros(3)
            hands.append(HandEnd(side, jac @ dq, per_kg, np.zeros(3)))
    peak = _peak_ratio(world, servos, traj, carried, mass)
    reach = _mass_range(hold, loaded)
    return MoveEnd(step.name, MOVE_TOLERANCE, tuple(hands), reach, peak, push_mass=mass if pushes else 0.0)


def _push_load(world: World, data: mujoco.MjData, step: Step, mass: float) -> FloatArray:
    """(1, nv) the generalised force on the robot of a push's sliding friction per kg of the pushed
    object: the reaction ``-F / m`` of the step's force (:func:`executive.tasks.push.push_force`,
    Coulomb ``mu m g`` along the push) at the pushing hand's site, ``J^T (-F / m)`` (``data``:
    the move's end pose, its kinematics computed)."""
    jac = np.zeros((3, world.model.nv))
    mujoco.mj_jacSite(world.model, data, jac, None, world.ids.hand_sites[step.side])
    return (jac.T @ (-np.asarray(step.force, dtype=float) / mass))[None, :]


def _object_load(world: World, data: mujoco.MjData, carried: tuple[str, str]) -> FloatArray:
    """(1, nv) the generalised force of 1 kg at the carried object's centre of mass, held by the
    hand: ``J^T m g`` with ``J`` the hand body's Jacobian at that point (the object's own dofs 0;
    ``data``: the move's end pose, its kinematics computed)."""
    model = world.model
    side, obj = carried
    hand = int(model.body(world.profile.arms[side].hand_body).id)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jac(model, data, jac, None, data.xipos[world.ids.object_bodies[obj]], hand)
    return (jac.T @ _GRAVITY)[None, :]


def _mass_range(hold: Hold, carried: bool) -> tuple[float, float]:
    """The carried masses (kg) for which every servo's torque stays within its limit:
    ``|t0 + m t1| <= limit`` per servo, intersected (empty: (inf, -inf))."""
    t0 = hold.torque[0]
    if not carried:
        held = bool(np.all(np.abs(t0) <= hold.limit))
        return (-np.inf, np.inf) if held else (np.inf, -np.inf)
    t1 = hold.torque[1]
    low, high = -np.inf, np.inf
    for a, b, limit in zip(t0, t1, hold.limit, strict=True):
        if not np.isfinite(limit):
            continue
        if abs(b) < 1e-12:
            if abs(a) > limit:
                return np.inf, -np.inf
            continue
        ends = sorted(((limit - a) / b, (-limit - a) / b))
        low, high = max(low, ends[0]), min(high, ends[1])
    return low, high


def _peak_ratio(
    world: World, servos: ServoSet, traj: Trajectory, carried: tuple[str, str] | None, mass: float
) -> float:
    """The largest |torque| / limit of an arm or waist servo along ``traj``: the inverse dynamics
    of its knots (MuJoCo ``mj_rne`` with the plan's velocities and accelerations) plus the carried
    object's weight and inertia at the hand (``J^T m (g - a)``)."""
    model = world.model
    upper = servos.bias & np.isfinite(servos.limit)
    if len(traj.times) < 3 or not upper.any():
        return 0.0
    dofs, limits = servos.dofs[upper], servos.limit[upper]
    qvel, qacc = _rates(model, traj)
    force = np.empty(model.nv)
    hand = int(model.body(world.profile.arms[carried[0]].hand_body).id) if carried else -1
    peak = 0.0
    with scratch_data(model) as data:
        for k in range(0, len(traj.times), _KNOT_STRIDE):
            data.qpos[:], data.qvel[:], data.qacc[:] = traj.qpos[k], qvel[k], qacc[k]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            mujoco.mj_comVel(model, data)
            mujoco.mj_rne(model, data, 1, force)
            need = force[dofs]
            if carried:
                jac = np.zeros((3, model.nv))
                point = data.xipos[world.ids.object_bodies[carried[1]]]
                mujoco.mj_jac(model, data, jac, None, point, hand)
                acc = jac @ qacc[k]
                need = need - mass * (jac[:, dofs].T @ (_GRAVITY - acc))
            peak = max(peak, float(np.max(np.abs(need) / limits)))
    return peak


def _rates(model: mujoco.MjModel, traj: Trajectory) -> tuple[FloatArray, FloatArray]:
    """Per knot, the plan's joint velocity and acceleration (finite differences in the tangent
    space, ``mj_differentiatePos``)."""
    n = len(traj.times)
    qvel = np.zeros((n, model.nv))
    for k in range(1, n):
        dt = float(traj.times[k] - traj.times[k - 1])
        mujoco.mj_differentiatePos(model, qvel[k], dt, traj.qpos[k - 1], traj.qpos[k])
    qacc = np.zeros((n, model.nv))
    qacc[1:] = np.diff(qvel, axis=0) / np.diff(traj.times)[:, None]
    return qvel, qacc


@dataclass(frozen=True)
class TrackingReport(RiskReport):
    """The tracking mode's report, with the prediction it was made from (a dry run refines it:
    :meth:`TrackingPrediction.measured`)."""

    prediction: TrackingPrediction | None = None


def tracking_report(prediction: TrackingPrediction, severity: float) -> TrackingReport:
    """The tracking mode's report of ``prediction``: P(some move fails), the union's bounds, and
    per move the details (the worst move, its hands' predicted distance, the servos' peak)."""
    p, each = prediction.probabilities()
    lower = float(each.max()) if len(each) else 0.0
    upper = float(min(1.0, each.sum()))
    p = float(np.clip(p, lower, upper))
    details: dict[str, float | str] = {"moves": float(len(prediction.moves))}
    if prediction.moves:
        worst = int(np.argmax(each))
        move = prediction.moves[worst]
        far = max(move.hands, key=lambda h: float(np.linalg.norm(h.error)))
        details.update(
            worst_move=move.name,
            worst_move_probability=float(each[worst]),
            worst_hand=far.side,
            worst_hand_error=float(np.linalg.norm(far.error)),
            largest_hand_error=max(float(np.linalg.norm(h.error)) for m in prediction.moves for h in m.hands),
            tolerance=move.tolerance,
            measured="dry run" if move.measured else "statics",
            peak_torque_ratio=max(m.peak_ratio for m in prediction.moves),
        )
    return TrackingReport("tracking", p, (lower, upper), severity, p, details=details, prediction=prediction)
