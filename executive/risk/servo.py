"""Position servos holding a planned pose: the steady-state joint error and where a servo saturates.

A position servo (MuJoCo's ``position`` actuator, force ``kp (ctrl - gear q)`` on a joint of
transmission ``gear``) of stiffness ``k = kp gear^2`` holds its joint ``tau / k`` off its target
under a torque ``tau`` that is not fed forward, and gives at most its force limit. The bundled
robot's servos are fed forward what its own links weigh
(:class:`executive.execution.simulated.JointTargetController`: arm and waist ``qfrc_bias``, legs
the target's static load with the feet sharing the base's weight at least-norm), so what is left
to the stiffness is what that misses: a carried object's weight (it reaches the hand through the
grip's contacts), a target whose feed-forward is clipped at the servo's range (a joint planned at
its limit), and, while the robot moves, the plan's accelerations.

:class:`ServoSet` reads the servos off a world's model; :meth:`ServoSet.hold` solves the static
equilibrium of a pose with the feet fixed on the floor (the joints' stiffness, the feet's
wrenches free: a linear complementarity-free KKT system, the standard compliance analysis of a
closed chain; Siciliano et al., *Robotics*, 2009, 3.8 and 8.4), for any number of external loads
at once.

Usage::

    servos = ServoSet.of(world)
    hold = servos.hold(world.model, qpos, loads)   # loads: (L, nv) generalised forces
    dq = hold.deflection                          # (L + 1, nv): the deficit's, then each load's
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.world.model import World
from executive.world.scratch import scratch_data

__all__ = ["Hold", "ServoSet"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Hold:
    """The static equilibrium of a pose: per right-hand side, the joints' deflection and torques.

    deflection: (L + 1, nv) generalised displacement from the planned pose (base and servoed
        joints; 0 elsewhere): row 0 what the clipped feed-forward leaves, row 1 + i what load i adds
        (linear: a load scaled by ``m`` deflects ``m`` times as much).
    torque: (L + 1, S) each servo's joint torque at that equilibrium (row 0 with the feed-forward
        it gives, rows 1 + i what load i adds).
    limit: (S,) each servo's joint torque limit (N m; inf when it has none).
    room_low, room_high: (S,) how far each servoed joint can move from the planned pose before
        its range stops it (rad; a sum of deflections beyond is held at the limit: :meth:`total`).
    """

    deflection: FloatArray
    torque: FloatArray
    limit: FloatArray
    room_low: FloatArray
    room_high: FloatArray

    def total(self, dofs: NDArray[np.int_], scales: FloatArray) -> FloatArray:
        """The deflection of the deficit plus ``scales[i]`` times load ``i``'s, each servoed joint
        (``dofs``, :attr:`ServoSet.dofs`) held within its range: (nv,) or (N, nv) for (N, L) scales."""
        s = np.asarray(scales, dtype=float)
        dq = self.deflection[0] + s @ self.deflection[1:]
        dq[..., dofs] = np.clip(dq[..., dofs], self.room_low, self.room_high)
        return np.asarray(dq, dtype=float)


class ServoSet:
    """The robot's joint servos (grippers excepted) as a static model: stiffness, limits, feed-forward.

    Attributes:
        dofs: (S,) dof address of each servoed joint; qpos: (S,) its qpos address.
        stiffness: (S,) N m / rad (``kp gear^2``); limit: (S,) N m (inf: unlimited).
        low, high: (S,) the joint targets a servo can be given (its ctrl range over its gear).
        bias: (S,) fed its links' ``qfrc_bias`` (arm, waist); legs: (S,) fed the static leg load;
        arms: (S,) an arm's joint.
        base: the floating base's 6 dofs (empty for a fixed base); feet: the foot bodies.
    """

    def __init__(self, world: World) -> None:
        model = world.model
        grippers = {a for ids in world.ids.gripper_actuators.values() for a in ids}
        named = {name for names in world.profile.leg_joints.values() for name in names}
        legs = {int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)) for n in named}
        arms = {j for ids in world.ids.arm_joints.values() for j in ids}
        waist = {
            int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)) for n in world.profile.waist_joints
        }
        upper = arms | waist
        rows = []
        for a in range(model.nu):
            if a in grippers or model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
                continue
            joint, gear = int(model.actuator_trnid[a, 0]), float(model.actuator_gear[a, 0])
            kp = float(model.actuator_gainprm[a, 0])
            force = np.inf
            if model.actuator_forcelimited[a]:
                force = float(np.max(np.abs(model.actuator_forcerange[a]))) * abs(gear)
            if model.jnt_actfrclimited[joint]:
                force = min(force, float(np.max(np.abs(model.jnt_actfrcrange[joint]))))
            low, high = -np.inf, np.inf
            if model.actuator_ctrllimited[a]:
                low, high = sorted(float(c) / gear for c in model.actuator_ctrlrange[a])
            dof, qadr = int(model.jnt_dofadr[joint]), int(model.jnt_qposadr[joint])
            rows.append(
                (dof, qadr, kp * gear * gear, force, low, high, joint in upper, joint in legs, joint in arms)
            )
        cols = list(zip(*rows, strict=True))
        self.dofs = np.array(cols[0], dtype=int)
        self.qpos = np.array(cols[1], dtype=int)
        self.stiffness, self.limit = np.array(cols[2]), np.array(cols[3])
        self.low, self.high = np.array(cols[4]), np.array(cols[5])
        self.bias, self.legs = np.array(cols[6], dtype=bool), np.array(cols[7], dtype=bool)
        self.arms = np.array(cols[8], dtype=bool)
        free = [
            j
            for j in range(model.njnt)
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
            and int(model.jnt_bodyid[j]) == world.ids.base_body
        ]
        start = int(model.jnt_dofadr[free[0]]) if free else 0
        self.base = np.arange(start, start + 6) if free else np.zeros(0, dtype=int)
        self.feet = [int(model.body(foot.body).id) for foot in world.profile.feet.values()] if free else []

    @classmethod
    def of(cls, world: World) -> ServoSet:
        """The servos of ``world``'s robot."""
        return cls(world)

    def hold(self, model: mujoco.MjModel, qpos: FloatArray, loads: FloatArray) -> Hold:
        """The static equilibrium of the planned pose ``qpos`` under the servos and ``loads``.

        Args:
            model: the world's model (the one :meth:`of` read).
            qpos: the planned full-model configuration (objects included; they are not moved).
            loads: (L, nv) generalised forces on the robot the feed-forward does not know (a
                carried object's weight: ``J^T m g`` at its centre of mass).

        Returns:
            The deflections and torques (:class:`Hold`), linear in the loads. The feet stay where
            the plan has them (their wrenches take up the difference); :meth:`Hold.total` sums
            them and holds a joint at its range.
        """
        with scratch_data(model) as d:
            d.qpos[:] = qpos
            d.qvel[:] = 0.0
            mujoco.mj_kinematics(model, d)
            mujoco.mj_comPos(model, d)
            gravity = np.empty(model.nv)
            mujoco.mj_rne(model, d, 0, gravity)  # at rest: gravity only
            contact = self._feet_jacobian(model, d)
            softening = self._gravity_stiffness(model, d, qpos, gravity, contact) if len(contact) else None
        feed = np.where(self.bias, gravity[self.dofs], 0.0)
        if self.legs.any() and len(contact):
            feed = feed + np.where(self.legs, self._leg_load(gravity, contact)[self.dofs], 0.0)
        target = qpos[self.qpos]
        given = np.clip(target + feed / self.stiffness, self.low, self.high)
        deficit = np.zeros(model.nv)
        deficit[self.dofs] = feed - self.stiffness * (given - target)
        rhs = np.vstack([-deficit[None, :], np.atleast_2d(loads)])
        dq = self._solve(model.nv, contact, rhs, softening)
        torque = -self.stiffness * dq[:, self.dofs]
        torque[0] += self.stiffness * (given - target)
        low, high = self._range(model)
        return Hold(dq, torque, self.limit.copy(), low - target, high - target)

    def _range(self, model: mujoco.MjModel) -> tuple[FloatArray, FloatArray]:
        """The servoed joints' ranges (inf where a joint is not limited)."""
        joints = model.dof_jntid[self.dofs]
        limited = model.jnt_limited[joints].astype(bool)
        low = np.where(limited, model.jnt_range[joints, 0], -np.inf)
        high = np.where(limited, model.jnt_range[joints, 1], np.inf)
        return low, high

    def _feet_jacobian(self, model: mujoco.MjModel, d: mujoco.MjData) -> FloatArray:
        """(6 feet, nv): each foot body's translation and rotation rows (the feet stay put)."""
        rows = np.zeros((6 * len(self.feet), model.nv))
        for i, foot in enumerate(self.feet):
            mujoco.mj_jacBody(model, d, rows[6 * i : 6 * i + 3], rows[6 * i + 3 : 6 * i + 6], foot)
        return rows

    def _leg_load(self, gravity: FloatArray, contact: FloatArray) -> FloatArray:
        """The legs' static load as the bundled servos feed it forward: the feet's least-norm
        wrenches carrying the base, ``g - J_c^T f`` (JointTargetController.leg_loads)."""
        base = contact[:, self.base]
        wrench = np.linalg.lstsq(base.T, gravity[self.base], rcond=None)[0]
        return np.asarray(gravity - contact.T @ wrench, dtype=float)

    def _gravity_stiffness(
        self,
        model: mujoco.MjModel,
        d: mujoco.MjData,
        qpos: FloatArray,
        gravity: FloatArray,
        contact: FloatArray,
    ) -> FloatArray:
        """(nv, nv) d(g - J_c^T f0)/dq on the rows whose feed-forward is fixed at the target (the
        base and the legs): how the body's weight turns as it leans (forward differences, in the
        scratch data ``d``)."""
        base = contact[:, self.base]
        wrench = np.linalg.lstsq(base.T, gravity[self.base], rcond=None)[0]
        eps = 1e-6
        # The base, legs and waist lean the body; an arm's deflection moves the weight on the legs
        # by its own mass times a few centimetres: its columns are left out.
        free = np.concatenate([self.base, self.dofs[~self.arms]])
        out = np.zeros((model.nv, model.nv))
        step = np.zeros(model.nv)
        at = gravity - contact.T @ wrench
        g = np.empty(model.nv)
        for i in free:
            step[:] = 0.0
            step[i] = eps
            d.qpos[:] = qpos
            mujoco.mj_integratePos(model, d.qpos, step, 1.0)
            mujoco.mj_kinematics(model, d)
            mujoco.mj_comPos(model, d)
            mujoco.mj_rne(model, d, 0, g)
            out[:, i] = (g - self._feet_jacobian(model, d).T @ wrench - at) / eps
        out[self.dofs[self.bias]] = 0.0  # fed the gravity of the pose they are in
        d.qpos[:] = qpos
        mujoco.mj_kinematics(model, d)
        return out

    def _solve(
        self, nv: int, contact: FloatArray, rhs: FloatArray, softening: FloatArray | None = None
    ) -> FloatArray:
        """Deflections ``dq`` with ``(K + S) dq - J_c^T df = rhs`` and ``J_c dq = 0`` (feet fixed),
        per row of ``rhs`` (``S``: :meth:`_gravity_stiffness`)."""
        free = np.concatenate([self.base, self.dofs])
        n, c = len(free), len(contact)
        stiffness = np.zeros(n)
        stiffness[len(self.base) :] = self.stiffness
        system = np.zeros((n + c, n + c))
        system[:n, :n] = np.diag(stiffness)
        if softening is not None:
            system[:n, :n] += softening[np.ix_(free, free)]
        if c:
            jac = contact[:, free]
            system[:n, n:] = -jac.T
            system[n:, :n] = jac
        right = np.zeros((n + c, len(rhs)))
        right[:n] = rhs[:, free].T
        solution = np.linalg.lstsq(system, right, rcond=None)[0] if c else np.linalg.solve(system, right)
        dq = np.zeros((len(rhs), nv))
        dq[:, free] = solution[:n].T
        return dq
