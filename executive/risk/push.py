"""Push risk: the force a push needs, what the arm makes of it, and what the robot feels.

A push step (:class:`executive.planning.plan.Step` with ``force``) slides an object by Coulomb
friction: the hand must exert ``F = mu m g`` (:func:`executive.tasks.push.push_force`). The
truth's mass and friction factors (``uncertainty.object_mass``, ``uncertainty.friction``, each
``max(0.2, 1 + s z)`` as the truth sampler draws them) scale it
(:func:`executive.risk.fall.force_scale_distribution`).

* The arm: every arm and waist actuator must supply ``tau = g(q) + J^T F u`` (quasi-static;
  ``J`` the hand site's translational Jacobian, MuJoCo ``mj_jacSite``; ``g`` the gravity
  torques, ``qfrc_bias`` at rest) within its ``actuator_forcerange``: beyond
  :func:`arm_force_capacity` it saturates. Before that, position servos yield: the whole body
  on its two feet gives way ``c F`` at the hand (:func:`hand_compliance`, from the servos'
  ``kp``), so the hand stops the object ``c F`` short of the target.
* Placement (the push's drop mode, :func:`assess_placement`): short by more than the place
  tolerance, or saturated, it fails; otherwise the object's position error across the push
  stays in it (along the push the hand meets it wherever it is).
* Balance: the robot feels the push's force up to where a stalled push ends, when its move
  gives up with the hand lagging between the move's tolerance and that plus a push leg
  (uniform between :attr:`PushLimits.felt_low` and :attr:`PushLimits.felt`); its reaction moves
  the zero-moment point (:func:`executive.risk.fall.zero_moment_points`) and the CoM gives way
  with it (:func:`yielding`), per knot in the fall model
  (:class:`executive.risk.fall.ExternalForce`, from :func:`plan_forces`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.timing import Trajectory
from executive.risk.fall import ExternalForce, force_scale_distribution
from executive.risk.gaussian import normal_cdf
from executive.risk.push_contact import face_contact
from executive.risk.report import RiskReport
from executive.schema.types import RiskConfig, Uncertainty
from executive.world.model import World


class AlternativePlan(Protocol):
    """What the push risk reads of a planned alternative (``planning.plan.AlternativePlan``)."""

    @property
    def name(self) -> str: ...

    @property
    def steps(self) -> tuple[Any, ...]: ...  # executive.planning.plan.Step: kind, side, force

    @property
    def trajectories(self) -> Mapping[str, Trajectory]: ...


__all__ = [
    "CONTACT_GAP",
    "GAP_SIGMAS",
    "HAND_TOLERANCE",
    "AlternativePlan",
    "PushLimits",
    "arm_force_capacity",
    "assess_placement",
    "descent_gap",
    "hand_compliance",
    "plan_forces",
    "push_limits",
    "yielding",
]

FloatArray = NDArray[np.float64]
#: m the hand stops behind the object's face before it pushes at least (the planner's 2 cm
#: clearance is waived for the pushed object, so the gap is what keeps the descent off it).
CONTACT_GAP = 0.01
#: The gap is at least this many sigmas of the object's position error (``uncertainty.object_position``):
#: an object nearer than its estimate by more than the gap is landed on (:func:`descent_gap`).
GAP_SIGMAS = 3.0
#: m: a hand further than this from its planned end fails its move (behaviours.move_hand.MoveHand's
#: default tolerance): a push whose hand lags more stalls there.
HAND_TOLERANCE = 0.03


def _arm_dofs(world: World, side: str) -> tuple[NDArray[np.int_], FloatArray]:
    """The dofs of ``side``'s arm and the waist that carry a hand force, and their torque limits (N m)."""
    model = world.model
    joints = set(world.ids.arm_joints[side])
    for name in world.profile.waist_joints:
        joints.add(int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)))
    dofs, limits = [], []
    for a in range(model.nu):
        joint = int(model.actuator_trnid[a, 0])
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or joint not in joints:
            continue
        gear = abs(float(model.actuator_gear[a, 0])) or 1.0
        limit = (
            float(np.max(np.abs(model.actuator_forcerange[a]))) if model.actuator_forcelimited[a] else np.inf
        )
        dofs.append(int(model.jnt_dofadr[joint]))
        limits.append(limit * gear)
    return np.array(dofs, dtype=int), np.array(limits)


def descent_gap(world: World) -> float:
    """m between the hand's face and the object's estimated face as the hand comes down behind it."""
    return max(CONTACT_GAP, GAP_SIGMAS * world.scenario.uncertainty.object_position)


def arm_force_capacity(world: World, side: str, qpos: FloatArray, direction: FloatArray) -> float:
    """Largest force (N) ``side``'s hand can exert along the unit ``direction`` in ``qpos``, holding still.

    Every arm and waist actuator must supply ``g_j + F (J^T u)_j`` within its force range.

    Args:
        world: the world whose model ``qpos`` indexes.
        side: the arm.
        qpos: the configuration.
        direction: unit vector (world) of the force the hand exerts.

    Returns:
        N; inf for a robot whose actuators are not force-limited.
    """
    model = world.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, world.ids.hand_sites[side])
    dofs, limits = _arm_dofs(world, side)
    lever = jac[:, dofs].T @ np.asarray(direction, dtype=float)
    gravity = data.qfrc_bias[dofs]
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(lever > 0.0, (limits - gravity) / lever, (limits + gravity) / -lever)
    bound = bound[np.abs(lever) > 1e-9]
    return float(max(0.0, np.min(bound))) if bound.size else float("inf")


def hand_compliance(world: World, side: str, qpos: FloatArray, direction: FloatArray) -> float:
    """m/N: how far ``side``'s hand yields along the unit ``direction`` per newton it pushes there
    (:func:`yielding`'s first value)."""
    return yielding(world, side, qpos, direction)[0]


def yielding(world: World, side: str, qpos: FloatArray, direction: FloatArray) -> tuple[float, FloatArray]:
    """How the standing robot gives way per newton its ``side`` hand pushes along ``direction``.

    The robot stands on both feet (held fixed) and holds its pose with position servos of stiffness
    ``kp`` (``actuator_gainprm``, times the gear squared): the quasi-static deflection ``dq`` under
    the reaction ``-f u`` at the hand minimises ``dq^T K dq / 2 + f u^T J_h dq`` subject to
    ``J_feet dq = 0`` (the KKT system over the robot's dofs; the floating base has no stiffness of
    its own, the legs carry it).

    Args:
        world: the world whose model ``qpos`` indexes.
        side: the arm.
        qpos: the configuration.
        direction: unit vector (world) of the force the hand exerts.

    Returns:
        The hand's compliance along ``direction`` (m/N, ``-u^T J_h dq / f``) and the CoM's
        displacement per newton (3,) (m/N, ``J_com dq / f``: against the push).
    """
    model = world.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    objects = {
        int(model.jnt_dofadr[model.body_jntadr[b]]) + k
        for b in world.ids.object_bodies.values()
        for k in range(6)
    }
    dofs = np.array([i for i in range(model.nv) if i not in objects], dtype=int)
    stiffness = np.zeros(model.nv)
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            dof = int(model.jnt_dofadr[int(model.actuator_trnid[a, 0])])
            stiffness[dof] += float(model.actuator_gainprm[a, 0]) * float(model.actuator_gear[a, 0]) ** 2
    hand = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, hand, None, world.ids.hand_sites[side])
    feet = []
    for foot in world.profile.feet.values():
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacBody(model, data, jacp, jacr, int(model.body(foot.body).id))
        feet += [jacp, jacr]
    constraint = np.vstack(feet)[:, dofs]
    n, c = len(dofs), len(constraint)
    kkt = np.zeros((n + c, n + c))
    kkt[:n, :n] = np.diag(stiffness[dofs])
    kkt[:n, n:], kkt[n:, :n] = constraint.T, constraint
    u = np.asarray(direction, dtype=float)
    rhs = np.concatenate([hand[:, dofs].T @ -u, np.zeros(c)])
    dq = np.linalg.lstsq(kkt, rhs, rcond=None)[0][:n]
    com = np.zeros((3, model.nv))
    mujoco.mj_jacSubtreeCom(model, data, com, world.ids.base_body)
    return float(-u @ hand[:, dofs] @ dq), np.asarray(com[:, dofs] @ dq, dtype=float)


@dataclass(frozen=True)
class PushLimits:
    """What one push's hand can do (the worst over its pushing knots).

    ``saturation``: N before an arm or waist actuator saturates (:func:`arm_force_capacity`);
    ``compliance``: m/N the hand yields (:func:`hand_compliance`); ``leg``: m, the longest push
    motion (the hand's target runs that far ahead before the move checks where the hand is).
    """

    saturation: float
    compliance: float
    leg: float
    com_yield: FloatArray  # (3,) m/N: the CoM's give (:func:`yielding`), the largest of the knots'

    def placed(self, tolerance: float) -> float:
        """N up to which the object ends within ``tolerance`` (m) of its target: it stops ``c F`` short."""
        return min(self.saturation, tolerance / self.compliance)

    @property
    def felt(self) -> float:
        """N the robot can feel at most: the hand lags at most a leg plus the move's tolerance."""
        return min(self.saturation, (HAND_TOLERANCE + self.leg) / self.compliance)

    @property
    def felt_low(self) -> float:
        """N of the least force a stalled push ends at: the move gives up past its tolerance.

        A stall's force is taken uniform between this and :attr:`felt` (where in its last leg the
        hand's lag passes the tolerance)."""
        return min(self.saturation, HAND_TOLERANCE / self.compliance)


def push_limits(world: World, plan: AlternativePlan) -> PushLimits | None:
    """The :class:`PushLimits` of ``plan``'s push steps (None: it pushes nothing)."""
    saturation, compliance, leg, com_yield = np.inf, 0.0, 0.0, np.zeros(3)
    for step in plan.steps:
        traj = plan.trajectories.get(step.name)
        if traj is None or step.kind != "push" or step.force is None or not np.any(step.force):
            continue
        u = np.asarray(step.force, dtype=float) / float(np.linalg.norm(step.force))
        path = np.asarray(traj.hand_paths[step.side], dtype=float)
        leg = max(leg, float(np.linalg.norm(path[-1] - path[0])))
        for q in (traj.qpos[0], traj.qpos[-1]):
            saturation = min(saturation, arm_force_capacity(world, step.side, q, u))
            give, com = yielding(world, step.side, q, u)
            compliance = max(compliance, give)
            com_yield = com if np.linalg.norm(com) > np.linalg.norm(com_yield) else com_yield
    return PushLimits(saturation, compliance, leg, com_yield) if compliance > 0.0 else None


def plan_forces(world: World, plan: AlternativePlan, uncertainty: Uncertainty) -> ExternalForce | None:
    """The hand forces of ``plan``'s push steps per knot of its concatenated trajectory (None: none).

    Knot order as :func:`executive.decision.assessment.concatenate` (each step after the first
    drops its repeated start knot). ``limit``: the most the robot can feel (:attr:`PushLimits.felt`).
    """
    limits = push_limits(world, plan)
    if limits is None:
        return None
    forces: list[FloatArray] = []
    points: list[FloatArray] = []
    yields: list[FloatArray] = []
    for step in plan.steps:
        traj = plan.trajectories.get(step.name)
        if traj is None:
            continue
        skip = 1 if forces else 0
        count = len(traj.times) - skip
        pushing = step.kind == "push" and step.force is not None
        force = np.asarray(step.force if pushing else (0.0, 0.0, 0.0), dtype=float)
        forces.append(np.tile(force, (count, 1)))
        yields.append(np.tile(limits.com_yield if pushing else np.zeros(3), (count, 1)))
        points.append(np.asarray(traj.hand_paths[step.side], dtype=float)[skip:])
    return ExternalForce(
        np.concatenate(forces),
        np.concatenate(points),
        mass_sigma=uncertainty.object_mass,
        friction_sigma=uncertainty.friction,
        limit=limits.felt,
        limit_low=limits.felt_low,
        com_yield=np.concatenate(yields),
    )


def assess_placement(
    world: World,
    plan: AlternativePlan,
    external: ExternalForce,
    risk_config: RiskConfig,
    uncertainty: Uncertainty,
    tolerance: float,
) -> RiskReport:
    """The drop mode of a push: P(the object does not end within ``tolerance`` (m) of its target).

    ``tolerance``: the failure detectors' ``place_position_tol``.

    Along the push the hand meets the object wherever it is, so its position error there is
    absorbed; the object stops ``c F`` short (``c`` the hand's compliance) and stalls once
    ``F`` exceeds the arm's saturation. Across the push its error ``e ~ N(0, s^2)`` (``s`` the
    scene's ``object_position``) stays: per force scale node, P = 1 if stalled, else
    ``P(|e| > tol - c F) = 2 Phi(-(tol - c F) / s)``; averaged over the nodes' weights. And the
    hand comes down ``gap`` behind the estimated face (:func:`descent_gap`): an
    object nearer by more is landed on, ``Phi(-gap / s)``, independent of the rest. And the
    planned hand must stay on the object's face along the push
    (:func:`executive.risk.push_contact.face_contact`), independent of the rest too.

    Returns:
        The report (mode ``grasp``, the drop mode's name in the combination); details: the
        nominal force, the arm's limits, how short the object stops, the stall's share, how the
        planned hand keeps to the face.
    """
    limits = push_limits(world, plan)
    if limits is None:
        raise ValueError(f"assess_placement: plan '{plan.name}' pushes nothing")
    nodes, weights = force_scale_distribution(external.mass_sigma, external.friction_sigma)
    needed = float(np.max(np.linalg.norm(external.force, axis=1)))
    force = nodes * needed
    room = tolerance - limits.compliance * force
    sigma = float(uncertainty.object_position)
    if sigma > 0.0:
        across = 2.0 * normal_cdf(-np.maximum(room, 0.0) / sigma)
    else:
        across = np.zeros_like(room)
    stalled = (force > limits.saturation) | (room <= 0.0)
    # Nearer than estimated by more than the descent's gap, the object is landed on.
    landed = float(normal_cdf(-descent_gap(world) / sigma)) if sigma > 0.0 else 0.0
    contact = face_contact(world, plan, uncertainty)
    lost = contact.probability if contact is not None else 0.0
    kept = (1.0 - landed) * (1.0 - lost)
    probability = 1.0 - kept * (1.0 - float(np.sum(weights * np.where(stalled, 1.0, across))))
    details: dict[str, float | str] = {
        "grasp": "none: a push",
        "push_force": needed,
        "arm_saturation_force": limits.saturation,
        "hand_stiffness": 1.0 / limits.compliance,
        "placed_force_limit": limits.placed(tolerance),
        "felt_force_limit": limits.felt,
        "short_by": limits.compliance * needed,
        "stall_probability": float(np.sum(weights[stalled])),
        "landing_probability": landed,
        **(contact.details() if contact is not None else {}),
        "drop_reason": _drop_reason(bool(np.any(stalled & (weights > 0.0))), lost),
    }
    severity = float(risk_config.severity.drop)
    return RiskReport("drop", probability, (probability, probability), severity, probability, details=details)


def _drop_reason(stalled: bool, lost: float) -> str:
    if lost >= 0.5:
        return "the planned hand leaves the object's face: it passes over or past the object"
    if stalled:
        return "the push falls short: the hand yields or stalls behind the object"
    return "the object's position error across the push"
