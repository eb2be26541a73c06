"""Balance feedback on the ankle servos: the measured capture point held on the plan's (ankle strategy).

Position servos alone hold a pose only as stiffly as their gains: on one foot a robot whose
leg servos (in series with the floor contact) are softer than gravity's toppling stiffness
``m g h`` drifts off its plan and tips over the sole's edge. :class:`AnkleBalance` is the
low-level balance loop a humanoid runs under its joint targets: each control period it estimates
the CoM and its velocity as the robot can (its own model's CoM corrected by its feet's force
sensors, :class:`~executive.execution.com_estimate.CoMEstimate`; never the simulation's truth),
compares the capture point with the plan's, and moves the centre of pressure under the feet to
drive the error back, through the ankle servos' targets; on one foot it integrates those targets
until the foot's measured CoP is the commanded one (:class:`~executive.execution.cop_tracking.CoPTracking`).
:class:`executive.execution.simulated.SimulatedRobot` runs it while a stepping behaviour asks for
it (:meth:`~executive.execution.simulated.SimulatedRobot.set_balance`); see docs/stepping.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.execution.com_estimate import CoMEstimate
from executive.execution.cop_tracking import CoPTracking
from executive.planning.balance_law import STEPPING_GAINS, pelvis_shift_offsets
from executive.world.model import World

__all__ = ["AnkleBalance", "BalanceTarget"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BalanceTarget:
    """What the balance feedback holds: the feet on the floor and the planned CoM.

    Attributes:
        support: the feet on the floor (one or two sides of ``profile.feet``).
        com: the planned whole-robot CoM (world x, y, z; m).
        com_velocity: its planned rate (world x, y; m/s).
    """

    support: tuple[str, ...]
    com: FloatArray
    com_velocity: FloatArray


class AnkleBalance:
    """Capture-point feedback on the ankles of the feet on the floor; every gain from the model.

    With ``omega = sqrt(g / h)`` (``h``: the planned CoM's height above the floor) the capture
    point is ``xi = c + c_dot / omega``. The measured one (the robot's estimate of its CoM and
    velocity, :class:`~executive.execution.com_estimate.CoMEstimate`) is taken relative to the
    support feet where they stand, the planned one relative to where the target puts them, so a
    foot that slid a little carries its CoM reference along. The
    centre of pressure moves by ``dp = (1 + convergence) (xi - xi_plan)``: the divergent component
    of motion then decays at ``convergence * omega`` (``xi_dot = omega (xi - p)``; Englsberger et
    al. 2015; ankle strategy, Kajita et al. 2003). A CoP shift under the weight ``m g`` is the ankle
    moment ``m g (-dp_y, dp_x, 0)``, shared by the support feet as the planned CoM puts the weight
    on them (the lever rule between the middles of their soles, from which the CoM is measured,
    weighted by the shares) and sent to each foot's ankle hinges (the two leg joints nearest the
    foot) as target offsets ``(axis . moment) / kp``: the servo's own gain turns them back into
    the moment.

    On two feet the ankles cannot move the CoM (both legs hold the pelvis where their joints put
    it), so there the CoM's error from the plan (relative to the feet, as the capture point's) is
    also integrated at ``integral * omega`` into a shift of the pelvis over the feet: every leg's
    servo targets move its foot by the shift relative to the pelvis (the least-squares joint
    offsets through the leg's Jacobian at the target, the foot's orientation kept). The shift
    persists on one foot (the stance leg holds it; the swing foot, shifted too, still goes where
    it was planned in the world) and is integrated again on two. On one foot the stance ankle's
    offsets also integrate the error between the commanded CoP (the planned CoM's place on the
    sole plus ``dp``) and the foot's measured one (:class:`~executive.execution.cop_tracking.CoPTracking`):
    a servo that gives under the load still presses the CoP the law asks for.

    Args:
        world: the truth world (its model: robot mass, gravity, feet, legs, floor).
        actuators: the servo actuators the offsets are for (their order is the offsets').
        kp: each actuator's position gain (N m/rad).
        convergence: the capture point error's decay rate over ``omega`` (1: it decays at the
            pendulum's own rate).
        integral: the rate over ``omega`` at which the CoM error on two feet shifts the pelvis
            (0: no shift).
        estimate_rate: the rate over ``omega`` at which the CoM estimate follows the error its
            feet's CoP shows.
        cop_rate: the rate over ``omega`` at which the stance ankle's offsets integrate the CoP
            error (0: no CoP tracking).

    Raises:
        ValueError: when a foot has fewer than two servoed leg hinges.
    """

    def __init__(
        self,
        world: World,
        actuators: NDArray[np.int_],
        kp: FloatArray,
        convergence: float = STEPPING_GAINS.convergence,
        integral: float = STEPPING_GAINS.integral,
        estimate_rate: float = STEPPING_GAINS.estimate_rate,
        cop_rate: float = STEPPING_GAINS.cop_rate,
    ) -> None:
        model = world.model
        self.model = model
        self._scratch = mujoco.MjData(model)
        self.base = world.ids.base_body
        self.gravity = float(np.linalg.norm(model.opt.gravity))
        self.weight = world.robot_mass * self.gravity
        self.convergence = convergence
        floor = world.ids.floor_geom
        mujoco.mj_kinematics(model, self._scratch)  # at qpos0: the floor's height
        self.floor_z = float(self._scratch.geom_xpos[floor][2]) if floor >= 0 else 0.0
        self.feet = {side: int(model.body(foot.body).id) for side, foot in world.profile.feet.items()}
        self.soles = {side: list(world.ids.foot_geoms[side]) for side in self.feet}
        servo = {int(model.actuator_trnid[a, 0]): i for i, a in enumerate(actuators)}
        self.kp = np.asarray(kp, dtype=float)
        self.size = len(actuators)
        self.ankles = {side: self._ankle(world, side, body, servo) for side, body in self.feet.items()}
        self.integral = integral
        self.estimate = CoMEstimate(world, estimate_rate)
        self.cop = CoPTracking(world, self.ankles, self.kp, cop_rate)
        self.legs = {
            side: [
                (servo[j], int(model.jnt_dofadr[j]))
                for name in world.profile.leg_joints.get(side, ())
                if (j := int(model.joint(name).id)) in servo
            ]
            for side in self.feet
        }
        self.shift = np.zeros(2)  # the pelvis shift's integral (m, world xy); see offsets()
        self._time: float | None = None
        self._jac = np.zeros((6, model.nv))

    def _ankle(
        self, world: World, side: str, body: int, servo: dict[int, int]
    ) -> tuple[tuple[int, int], ...]:
        """(offset index, joint id) of the two leg hinges nearest the ``side`` foot."""
        model = self.model
        legs = {int(model.joint(name).id) for name in world.profile.leg_joints.get(side, ())}
        found: list[tuple[int, int]] = []
        while body > 0 and len(found) < 2:
            first = int(model.body_jntadr[body])
            for joint in range(first, first + int(model.body_jntnum[body])):
                if joint in legs and joint in servo and len(found) < 2:
                    found.append((servo[joint], joint))
            body = int(model.body_parentid[body])
        if len(found) < 2:
            raise ValueError(f"the {side} foot has {len(found)} servoed leg hinges for its ankle, not two")
        return tuple(found)

    def target(
        self, support: Sequence[str], com: Sequence[float], com_velocity: Sequence[float] | None = None
    ) -> BalanceTarget:
        """A :class:`BalanceTarget`, checked.

        Args:
            support: one or two of the robot's feet (sides of ``profile.feet``).
            com: the planned CoM (world x, y, z).
            com_velocity: its planned rate (world x, y; None: at rest).

        Raises:
            ValueError: when ``support`` names no foot, more than two, or a foot the robot does
                not have, or ``com`` is not three numbers.
        """
        feet = tuple(support)
        if not feet or len(feet) > 2 or len(set(feet)) != len(feet) or set(feet) - set(self.feet):
            raise ValueError(f"balance support {list(feet)} must name one or two of {list(self.feet)}")
        point = np.asarray(com, dtype=float)
        if point.shape != (3,):
            raise ValueError(f"the planned CoM must be a point (x, y, z), not {point.tolist()}")
        rate = np.zeros(2) if com_velocity is None else np.asarray(com_velocity, dtype=float)[:2]
        return BalanceTarget(feet, point, rate)

    def offsets(self, data: mujoco.MjData, q_target: FloatArray, target: BalanceTarget) -> FloatArray:
        """The servo target offsets (rad, in the order of ``actuators``; 0 but on the ankles).

        Args:
            data: the robot's measured state (CoM, its velocity, feet, joint axes).
            q_target: the full-model qpos target the servos follow (where it puts the feet).
            target: the feet on the floor and the planned CoM (:meth:`target`).

        Returns:
            The offsets to add to the servos' ctrl for this control period.
        """
        support = target.support
        d = self._scratch
        d.qpos[:] = q_target
        mujoco.mj_kinematics(self.model, d)
        planned_soles = self._soles(d, support)
        shares = np.ones(1)
        if len(support) == 2:
            a, b = planned_soles
            lever = (target.com[:2] - b) @ (a - b) / max(float((a - b) @ (a - b)), 1e-12)
            shares = np.array([float(np.clip(lever, 0.0, 1.0)), 0.0])
            shares[1] = 1.0 - shares[0]
        omega = math.sqrt(self.gravity / max(float(target.com[2]) - self.floor_z, 1e-3))
        planned = target.com[:2] - shares @ planned_soles + target.com_velocity / omega
        com, velocity = self.estimate.update(data, omega)
        measured = com[:2] - shares @ self._soles(data, support)
        xi = measured + velocity[:2] / omega
        shift = (1.0 + self.convergence) * (xi - planned)
        moment = self.weight * np.array([-shift[1], shift[0], 0.0])
        out = np.zeros(self.size)
        for side, share in zip(support, shares, strict=True):
            for index, joint in self.ankles[side]:
                out[index] = share * float(data.xaxis[joint] @ moment) / self.kp[index]
        dt = self._integrate(data.time, omega, support, measured - (target.com[:2] - shares @ planned_soles))
        if self.integral > 0.0:
            self._shift_pelvis(out)
        if self.cop.rate > 0.0:
            stance = support[0] if len(support) == 1 else None
            cop = target.com[:2] - planned_soles[0] + self._soles(data, support)[0] + shift
            out += self.cop.update(data, stance, cop if stance else None, omega, dt)
        return out

    def _integrate(self, time: float, omega: float, support: Sequence[str], error: FloatArray) -> float:
        """On two feet, add this period's CoM ``error`` (m) to the pelvis shift; a clock that went
        back (a new run) starts it and the CoP tracking from zero. Returns the period (s)."""
        if self._time is None or time < self._time:
            self.shift[:] = 0.0
            self.cop.reset()
            self._time = time
        dt, self._time = min(time - self._time, 0.1), time
        if len(support) == 2:
            self.shift += self.integral * omega * dt * error
        return dt

    def _shift_pelvis(self, out: FloatArray) -> None:
        """Add to ``out`` every leg's joint offsets that move its foot by :attr:`shift` relative to
        the pelvis (the scratch data holds the target's kinematics;
        :func:`~executive.planning.balance_law.pelvis_shift_offsets`)."""
        if not self.shift.any():
            return
        mujoco.mj_comPos(self.model, self._scratch)  # the Jacobians' cdof
        legs = {self.feet[side]: [dof for _, dof in joints] for side, joints in self.legs.items()}
        offsets = pelvis_shift_offsets(self.model, self._scratch, legs, self.shift, self._jac)
        for side, joints in self.legs.items():
            for (index, _), delta in zip(joints, offsets[self.feet[side]], strict=True):
                out[index] += delta

    def _soles(self, data: mujoco.MjData, support: Sequence[str]) -> FloatArray:
        """The middle (xy) of each support foot's sole geoms in ``data``, one row per foot."""
        return np.array([data.geom_xpos[self.soles[side]][:, :2].mean(axis=0) for side in support])
