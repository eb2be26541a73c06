"""Monte Carlo P(collision) with exact coal distances, to validate the first-order probability.

:func:`monte_carlo_collision_probability` shifts every uncertain environment body (and a carried
object by its own error) once per sample, holds the shift over the whole trajectory, and counts
the samples in which some pair penetrates at some knot. Re-exported by
:mod:`executive.risk.collision`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.collision_model import CollisionModel, TrajectoryLike
from executive.risk.collision_probability import CollisionModelError
from executive.risk.collision_setup import Allow, PairLayout

__all__ = ["MonteCarloResult", "monte_carlo_collision_probability"]

FloatArray = NDArray[np.float64]


class MonteCarloResult(NamedTuple):
    """Sampled P(collision): over the trajectory and per knot, with standard errors."""

    probability: float
    stderr: float
    per_knot: FloatArray
    samples: int
    coal_calls: int


def monte_carlo_collision_probability(
    model: CollisionModel,
    trajectory: TrajectoryLike,
    rng: np.random.Generator,
    samples: int = 10_000,
    *,
    allow: Allow = (),
) -> MonteCarloResult:
    """P(d < 0 at some knot) with every uncertain environment body shifted by ``N(0, sigma^2 I_2)``.

    One shift per body per sample, held over the whole trajectory (a truth world). Exact
    coal distances; a pair is recomputed only in samples whose shift can close its
    nominal broad-phase lower bound (``|delta| >= bound``), so the answer is unaffected.
    """
    if samples <= 0:
        raise CollisionModelError(f"samples must be > 0, got {samples}")
    carried = trajectory.carried[1] if trajectory.carried is not None else None
    layout = model._layout(carried, allow)
    mdl = model.model
    draws = _draw_shifts(model, layout, carried, rng, samples)
    qpos = np.asarray(trajectory.qpos, dtype=float)
    hit_any = np.zeros(samples, dtype=bool)
    per_knot = np.zeros(len(qpos))
    data = model._data
    calls = 0
    for k, row in enumerate(qpos):
        data.qpos[:] = row
        mujoco.mj_kinematics(mdl, data)
        bounds = model._lower_bounds(data.geom_xpos, data.geom_xmat, layout)
        hit = np.zeros(samples, dtype=bool)
        for ei, ri in zip(*np.nonzero(layout.mask), strict=True):
            calls += _sampled_hits(model, data, layout, ei, ri, bounds[ei, ri], draws, hit)
        per_knot[k] = float(np.mean(hit))
        hit_any |= hit
    p = float(np.mean(hit_any))
    return MonteCarloResult(p, math.sqrt(max(p * (1.0 - p), 1e-300) / samples), per_knot, samples, calls)


class _Shifts(NamedTuple):
    """The Monte Carlo samples' pose errors: each environment geom's body (layout order), each
    uncertain body's (samples, 2) shifts and their lengths, the carried object's geom (None)
    with its own sigma, shifts and their lengths, and zero shifts."""

    env_bodies: list[int]
    by_body: dict[int, FloatArray]
    radius: dict[int, FloatArray]
    carried_geom: int | None
    own_sigma: float
    own: FloatArray
    own_radius: FloatArray
    zero: FloatArray


def _draw_shifts(
    model: CollisionModel, layout: PairLayout, carried: str | None, rng: np.random.Generator, samples: int
) -> _Shifts:
    """Draw all shifts up front, bodies in sorted id order (same generator state, same answer);
    then the carried object's own shift (it sits in the hand wherever it really was)."""
    env_bodies = [int(model.model.geom_bodyid[e]) for e in layout.env]
    uncertain = sorted({b for b in env_bodies if model.setup.env_sigma.get(b, 0.0) > 0.0})
    shifts = {b: rng.normal(0.0, model.setup.env_sigma[b], size=(samples, 2)) for b in uncertain}
    carried_geom = model._object_geom(carried) if carried is not None else None
    own_sigma = model.carried_sigma.get(carried_geom, 0.0) if carried_geom is not None else 0.0
    zero = np.zeros((samples, 2))
    own = rng.normal(0.0, own_sigma, size=(samples, 2)) if own_sigma > 0.0 else zero
    own_radius = np.hypot(own[:, 0], own[:, 1])
    radius = {b: np.hypot(s[:, 0], s[:, 1]) for b, s in shifts.items()}
    return _Shifts(env_bodies, shifts, radius, carried_geom, own_sigma, own, own_radius, zero)


def _sampled_hits(
    model: CollisionModel,
    data: mujoco.MjData,
    layout: PairLayout,
    ei: np.intp,
    ri: np.intp,
    bound: float,
    draws: _Shifts,
    hit: NDArray[np.bool_],
) -> int:
    """Mark in ``hit`` the samples in which layout pair (env ei, robot ri), ``bound`` its nominal
    broad-phase lower bound at the knot in ``data``, penetrates; returns the coal calls made."""
    env, robot, body = layout.env_list[ei], layout.robot_list[ri], draws.env_bodies[ei]
    model._place(data, env)
    model._place(data, robot)
    moves = robot == draws.carried_geom and draws.own_sigma > 0.0
    if body not in draws.by_body and not moves:
        if bound <= 0.0:
            if model._pair_distance(layout, int(ei), int(ri)) < 0.0:
                hit[:] = True
            return 1
        return 0
    calls = 0
    # Only shifts at least as long together as the pair's lower bound can close it.
    env_shift = draws.by_body.get(body, draws.zero)
    reach = draws.radius.get(body, draws.zero[:, 0]) + (draws.own_radius if moves else 0.0)
    env_transform, robot_transform = model._transforms[env], model._transforms[robot]
    env_nominal = np.array(data.geom_xpos[env], dtype=float)
    robot_nominal = np.array(data.geom_xpos[robot], dtype=float)
    for s in np.nonzero(reach >= bound)[0]:
        if hit[s]:
            continue
        dx, dy = env_shift[s]
        env_transform.setTranslation(env_nominal + np.array([dx, dy, 0.0]))
        if moves:
            ox, oy = draws.own[s]
            robot_transform.setTranslation(robot_nominal + np.array([ox, oy, 0.0]))
        calls += 1
        if model._pair_distance(layout, int(ei), int(ri)) < 0.0:
            hit[s] = True
    model._place(data, env)
    model._place(data, robot)
    return calls
