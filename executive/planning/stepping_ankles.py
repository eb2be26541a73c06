"""The feet's ankle hinges, found from the model, and the balance reserve they keep while stepping.

A robot on position servos balances through its ankles: the balance feedback
(:class:`executive.execution.balance.AnkleBalance`) moves the ankle hinges' servo targets to move
the centre of pressure under the sole, and shifts the pelvis over the feet (every leg joint's
target, the ankles' too) to take up a CoM the model has wrong. A servo's target is clamped to its
joint's range, so a hinge planned near its limit has no torque left towards it: a stance foot
whose body tips that way cannot push back (docs/stepping.md, "The balance reserve").

:func:`find_ankles` finds each foot's ankle: the two leg joints nearest the foot along its body
chain (the balance's actuated hinges). :func:`balance_reserves` is the room (rad) each hinge keeps
from either end of its range for the balance: the servo angle that puts the whole weight's CoP at
the sole's farthest point from the hinge's axis, plus the hinge's share of a pelvis shift that
takes up ``sigmas`` standard deviations of the CoM's uncertainty. :class:`AnkleReserveLimit`
keeps the ankles of the feet on the floor inside their range shrunk by it (:func:`reserve_limit`
builds it for a world). Where that leaves the legs' lean short of the CoM's goal the step planner
leans the torso over the stance foot with the waist's roll joint (:func:`waist_roll`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import mink
import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.limits import SupportPolygon
from executive.world.model import World

__all__ = [
    "AnkleHinge",
    "AnkleReserveLimit",
    "balance_reserves",
    "find_ankles",
    "reserve_limit",
    "waist_roll",
]

FloatArray = NDArray[np.float64]

#: The damping (m^2) of the leg's least-squares pelvis shift (as the balance feedback's).
_DAMPING = 1e-4
#: How close (rad) a hinge must be to its reserve's bound to count as binding (as a joint's range).
_SLACK = 0.01


@dataclass(frozen=True)
class AnkleHinge:
    """One ankle hinge of a foot: its joint's name and id, dof and qpos address, and range (rad)."""

    joint: str
    joint_id: int
    dof: int
    qadr: int
    lower: float
    upper: float


def find_ankles(
    model: mujoco.MjModel,
    legs: Mapping[str, Sequence[str]],
    feet: Mapping[str, int],
    eligible: Collection[int] | None = None,
) -> dict[str, tuple[AnkleHinge, ...]]:
    """The two leg joints nearest each foot, walking up from the foot's body (foot first).

    Args:
        model: the robot's model.
        legs: the legs' joint names by side (the profile's ``leg_joints``).
        feet: the foot body id of each side.
        eligible: the joint ids that may count (e.g. those with a servo); None: every leg joint.

    Returns:
        side -> its ankle hinges (two, or fewer when the leg has fewer eligible joints).
    """
    out: dict[str, tuple[AnkleHinge, ...]] = {}
    for side, body in feet.items():
        joints = {int(model.joint(name).id) for name in legs.get(side, ())}
        if eligible is not None:
            joints &= set(eligible)
        found: list[AnkleHinge] = []
        while body > 0 and len(found) < 2:
            first = int(model.body_jntadr[body])
            for j in range(first, first + int(model.body_jntnum[body])):
                if j in joints and len(found) < 2:
                    lower, upper = (float(v) for v in model.jnt_range[j])
                    if not model.jnt_limited[j]:
                        lower, upper = -np.inf, np.inf
                    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint {j}"
                    found.append(
                        AnkleHinge(name, j, int(model.jnt_dofadr[j]), int(model.jnt_qposadr[j]), lower, upper)
                    )
            body = int(model.body_parentid[body])
        out[side] = tuple(found)
    return out


def _servo_gains(model: mujoco.MjModel) -> dict[int, float]:
    """joint id -> the position gain (N m/rad) of the position servo that drives it."""
    gains: dict[int, float] = {}
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        kp = float(model.actuator_gainprm[a, 0])
        if kp > 0.0 and float(model.actuator_biasprm[a, 1]) == -kp:  # a position servo
            gains[int(model.actuator_trnid[a, 0])] = kp
    return gains


def balance_reserves(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    ankles: Mapping[str, Sequence[AnkleHinge]],
    feet: Mapping[str, int],
    legs: Mapping[str, Sequence[str]],
    soles: Mapping[str, Sequence[int]],
    base_body: int,
    shift: float,
) -> dict[int, float]:
    """The room (rad) each ankle hinge keeps from its range's ends for the balance feedback.

    Two parts, in the configuration of ``data`` (its kinematics computed; the robot standing):

    * the CoP: ``W e / kp``, with ``W`` the robot's weight, ``kp`` the hinge's servo gain and
      ``e`` the farthest a point of the sole's footprint lies from the hinge's axis across it (in
      the floor plane): the servo angle past the target at which the whole weight's CoP reaches
      the sole's edge (a hinge without a position servo keeps none);
    * the pelvis shift: ``shift * |g|``, with ``g`` the hinge's rates (rad/m) when the pelvis
      moves over the foot along x and along y (the leg's damped least-squares joint rates, the
      foot's orientation kept, as the balance feedback shifts it): the hinge's share of a pelvis
      shift of ``shift`` (m) in any direction.

    Args:
        model, data: the robot's model and a standing configuration's kinematics.
        ankles: each foot's ankle hinges (:func:`find_ankles`).
        feet: the foot body id of each side.
        legs: the legs' joint names by side (the profile's ``leg_joints``; the shift's joints).
        soles: each foot's sole geoms.
        base_body: the robot's base (its subtree's mass is the robot's).
        shift: the pelvis shift (m) to keep room for.

    Returns:
        joint id -> reserve (rad).
    """
    weight = float(model.body_subtreemass[base_body]) * float(np.linalg.norm(model.opt.gravity))
    gains = _servo_gains(model)
    mujoco.mj_comPos(model, data)
    jac = np.zeros((6, model.nv))
    out: dict[int, float] = {}
    for side, hinges in ankles.items():
        corners = SupportPolygon.from_feet(model, data, soles[side]).vertices
        rates = _shift_rates(model, data, feet[side], legs.get(side, ()), jac)
        for hinge in hinges:
            across = np.cross([0.0, 0.0, 1.0], data.xaxis[hinge.joint_id])[:2]
            length = float(np.linalg.norm(across))
            cop = 0.0
            if length > 1e-6 and hinge.joint_id in gains:
                reach = float(
                    np.max(np.abs((corners - data.xanchor[hinge.joint_id][:2]) @ (across / length)))
                )
                cop = weight * reach / gains[hinge.joint_id]
            out[hinge.joint_id] = cop + shift * float(np.linalg.norm(rates.get(hinge.dof, np.zeros(2))))
    return out


def _shift_rates(
    model: mujoco.MjModel, data: mujoco.MjData, foot: int, leg: Sequence[str], jac: FloatArray
) -> dict[int, FloatArray]:
    """dof -> (rad/m along x, along y) of the leg's joints when the pelvis moves over the foot
    (the foot by -1 m relative to the pelvis, its orientation kept; damped least squares)."""
    dofs = [int(model.jnt_dofadr[model.joint(name).id]) for name in leg]
    if not dofs:
        return {}
    mujoco.mj_jacBody(model, data, jac[:3], jac[3:], foot)
    j = jac[:, dofs]
    rates = np.zeros((len(dofs), 2))
    for axis in (0, 1):
        goal = np.zeros(6)
        goal[axis] = -1.0
        rates[:, axis] = j.T @ np.linalg.solve(j @ j.T + _DAMPING * np.eye(6), goal)
    return {dof: rates[i] for i, dof in enumerate(dofs)}


class AnkleReserveLimit(mink.Limit):
    """The ankle hinges of the feet on the floor keep their balance reserve inside their range.

    Velocity-damper rows as mink's ``ConfigurationLimit``, on the range shrunk by each hinge's
    reserve: ``dq <= gain (upper - reserve - q)`` and ``-dq <= gain (q - lower - reserve)``. A hinge
    that starts inside the reserve (a foot put down with its ankle there) moves out at most
    ``recovery`` (rad) per step, as :class:`~executive.planning.stepping_knees.KneeBendLimit`.
    Set :attr:`support` to the feet on the floor before each phase. A hinge's reserve is its CoP
    part plus its rate times :attr:`shift` (the pelvis shift kept room for); with :attr:`active`
    False the limit is off (no rows).

    Args:
        model: the robot's model.
        ankles: each foot's ankle hinges (:func:`find_ankles`).
        cop: joint id -> the CoP part of its reserve (rad) (:func:`balance_reserves`, no shift).
        rates: joint id -> its share of a pelvis shift (rad/m).
        shift: the pelvis shift (m) the reserves keep room for.
        gain: the fraction of its slack a hinge may close per step.
        recovery: rad a hinge inside its reserve moves out per step at most.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        ankles: Mapping[str, Sequence[AnkleHinge]],
        cop: Mapping[int, float],
        rates: Mapping[int, float],
        shift: float,
        gain: float = 0.5,
        recovery: float = 0.005,
    ) -> None:
        self.nv = model.nv
        self.ankles = {side: [h for h in hinges if np.isfinite(h.lower)] for side, hinges in ankles.items()}
        self.cop, self.rates = dict(cop), dict(rates)
        self.shift = float(shift)
        self.active = True
        self.gain, self.recovery = float(gain), float(recovery)
        self.support: tuple[str, ...] = ()

    @property
    def reserves(self) -> dict[int, float]:
        """joint id -> its reserve (rad) now (0 everywhere while not :attr:`active`)."""
        return {
            j: (self.cop.get(j, 0.0) + self.rates.get(j, 0.0) * self.shift) if self.active else 0.0
            for j in set(self.cop) | set(self.rates)
        }

    def bounds(self, hinge: AnkleHinge) -> tuple[float, float]:
        """The hinge's range shrunk by its reserve (rad)."""
        j = hinge.joint_id
        reserve = self.cop.get(j, 0.0) + self.rates.get(j, 0.0) * self.shift if self.active else 0.0
        reserve = min(reserve, 0.5 * (hinge.upper - hinge.lower))
        return hinge.lower + reserve, hinge.upper - reserve

    def binding(self, q: FloatArray, support: Sequence[str]) -> list[str]:
        """The ankle hinges of ``support`` at their reserve's bound (not at their range's), named."""
        out: list[str] = []
        if not self.active:
            return out
        reserves = self.reserves
        for hinge in (h for side in support for h in self.ankles.get(side, ())):
            lower, upper = self.bounds(hinge)
            angle = float(q[hinge.qadr])
            if hinge.lower + _SLACK < angle < hinge.upper - _SLACK:
                for bound in (
                    b for b, at in ((lower, angle <= lower + _SLACK), (upper, angle >= upper - _SLACK)) if at
                ):
                    reserve = reserves.get(hinge.joint_id, 0.0)
                    out.append(
                        f"joint '{hinge.joint}' at its balance reserve ({bound:.2f} rad, {reserve:.3f} rad "
                        "inside its range)"
                    )
        return out

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a position limit, like mink's ConfigurationLimit
        hinges = [h for side in self.support for h in self.ankles.get(side, ())] if self.active else []
        G = np.zeros((2 * len(hinges), self.nv))
        slack = np.zeros(2 * len(hinges))
        q = configuration.q
        for row, hinge in enumerate(hinges):
            lower, upper = self.bounds(hinge)
            G[2 * row, hinge.dof], slack[2 * row] = 1.0, upper - q[hinge.qadr]
            G[2 * row + 1, hinge.dof], slack[2 * row + 1] = -1.0, q[hinge.qadr] - lower
        h = np.where(slack >= 0.0, self.gain * slack, -np.minimum(-self.gain * slack, self.recovery))
        return mink.Constraint(G=G, h=h)


def reserve_limit(
    world: World, feet: Mapping[str, int], soles: Mapping[str, Sequence[int]], sigmas: float
) -> AnkleReserveLimit:
    """The :class:`AnkleReserveLimit` of ``world``'s robot, its reserves measured at the keyframe,
    keeping room for a pelvis shift of ``sigmas`` times the scenario's ``uncertainty.com``.

    Args:
        world: the (estimate) world planned on.
        feet: the foot body id of each side.
        soles: each foot's sole geoms.
        sigmas: the standard deviations of the CoM's uncertainty the pelvis shift keeps room for.
    """
    model, legs = world.model, world.profile.leg_joints
    ankles = find_ankles(model, legs, feet)
    data = mujoco.MjData(model)
    data.qpos[:] = world.home_qpos()
    mujoco.mj_kinematics(model, data)
    cop = balance_reserves(model, data, ankles, feet, legs, soles, world.ids.base_body, 0.0)
    per_metre = balance_reserves(model, data, ankles, feet, legs, soles, world.ids.base_body, 1.0)
    rates = {j: per_metre[j] - cop[j] for j in cop}
    return AnkleReserveLimit(model, ankles, cop, rates, sigmas * world.scenario.uncertainty.com)


def waist_roll(model: mujoco.MjModel, home: FloatArray, base_body: int, waist: Sequence[str]) -> str | None:
    """The waist joint that rolls the torso sideways: the hinge whose axis lies nearest the base's
    forward axis at the keyframe (None: no waist joint is within 45 deg of it)."""
    data = mujoco.MjData(model)
    data.qpos[:] = home
    mujoco.mj_kinematics(model, data)
    forward = data.xmat[base_body].reshape(3, 3)[:, 0]
    best, along = None, float(np.cos(np.pi / 4))
    for name in waist:
        joint = model.joint(name).id
        if model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        cosine = abs(float(data.xaxis[joint] @ forward))
        if cosine > along:
            best, along = name, cosine
    return best
