"""The squeeze of a dexterous hand (a thumb against fingers) on an object, from its servos.

A hand like the G1's Dex3 has no slide jaws whose servo error gives the grip force. Its
force (:func:`dexterous_squeeze`) and where it holds an object across the site
(:func:`pinch_centre`) are read off the model at the profile's closed gripper targets
(MuJoCo forward kinematics, ``mj_jac``); the model is in those functions' docstrings.

Usage::

    squeeze = dexterous_squeeze(world, "left", width=0.09)
    squeeze.force  # N, normal force of each side on the object
    pinch_centre(world, "left", 0.09)  # m along the site's +y where the closed hand holds it
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.risk.hand_span import FAN_HALF_WIDTH, hand_collision_geoms, posed_hand
from executive.risk.model_geometry import geom_points
from executive.world.model import World

__all__ = ["Chain", "Squeeze", "dexterous_squeeze", "hand_chains", "pinch_centre"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Chain:
    """One finger (or the thumb) at the closed targets: its contact point and stiffness.

    Attributes:
        name: the chain's leaf body.
        thumb: on the thumb's side (-y of the site).
        geom: the geom that holds the contact point (the chain's pad).
        point: (3,) the contact point in the site frame (m).
        stiffness: N/m along the closing axis at that point.
        force_cap: N, the largest force its force-limited actuators allow (inf: none).
    """

    name: str
    thumb: bool
    geom: int
    point: FloatArray
    stiffness: float
    force_cap: float


@dataclass(frozen=True)
class Squeeze:
    """The hand closed on an object of ``width``: each side's normal force and its chains."""

    width: float
    force: float
    chains: tuple[Chain, ...]


def _site_frame(world: World, data: mujoco.MjData, side: str) -> tuple[FloatArray, FloatArray]:
    site = world.ids.hand_sites[side]
    return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()


def _leaf_chains(world: World, side: str) -> list[list[int]]:
    """Per leaf body of the hand (below its root), the bodies from the leaf up to the root's child."""
    model = world.model
    bodies = list(world.ids.hand_bodies[side])
    root = bodies[0] if int(model.body_parentid[bodies[0]]) not in bodies else None
    moving = [b for b in bodies if b != root]
    parents = {int(model.body_parentid[b]) for b in moving}
    chains = []
    for leaf in (b for b in moving if b not in parents):
        chain, b = [], leaf
        while b in moving:
            chain.append(b)
            b = int(model.body_parentid[b])
        chains.append(chain)
    return chains


def _chain_stiffness(
    world: World, data: mujoco.MjData, body: int, point: FloatArray, n: FloatArray
) -> tuple[float, float]:
    """Stiffness (N/m) along ``n`` at the world ``point`` of ``body``, and the force cap (N)."""
    model = world.model
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jac(model, data, jacp, None, point, body)
    lever = n @ jacp
    compliance, cap = 0.0, np.inf
    for act in range(model.nu):
        if model.actuator_trntype[act] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        dof = int(model.jnt_dofadr[int(model.actuator_trnid[act, 0])])
        arm = float(lever[dof])
        kp = float(model.actuator_gainprm[act, 0])
        if arm == 0.0 or kp <= 0.0 or not _is_hand_dof(world, dof):
            continue
        compliance += arm * arm / kp
        cap = min(cap, _torque_limit(model, act) / abs(arm))
    return (1.0 / compliance if compliance > 0.0 else 0.0), cap


def _torque_limit(model: mujoco.MjModel, act: int) -> float:
    """The largest force an actuator puts on its joint: its forcerange and the joint's
    actuatorfrcrange (MuJoCo clamps the joint's total actuator force to it), inf if neither."""
    limit = np.inf
    if model.actuator_forcelimited[act]:
        limit = float(np.max(np.abs(model.actuator_forcerange[act])))
    joint = int(model.actuator_trnid[act, 0])
    if model.jnt_actfrclimited[joint]:
        limit = min(limit, float(np.max(np.abs(model.jnt_actfrcrange[joint]))))
    return float(limit)


def _is_hand_dof(world: World, dof: int) -> bool:
    """Whether a dof moves a body below the hand's root (a finger joint, not the arm)."""
    body = int(world.model.dof_bodyid[dof])
    bodies = world.ids.hand_bodies
    return any(body in list(b)[1:] for b in bodies.values())


def hand_chains(world: World, side: str) -> tuple[Chain, ...]:
    """The ``side`` hand's chains at its closed targets (see the module docstring).

    Raises:
        ValueError: the hand has no chain on one side of its site (not a thumb against fingers).
    """
    model = world.model
    open_data = posed_hand(world, side)
    o_origin, o_frame = _site_frame(world, open_data, side)
    data = posed_hand(world, side, tuple(world.profile.arms[side].gripper.closed))
    mujoco.mj_comPos(model, data)
    origin, frame = _site_frame(world, data, side)
    geoms = hand_collision_geoms(world, side)
    chains = []
    for bodies in _leaf_chains(world, side):
        own = [g for g in geoms if int(model.geom_bodyid[g]) in bodies]
        if not own:
            continue
        centre = np.mean(np.vstack([geom_points(model, open_data, g) for g in own]), axis=0)
        thumb = float((centre - o_origin) @ o_frame[:, 1]) < 0.0
        best: tuple[float, int, FloatArray] | None = None
        for g in own:
            local = (geom_points(model, data, g) - origin) @ frame
            local = local[(local[:, 2] >= 0.0) & (np.abs(local[:, 0]) <= FAN_HALF_WIDTH)]
            if not len(local):
                continue
            k = int(np.argmax(local[:, 1]) if thumb else np.argmin(local[:, 1]))
            reach = float(local[k, 1]) if thumb else -float(local[k, 1])
            if best is None or reach > best[0]:
                best = (reach, g, local[k])
        if best is None:
            continue
        world_point = origin + frame @ best[2]
        k_n, cap = _chain_stiffness(world, data, int(model.geom_bodyid[best[1]]), world_point, frame[:, 1])
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, bodies[0]) or str(bodies[0])
        chains.append(Chain(name, thumb, best[1], best[2], k_n, cap))
    if not any(c.thumb for c in chains) or all(c.thumb for c in chains):
        raise ValueError(f"the {side} hand has no opposing chains across its site's closing axis")
    return tuple(chains)


def dexterous_squeeze(world: World, side: str, width: float) -> Squeeze:
    """Normal force (N) of each side of the ``side`` hand closed on an object ``width`` wide.

    * Sides: the hand's moving links (those below its root body) whose collision geoms lie on
      the site's -y side at the open targets are the thumb's; those on +y the fingers'.
      Each leaf link starts one chain (thumb, index, middle), its ancestors up to the root.
    * Contact point of a chain: its innermost mesh vertex (towards the other side) in the
      region an object between the jaws fills: at or below the site along the approach (z >= 0)
      and within the rays' fan across it (|x| <= ``FAN_HALF_WIDTH``).
    * Interference: the object of width w spans |y| <= w / 2 about the site; a chain's closed
      contact point lies ``delta = w / 2 + y`` (thumb) or ``w / 2 - y`` (fingers) inside it
      (> 0: the servo's target is past the face). One side's delta may be negative: the other
      pushes the object over to it, and the hand grips while the sum is positive.
    * Stiffness of a chain along the closing axis n at its contact point: the position servos
      are joint springs kp, so the tip's compliance is n^T J Kp^-1 J^T n (Cartesian stiffness of
      a serial chain; Salisbury 1980, "Active stiffness control of a manipulator in Cartesian
      coordinates"), J the point's translational Jacobian over the chain's joints.
    * Squeeze: the object shifts along n until the two sides' forces balance; with each side's
      chains in parallel (k_s = sum k_i, preload sum k_i delta_i) the force is F = (P_t k_f + P_f
      k_t) / (k_t + k_f) for preloads P and stiffnesses k of thumb and fingers (two springs in
      series against each other: k_t k_f (delta_t + delta_f) / (k_t + k_f) for one chain a side), 0
      when the object is narrower than the closed hand. Servos saturate: a chain presses at most
      min_i limit_i / |n^T J_i| over its joints (limit_i the actuator's forcerange or the joint's
      actuatorfrcrange, which MuJoCo clamps the joint's actuator force to), and the squeeze is at
      most the weaker side's sum of those.

    Args:
        world: the world whose robot has the hand (its profile's closed targets are used).
        side: the arm.
        width: the object's extent across the closing axis (m), centred on the site.

    Returns:
        The :class:`Squeeze`; force 0 when the closed hand does not reach the object's faces.
    """
    chains = hand_chains(world, side)
    sums = {True: [0.0, 0.0], False: [0.0, 0.0]}  # per side: stiffness, preload
    for c in chains:
        y = float(c.point[1])
        inside = width / 2.0 + (y if c.thumb else -y)
        sums[c.thumb][0] += c.stiffness
        sums[c.thumb][1] += c.stiffness * inside
    (k_t, p_t), (k_f, p_f) = sums[True], sums[False]
    if k_t <= 0.0 or k_f <= 0.0:
        return Squeeze(width, 0.0, chains)
    spring = max(0.0, (p_t * k_f + p_f * k_t) / (k_t + k_f))
    caps = {thumb: sum(c.force_cap for c in chains if c.thumb == thumb) for thumb in (True, False)}
    return Squeeze(width, float(min(spring, caps[True], caps[False])), chains)


def _side_force(chains: tuple[Chain, ...], thumb: bool, width: float, shift: float) -> float:
    """Total force (N) of one side's chains on an object ``width`` wide centred at ``shift`` (site y)."""
    total = 0.0
    for c in chains:
        if c.thumb != thumb:
            continue
        y = float(c.point[1])
        inside = (width / 2.0 + y - shift) if thumb else (width / 2.0 - y + shift)
        total += min(c.force_cap, c.stiffness * max(0.0, inside))
    return total


def pinch_centre(world: World, side: str, width: float, *, tol: float = 1e-7) -> float:
    """Where along the site's closing axis (+y, thumb to fingers) the closed ``side`` hand holds
    an object ``width`` wide: the offset (m) of the object's centre from the hand site at which
    the thumb's and the fingers' forces balance.

    * Pinch centre: closing, the hand moves the object to where the two sides' forces balance,
      whatever its offset across the site before (as long as both sides reach it). With the
      object centred at ``s`` on the closing axis each chain presses min(cap, k max(0, delta -
      s)) (thumb) or min(cap, k max(0, delta + s)) (fingers), delta its interference at s = 0;
      the thumb's total falls and the fingers' rises with s, and the equilibrium is their
      crossing (bisection; the middle of the span where both are saturated and equal). Unequal
      thumb and finger reach (the Dex3's thumb passes the site, its fingers stop short of it)
      puts that centre off the site: the object is carried, and placed, that far from where the
      hand aims.

    Args:
        world: the world whose robot has the hand (its profile's closed targets are used).
        side: the arm.
        width: the object's extent across the closing axis (m).
        tol: bisection's stopping width (m).

    Returns:
        The offset; 0.0 when the closed hand does not reach the object (no squeeze, no shift).

    Raises:
        ValueError: the hand is not a thumb against fingers (:func:`hand_chains`).
    """
    chains = hand_chains(world, side)
    ys = [float(c.point[1]) for c in chains]
    lo, hi = min(ys) - width, max(ys) + width  # thumb's force is 0 above hi, fingers' 0 below lo

    def excess(s: float) -> float:
        return _side_force(chains, True, width, s) - _side_force(chains, False, width, s)

    if dexterous_squeeze(world, side, width).force <= 0.0:
        return 0.0
    a, b = lo, hi  # excess(a) >= 0 >= excess(b); non-increasing in s
    while b - a > tol:
        m = 0.5 * (a + b)
        if excess(m) > 0.0:
            a = m
        else:
            b = m
    left = 0.5 * (a + b)
    a, b = lo, hi  # the other end of a flat zero span: the last s with excess >= 0
    while b - a > tol:
        m = 0.5 * (a + b)
        if excess(m) >= 0.0:
            a = m
        else:
            b = m
    return float(0.5 * (left + 0.5 * (a + b)))
