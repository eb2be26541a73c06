"""Executing joint targets in the truth world: position servos, gravity feed-forward, detectors.

The behaviours never step physics. Each tick they set targets on a
:class:`SimulatedRobot`; the host then calls :meth:`SimulatedRobot.advance`,
which steps MuJoCo for one control period at the model's timestep, with the
failure detectors' contact check after every physics step and their full check
at the end of the period.
"""

from __future__ import annotations

import time
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.execution.balance import AnkleBalance, BalanceTarget
from executive.monitoring.detectors import Failure, FailureDetector
from executive.world.model import World
from executive.world.observation import SimulatedSensor

__all__ = ["STANCE_MOMENT_LENGTH", "JointTargetController", "SimulatedRobot"]

FloatArray = NDArray[np.float64]

#: m: in a stance of several feet (:meth:`JointTargetController.leg_loads`) a foot's moment costs as
#: much as a force at this lever arm: the feet's vertical forces carry the base, their moments
#: only what the forces cannot.
STANCE_MOMENT_LENGTH = 0.01


def _as_slice(index: NDArray[np.int_]) -> slice | NDArray[np.int_]:
    """``index`` as a slice when it is a contiguous ascending run (numpy then takes a view)."""
    if len(index) and np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        return slice(int(index[0]), int(index[0]) + len(index))
    return index


class JointTargetController:
    """Maps a full-model qpos target to the robot's position-servo ctrl.

    MuJoCo's position actuator applies ``kp (ctrl - q) - kv qdot``; to hold a
    joint at ``q*`` against a static load torque ``tau`` the servo needs
    ``ctrl = q* + tau / kp`` (feed-forward). The static load is
    ``tau = g(q) - J_c^T f`` (``M qacc + bias = tau + J_c^T f`` with ``qacc = 0``):

    * arm and waist joints: ``qfrc_bias`` of the current state, the gravity of the
      links they carry (no contact term: a contact on the arm is not pushed against);
      :meth:`period` holds it over a control period;
    * leg joints: for a floating-base robot ``g`` of a leg joint is only the weight of
      the links *below* it; the body the stance leg carries reaches it through the
      floor's support. The support wrenches ``f`` (one per foot, at the foot body) are
      the least-squares solution of the floating base's equilibrium
      ``J_c,base^T f = g_base`` in the *target* pose, so ``tau_legs = g_legs - J_c,legs^T f``
      is the torque that holds the planned pose without any sag. It is a model-based
      feed-forward (computed once per new target), not a measured one: feeding back the
      measured contact forces would cancel the ankles' stiffness against toppling. A stepping
      behaviour names the feet on the floor (:meth:`leg_loads`' ``stance``): the stance foot
      alone carries the body while the other swings.

    Gripper actuators are left to :meth:`SimulatedRobot.set_gripper`.
    """

    def __init__(self, world: World) -> None:
        model = world.model
        grippers = {a for ids in world.ids.gripper_actuators.values() for a in ids}
        arm_and_waist = {j for ids in world.ids.arm_joints.values() for j in ids}
        for name in world.profile.waist_joints:
            arm_and_waist.add(int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)))
        legs = {
            int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name))
            for names in world.profile.leg_joints.values()
            for name in names
        }
        self.model = model
        self._scratch = mujoco.MjData(model)
        self.feet = [int(model.body(foot.body).id) for foot in world.profile.feet.values()]
        self.foot_sides: tuple[str, ...] = tuple(world.profile.feet)
        self._soles = [list(world.ids.foot_geoms[side]) for side in self.foot_sides]
        free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        base = next(j for j in free if int(model.jnt_bodyid[j]) == world.ids.base_body)
        self.base_dofs = np.arange(int(model.jnt_dofadr[base]), int(model.jnt_dofadr[base]) + 6)
        acts, qadr, dadr, kp, kv, ff, support = [], [], [], [], [], [], []
        for a in range(model.nu):
            if a in grippers or model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
                continue
            joint = int(model.actuator_trnid[a, 0])
            acts.append(a)
            qadr.append(int(model.jnt_qposadr[joint]))
            dadr.append(int(model.jnt_dofadr[joint]))
            kp.append(float(model.actuator_gainprm[a, 0]))
            kv.append(-float(model.actuator_biasprm[a, 2]))  # position servo bias: -kp q - kv qdot
            ff.append(joint in arm_and_waist or joint in legs)
            support.append(joint in legs)
        self.actuators = np.array(acts, dtype=int)
        self.qpos_adr = np.array(qadr, dtype=int)
        self.dof_adr = np.array(dadr, dtype=int)
        self.kp = np.array(kp)
        self.kv = np.array(kv)
        self.feed_forward = np.array(ff, dtype=bool)
        self.support = np.array(support, dtype=bool)
        self._leg_dofs = self.dof_adr[self.support]
        self._kv_over_kp = self.kv / self.kp
        self._bias = self.feed_forward & ~self.support  # arm and waist servos
        self._bias_dofs = self.dof_adr[self._bias]
        self._bias_kp = self.kp[self._bias]
        self._support_kp = self.kp[self.support]
        self._bias_idx = np.flatnonzero(self._bias)
        self._support_idx = np.flatnonzero(self.support)
        self._fixed = np.zeros(len(self.actuators))
        self._ramp_key: tuple[int, float] | None = None
        self._ramp: NDArray[np.floating[Any]] = np.zeros((0, 1))
        # leg_loads' index work: slices where the indices are contiguous (views, no copies)
        self._base_take = _as_slice(self.base_dofs)
        self._leg_take = _as_slice(self._leg_dofs)
        self._support_take = _as_slice(self._support_idx)
        self.ctrl_low = model.actuator_ctrlrange[self.actuators, 0]
        self.ctrl_high = model.actuator_ctrlrange[self.actuators, 1]

    def leg_load(self, q_target: FloatArray, stance: Collection[str] | None = None) -> FloatArray:
        """Static torque of each leg actuator holding ``q_target`` (0 elsewhere): :meth:`leg_loads`
        of the one target.

        Args:
            q_target: a full-model qpos.
            stance: the feet (sides of ``profile.feet``) that carry the body, sharing it as the
                target's CoM puts it on them; None: all feet, the minimum-norm split (see
                :meth:`leg_loads`).

        Returns:
            The torque of each actuator of ``self.actuators`` (N m; 0 but on the legs).
        """
        rows = None if stance is None else [stance]
        return self.leg_loads(np.asarray(q_target, dtype=float)[None, :], rows)[0]

    def leg_loads(
        self, q_targets: FloatArray, stance: Sequence[Collection[str] | None] | None = None
    ) -> FloatArray:
        """:meth:`leg_load` of each row of ``q_targets`` (N, nq): (N, actuators).

        Per target, MuJoCo's gravity torques (``mj_rne`` at rest) and the feet's Jacobians; the
        support wrenches are then the minimum-norm solution of ``A f = g_base`` (``A`` =
        ``J_c,base^T``, 6 x 12, full row rank: each foot's base block is a rigid transform),
        ``f = A^T (A A^T)^-1 g_base`` (what ``numpy.linalg.lstsq`` returns, to rounding), solved
        for all targets in one batch. A stream of targets known ahead
        (:class:`behaviours.move_hand.MoveHand`) asks for half a second of them at once.

        ``stance`` (one entry per target; None: the split above for every target) names the feet
        that carry the body at each target (sides of ``profile.feet``). Their wrenches balance
        the whole base, a foot left out carrying only its own leg's links (its wrench is zero):
        one foot takes all of it; several share it as the target's CoM puts it on them, the
        wrenches with the least foot moments (:data:`STANCE_MOMENT_LENGTH`), each taken about the
        middle of the foot's sole (its ``foot_geoms``' mean): the vertical forces then follow the
        lever rule between the soles' middles, so the load moves onto a foot as the CoM moves
        over its sole, unlike the minimum-norm split, which keeps the forces equal and twists
        the feet against each other. An entry of None is the minimum-norm split above.

        Raises:
            ValueError: when ``stance`` has not one entry per target, or names no foot or a foot
                the robot does not have.
        """
        if stance is not None:
            return self._stance_loads(np.asarray(q_targets, dtype=float), stance)
        q_targets = np.asarray(q_targets, dtype=float)
        n = len(q_targets)
        model, d = self.model, self._scratch
        gravity = np.empty((n, model.nv))
        jac = np.empty((n, 6 * len(self.feet), model.nv))
        d.qvel[:] = 0.0
        for k, q in enumerate(q_targets):
            d.qpos[:] = q
            mujoco.mj_kinematics(model, d)
            mujoco.mj_comPos(model, d)
            mujoco.mj_rne(model, d, 0, gravity[k])  # qvel = 0, no acceleration: gravity only
            for i, foot in enumerate(self.feet):
                mujoco.mj_jacBody(model, d, jac[k, 6 * i : 6 * i + 3], jac[k, 6 * i + 3 : 6 * i + 6], foot)
        base = jac[:, :, self._base_take]  # (N, 12, 6): A^T per target
        g_base = gravity[:, self._base_take]
        normal = np.matmul(base.transpose(0, 2, 1), base)  # A A^T
        try:
            np.linalg.cholesky(normal)  # positive definite: every stance well posed (two feet)
            wrench = np.matmul(base, np.linalg.solve(normal, g_base[:, :, None]))[:, :, 0]
        except np.linalg.LinAlgError:  # a degenerate stance (never on two feet): least squares
            wrench = np.array(
                [np.linalg.lstsq(b.T, g, rcond=None)[0] for b, g in zip(base, g_base, strict=True)]
            )
        loads = np.zeros((n, len(self.dof_adr)))
        legs = jac[:, :, self._leg_take]  # (N, 12, legs)
        loads[:, self._support_take] = (
            gravity[:, self._leg_take] - np.matmul(legs.transpose(0, 2, 1), wrench[:, :, None])[:, :, 0]
        )
        return loads

    def _stance_loads(self, q_targets: FloatArray, stance: Sequence[Collection[str] | None]) -> FloatArray:
        """:meth:`leg_loads` with a ``stance`` per target: the targets on all feet through the
        all-feet batch, each other one with the base wrench on its stance feet alone."""
        if len(stance) != len(q_targets):
            raise ValueError(f"stance has {len(stance)} entries for {len(q_targets)} targets")
        masks = [self._stance_mask(s) for s in stance]
        loads = np.zeros((len(q_targets), len(self.dof_adr)))
        default = [k for k, m in enumerate(masks) if m is None]
        if default:
            loads[default] = self.leg_loads(q_targets[default])
        model, d = self.model, self._scratch
        gravity = np.empty(model.nv)
        jac = np.empty((6 * len(self.feet), model.nv))
        # Weighted least norm: a foot moment (N m) costs as a force (N) at STANCE_MOMENT_LENGTH.
        weight = np.tile([1.0, 1.0, 1.0] + [STANCE_MOMENT_LENGTH**2] * 3, len(self.feet))
        d.qvel[:] = 0.0
        for k, mask in enumerate(masks):
            if mask is None:
                continue
            d.qpos[:] = q_targets[k]
            mujoco.mj_kinematics(model, d)
            mujoco.mj_comPos(model, d)
            mujoco.mj_rne(model, d, 0, gravity)
            for i, foot in enumerate(self.feet):  # each foot's wrench at the middle of its sole
                sole = d.geom_xpos[self._soles[i]].mean(axis=0)
                mujoco.mj_jac(model, d, jac[6 * i : 6 * i + 3], jac[6 * i + 3 : 6 * i + 6], sole, foot)
            rows = np.repeat(mask, 6)
            base = jac[rows][:, self._base_take]  # A^T of the stance feet
            scaled = weight[rows][:, None] * base  # W^-1 A^T
            wrench = scaled @ np.linalg.solve(base.T @ scaled, gravity[self._base_take])
            loads[k, self._support_take] = gravity[self._leg_take] - jac[rows][:, self._leg_take].T @ wrench
        return loads

    def _stance_mask(self, stance: Collection[str] | None) -> NDArray[np.bool_] | None:
        """Which of ``self.feet`` carry the body (None: the default minimum-norm split)."""
        if stance is None:
            return None
        unknown = set(stance) - set(self.foot_sides)
        if unknown or not stance:
            raise ValueError(f"stance {sorted(stance)} must name some of the feet {list(self.foot_sides)}")
        return np.array([side in stance for side in self.foot_sides], dtype=bool)

    def joint_ctrl(
        self,
        q_target: FloatArray,
        data: mujoco.MjData,
        leg_load: FloatArray | None = None,
        qvel_target: FloatArray | None = None,
    ) -> FloatArray:
        """Servo targets for the non-gripper actuators, in the order of ``self.actuators``.

        ``leg_load``: :meth:`leg_load` of ``q_target`` (computed here when not given).
        ``qvel_target``: the target's joint velocity (full-model qpos layout; robot joints are
        hinges and slides): the servo's damping ``kv qdot`` is fed forward as ``kv / kp qdot*``,
        so a joint that follows a moving target does not lag it by ``kv / kp`` seconds.
        """
        ctrl = q_target[self.qpos_adr].copy()
        if qvel_target is not None:
            ctrl += self.kv / self.kp * qvel_target[self.qpos_adr]
        load = np.where(self.support, 0.0, data.qfrc_bias[self.dof_adr])
        load += self.leg_load(q_target) if leg_load is None else leg_load
        ctrl[self.feed_forward] += load[self.feed_forward] / self.kp[self.feed_forward]
        return np.clip(ctrl, self.ctrl_low, self.ctrl_high)

    def period(
        self,
        q_target: FloatArray,
        leg_load: FloatArray,
        qvel_target: FloatArray | None,
        steps: int,
        timestep: float,
        data: mujoco.MjData,
    ) -> ServoPeriod:
        """:meth:`joint_ctrl` for the ``steps`` physics steps of one control period, prepared at once.

        Step ``k`` servos to ``q_target + k timestep qvel_target`` (the ramp); the arm/waist
        feed-forward is ``data.qfrc_bias`` at the start of the period, held for its steps (the
        gravity torque of an arm moving at 1 rad/s changes by about 2 % of itself in a 20 ms
        period; the servo's stiffness takes up the rest). Row ``k`` is bit for bit
        ``joint_ctrl(q_target + k timestep qvel_target, data, leg_load, qvel_target)`` with
        ``data`` as it is now.
        """
        q = q_target[self.qpos_adr]
        if qvel_target is not None:
            v = qvel_target[self.qpos_adr]
            if self._ramp_key != (steps, timestep):
                self._ramp_key = (steps, timestep)
                self._ramp = (np.arange(steps) * timestep)[:, None]
            base = q + self._ramp * v  # (steps, n)
            base += self._kv_over_kp * v
        else:
            base = q[None, :]  # every step the same: one row
        # The arithmetic (operands, order, rounding) of joint_ctrl: legs get the model-based
        # load of the target, arms and waist qfrc_bias, the rest + 0.0 (exact).
        fixed = self._fixed  # zero but for the entries written here
        fixed[self._bias_idx] = data.qfrc_bias[self._bias_dofs] / self._bias_kp
        fixed[self._support_idx] = leg_load[self._support_idx] / self._support_kp
        base += fixed
        ctrl = np.maximum(base, self.ctrl_low, out=base)  # np.clip, without its wrapper
        np.minimum(ctrl, self.ctrl_high, out=ctrl)
        return ServoPeriod(self.actuators, ctrl, moving=qvel_target is not None)


class ServoPeriod:
    """One control period of :class:`JointTargetController`: the servo ctrl of each physics step."""

    def __init__(self, actuators: NDArray[np.int_], ctrl: FloatArray, *, moving: bool) -> None:
        self.actuators = actuators
        self.ctrl = ctrl  # (steps, len(actuators)); a fixed target: one row for all steps
        self.moving = moving  # False: every step's ctrl is row 0

    def write(self, k: int, data: mujoco.MjData) -> None:
        """Servo ctrl of the period's ``k``-th physics step into ``data.ctrl``."""
        data.ctrl[self.actuators] = self.ctrl[k if self.moving else 0]


@dataclass
class StepStats:
    physics_steps: int = 0
    physics_wall_s: float = 0.0


class SimulatedRobot:
    """The truth world driven through its actuators, watched by a :class:`FailureDetector`.

    Args:
        world: the truth world physics runs.
        control_dt: the control period (s) of :meth:`advance`.
        detector: the failure detectors (default: a :class:`FailureDetector` of ``world``).
        sensor: what :meth:`observe_objects` sees (default: the scenario's object uncertainty,
            seeded with ``trials.seed``).
    """

    def __init__(
        self,
        world: World,
        control_dt: float = 0.02,
        detector: FailureDetector | None = None,
        sensor: SimulatedSensor | None = None,
    ) -> None:
        self.world = world
        self.sensor = sensor if sensor is not None else SimulatedSensor(world, world.scenario.trials.seed)
        self.model = world.model
        self.data = world.data
        self.control_dt = control_dt
        self.substeps = max(1, round(control_dt / self.model.opt.timestep))
        self.detector = detector if detector is not None else FailureDetector(world)
        self.controller = JointTargetController(world)
        self.q_target: FloatArray = self.data.qpos.copy()
        self.qvel_target: FloatArray = np.zeros(self.model.nq)
        self._leg_load = self.controller.leg_load(self.q_target)
        self.gripper_ctrl: dict[str, FloatArray] = {}
        self._gripper_idx: dict[str, NDArray[np.intp]] = {}
        for side in world.profile.arms:
            ids = np.array(list(world.ids.gripper_actuators[side]), dtype=np.intp)
            self._gripper_idx[side] = ids
            self.gripper_ctrl[side] = self.data.ctrl[ids].copy()
        self.stats = StepStats()
        self.balance: BalanceTarget | None = None  # the ankle balance feedback's; None: off
        self._balancer: AnkleBalance | None = None

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def failure(self) -> Failure | None:
        return self.detector.failure

    def observe_base(self) -> tuple[FloatArray, FloatArray]:
        """Where the robot measures its base (after a walk): the truth with the sensor's odometry noise."""
        return self.sensor.observe_base()

    def observe_objects(self) -> dict[str, tuple[FloatArray, FloatArray]]:
        """One look at the objects: their truth poses with the sensor's noise (:class:`SimulatedSensor`).

        Returns:
            name -> (position (m), quaternion w x y z) of every object of the scene.
        """
        return self.sensor.observe()

    @property
    def observation_source(self) -> dict[str, object]:
        """Where :meth:`observe_objects` comes from, for the log (the sensor and its sigmas)."""
        return self.sensor.source

    def set_joint_targets(
        self,
        q_target: FloatArray,
        qvel_target: FloatArray | None = None,
        *,
        leg_load: FloatArray | None = None,
    ) -> None:
        """Targets for every robot joint, given as a full-model qpos (object entries ignored).

        ``qvel_target`` (same layout, d q_target / dt): the target moves on at this rate during
        the control period (the servos track a ramp, not a staircase) and the servos' damping
        is fed forward. None: a fixed target.

        ``leg_load``: ``controller.leg_load(q_target)`` if the caller has it already (e.g. from
        :meth:`JointTargetController.leg_loads` over targets known ahead); None: computed here
        for a new target.
        """
        q = np.asarray(q_target, dtype=float)
        old = self.q_target
        if leg_load is not None:
            self._leg_load = leg_load
        elif q.shape != old.shape or not (q == old).all():  # np.array_equal, without its wrapper
            self._leg_load = self.controller.leg_load(q)
        self.q_target = q
        self.qvel_target = np.zeros(self.model.nq) if qvel_target is None else np.asarray(qvel_target, float)

    def set_balance(
        self,
        support: Sequence[str] | None,
        com: Sequence[float] | None = None,
        com_velocity: Sequence[float] | None = None,
    ) -> None:
        """Switch the ankle balance feedback (:class:`AnkleBalance`) on the ``support`` feet, or off.

        While on, every control period moves the support feet's ankle servo targets so that the
        measured capture point follows the planned one (the CoP under the feet shifts to drive
        the error back); a stepping behaviour sets it each tick with its plan's CoM and switches
        it off when the step ends. Off (None, the default, and after :meth:`hold`): the plain
        servos, exactly as without it.

        Args:
            support: the feet on the floor (one or two sides of ``profile.feet``), or None: off.
            com: the planned whole-robot CoM now (world x, y, z; m); needed with ``support``.
            com_velocity: its planned rate (world x, y; m/s; None: at rest).

        Raises:
            ValueError: when ``support`` names no foot, more than two, or an unknown one, or
                ``com`` is missing or not a point.
        """
        if support is None:
            self.balance = None
            return
        if com is None:
            raise ValueError("the balance feedback needs the planned CoM (com=)")
        if self._balancer is None:
            c = self.controller
            self._balancer = AnkleBalance(self.world, c.actuators, c.kp)
        self.balance = self._balancer.target(support, com, com_velocity)

    def set_gripper(self, side: str, closed: bool) -> None:
        grip = self.world.profile.arms[side].gripper
        self.gripper_ctrl[side] = np.array(grip.closed if closed else grip.open, dtype=float)

    def gripper_opening(self, side: str) -> float:
        """Mean absolute position of the gripper's actuated joints (0 = closed for the humanoid)."""
        joints = self.model.actuator_trnid[list(self.world.ids.gripper_actuators[side]), 0]
        return float(np.mean(np.abs(self.data.qpos[self.model.jnt_qposadr[joints]])))

    def hold(self) -> None:
        """Safe hold: servo every joint to where it is now (the balance feedback off)."""
        self.balance = None
        self.q_target = self.data.qpos.copy()
        self.qvel_target = np.zeros(self.model.nq)
        self._leg_load = self.controller.leg_load(self.q_target)

    def advance(self) -> Failure | None:
        """Step physics for one control period; stop early at the first detected failure.

        The detectors look at the contacts after every physics step
        (:meth:`FailureDetector.check_contacts`) and at the whole state after the period's last
        step (:meth:`FailureDetector.check`). The servo targets are those of
        :meth:`JointTargetController.joint_ctrl` for each step (the target ramps on at
        ``qvel_target``; the arm/waist gravity feed-forward is ``qfrc_bias`` at the start of the
        period), all computed at once (:meth:`JointTargetController.period`); a fixed target
        writes them once. With the balance feedback on (:meth:`set_balance`) its ankle offsets of
        the period's start are added to every step's targets.
        """
        data, model = self.data, self.model
        start = time.perf_counter()
        moving = bool(self.qvel_target.any())
        servo = self.controller.period(
            self.q_target,
            self._leg_load,
            self.qvel_target if moving else None,
            self.substeps,
            model.opt.timestep,
            data,
        )
        if self.balance is not None and self._balancer is not None:
            self._add_balance(servo, self._balancer.offsets(data, self.q_target, self.balance))
        ctrl = data.ctrl
        for side, values in self.gripper_ctrl.items():  # fixed over the period
            ctrl[self._gripper_idx[side]] = values
        acts, rows = servo.actuators, servo.ctrl
        ctrl[acts] = rows[0]
        check_contacts = self.detector.check_contacts
        steps, last = 0, self.substeps - 1
        for k in range(self.substeps):
            if k and moving:
                ctrl[acts] = rows[k]
            mujoco.mj_step(model, data)
            steps += 1
            if (check_contacts() if k < last else self.detector.check()) is not None:
                self.hold()
                break
        self.stats.physics_steps += steps
        self.stats.physics_wall_s += time.perf_counter() - start
        return self.detector.failure

    def _add_balance(self, servo: ServoPeriod, offsets: FloatArray) -> None:
        """Add the ankle balance offsets (of this period's start) to every step's servo targets."""
        c = self.controller
        servo.ctrl = np.clip(servo.ctrl + offsets, c.ctrl_low, c.ctrl_high)
