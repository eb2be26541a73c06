"""Risk of whole alternatives: plan each on the estimate, assess every failure mode, combine.

Per alternative:

* collision: every motion step is profiled with coal (with its own allowances:
  the hand may touch the object it grasps, the object its support while lifted
  or placed); the first-order probability is taken over the union of all knots
  of all steps, with one static pose error per body for the whole alternative
  (as a truth world draws it), and the seed score over the concatenated
  distance profile;
* fall: the alternative's steps concatenated into one trajectory; the CoM error
  is one persistent bias, so its probability is exact over all knots;
* drop: the first grasp of the object from the table, against
  the scene's object pose uncertainty (a handover's second grasp takes the object
  from a hand whose pose the robot knows; it is not scored here): the jaws must clear the
  object's sides all the way down the planned approach (offset and yaw jointly), and the
  placement it leads to: the jaws centre the object across them, but its error
  along them stays in the hand and lands on the target, where the failure
  detector calls it misplaced beyond ``place_position_tol`` (see :func:`_grasp`);
  its union with the hold risk (:mod:`executive.risk.hold`: a grip that slips under
  the object's weight and the plan's accelerations, or a handover receiver that
  misses an object turned in the giver's jaws) is the drop mode (:func:`drop_union`);
* combined: :func:`executive.risk.combine.combine`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import mujoco
import numpy as np

from executive.decision.risk_models import PlanContext, register_model, risk_model
from executive.monitoring.detectors import DetectorThresholds
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner, PlanningError, Trajectory
from executive.planning.timing import concatenate
from executive.risk.collision import CollisionModel, CollisionProfile, KnotDistance, report_from_profile
from executive.risk.combine import CombinedRisk, combine
from executive.risk.fall import assess_fall
from executive.risk.fall_balance import walk_phases
from executive.risk.grasp import (
    GraspTolerance,
    approach_envelope,
    assess_grasp,
    grasp_error,
    grasp_tolerance,
    hand_pose_at,
)
from executive.risk.hold import assess_hold
from executive.risk.pinch import closing_shift, horizontal_shift, placement_tolerance
from executive.risk.press import press_forces
from executive.risk.push import assess_placement, plan_forces
from executive.risk.report import RiskReport
from executive.schema.failure_modes import mode_names
from executive.tasks.base import Alternative, Task
from executive.tasks.registry import get as task_kind
from executive.tasks.steps import plan_alternative
from executive.world.model import World

__all__ = ["AlternativeRisk", "assess_plan", "assess_task", "concatenate", "drop_union"]


@dataclass(frozen=True)
class AlternativeRisk:
    """One alternative of a task: its plan (if feasible) and its risk."""

    name: str
    feasible: bool
    risk: CombinedRisk | None
    plan: AlternativePlan | None
    error: str = ""
    plan_s: float = 0.0
    assess_s: float = 0.0
    physics: dict[str, Any] | None = None  # the physics check's summary (executive.decision.physics_check)


def _collision_model(ctx: PlanContext) -> RiskReport:
    """The collision mode: one distance profile through every motion step, each with its own allowances."""
    model, plan = ctx.collision_model, ctx.plan
    obj = plan.task.object
    times: list[np.ndarray] = []
    knots: list[KnotDistance] = []
    offset = 0.0
    for step in plan.steps:
        traj = plan.trajectories.get(step.name)
        if traj is None:
            continue
        allow = model.step_allow(step.side, step.kind, obj, step.allow_contact, traj.carried)
        profile = model.profile(traj, allow=allow)
        times.append(profile.times + offset)
        knots.extend(profile.knots)
        offset += traj.duration
    return report_from_profile(model, CollisionProfile(np.concatenate(times), tuple(knots)))


def assess_plan(world: World, plan: AlternativePlan, collision_model: CollisionModel) -> CombinedRisk:
    """Every failure mode's risk of a planned alternative (its registered model), and their combination."""
    scenario = world.scenario
    whole = concatenate(plan.ordered_trajectories(), plan.name)
    pushes = plan_forces(world, plan, scenario.uncertainty)  # the reaction of a push moves the ZMP
    external = pushes if pushes is not None else press_forces(plan)  # or a press's
    context = PlanContext(world, plan, collision_model, whole, pushes, external)
    return combine([risk_model(mode)(context) for mode in mode_names()], scenario.risk, plan.duration)


def _fall_model(ctx: PlanContext) -> RiskReport:
    """The fall mode: the CoM against the support polygon over the whole plan (:mod:`executive.risk.fall`),
    the walks' knots as the balance feedback leaves the CoM error (:mod:`executive.risk.fall_balance`)."""
    scenario = ctx.world.scenario
    walks = walk_phases(ctx.plan)
    return assess_fall(ctx.world, ctx.whole, scenario.risk, scenario.uncertainty, ctx.external, walks)


def _drop_model(ctx: PlanContext) -> RiskReport:
    """The drop mode: a push falling short; else the grasps off the table (or a placement from
    the hand) united with the hold model (:func:`drop_union`)."""
    world, plan, scenario = ctx.world, ctx.plan, ctx.world.scenario
    grasp_step = next((s for s in plan.steps if s.kind == "grasp"), None)
    if ctx.pushes is not None and grasp_step is None:  # a push holds nothing: its drop mode is falling short
        tol = DetectorThresholds().place_position_tol
        return assess_placement(world, plan, ctx.pushes, scenario.risk, scenario.uncertainty, tol)
    if grasp_step is None:  # the object is in hand from the start (a place) or never taken
        grasp = _placed_from_hand(world, plan)
    else:
        # Every grasp that takes the object off the table (a regrasp takes it twice); a
        # handover's grasp in the air is the hold model's.
        grasps = [_table_grasp(world, plan, i) for i, s in enumerate(plan.steps) if _off_table(plan, i)]
        grasp = _union(grasps)
    hold = assess_hold(world, plan, scenario.risk, scenario.uncertainty)
    return drop_union(grasp, hold)


def _off_table(plan: AlternativePlan, i: int) -> bool:
    """Whether step ``i`` is a grasp of an object no hand carries then (it lies on the table)."""
    step = plan.steps[i]
    if step.kind != "grasp":
        return False
    before = [s for s in plan.steps[:i] if s.side == step.side and s.name in plan.trajectories]
    return bool(before) and before[-1].carried is None


def _table_grasp(world: World, plan: AlternativePlan, i: int) -> RiskReport:
    """The grasp risk of step ``i``: the jaws down its side's moves onto the object, and the place after."""
    step = plan.steps[i]
    moves = [s for s in plan.steps[:i] if s.side == step.side and s.name in plan.trajectories]
    places = any(s.kind == "place" for s in plan.steps[i:])
    down = np.concatenate([plan.trajectories[s.name].qpos for s in moves])
    obj = plan.task.object
    # Set down earlier in the plan (a regrasp): it lies where the last carry left it.
    carries = [s for s in plan.steps[:i] if s.carried is not None and s.carried[1] == obj]
    carries = [s for s in carries if s.name in plan.trajectories]
    if carries:
        world = _with_object_at(world, obj, plan.trajectories[carries[-1].name].qpos[-1])
    return _grasp(world, step.side, obj, plan.trajectories[moves[-1].name], down, places=places)


def _with_object_at(world: World, obj: str, qpos: np.ndarray) -> World:
    """A view of ``world`` with its own MuJoCo data, ``obj`` where ``qpos`` has it (the rest as is)."""
    data = mujoco.MjData(world.model)
    data.qpos[:] = world.data.qpos
    adr = world.ids.object_qpos[obj]
    data.qpos[adr : adr + 7] = qpos[adr : adr + 7]
    mujoco.mj_kinematics(world.model, data)
    return replace(world, data=data)


def _union(reports: list[RiskReport]) -> RiskReport:
    """Failure of any of independent ``reports`` of one mode: 1 - prod(1 - p); the first's details."""
    if len(reports) == 1:
        return reports[0]
    p = 1.0 - float(np.prod([1.0 - r.probability for r in reports]))
    lower = max(r.probability_bounds[0] for r in reports)
    upper = min(1.0, sum(r.probability_bounds[1] for r in reports))
    details = {**reports[0].details, "grasps": float(len(reports))}
    return replace(reports[0], probability=p, probability_bounds=(lower, upper), details=details)


def drop_union(grasp: RiskReport, hold: RiskReport) -> RiskReport:
    """The drop mode: the grasp (pose) failure or the hold (mass, friction) failure.

    probability: 1 - (1 - p_grasp)(1 - p_hold), as if independent (the pose error and the
    mass are drawn independently; the lateral error enters both, so the Fréchet bounds
    max(p) <= P <= min(1, sum p) are kept as the bounds). details: the grasp's, the hold's, and
    ``drop_reason`` naming the likelier of the two.
    """
    pg, ph = grasp.probability, hold.probability
    lower = max(grasp.probability_bounds[0], hold.probability_bounds[0])
    upper = min(1.0, grasp.probability_bounds[1] + hold.probability_bounds[1])
    details = {**grasp.details, **hold.details, "grasp_probability": pg, "hold_probability": ph}
    details["drop_reason"] = "hold: the grip slips or a handover's receiver misses" if ph > pg else "grasp"
    return replace(
        grasp,
        mode="drop",
        probability=1.0 - (1.0 - pg) * (1.0 - ph),
        probability_bounds=(lower, upper),
        details=details,
    )


def _placed_from_hand(world: World, plan: AlternativePlan) -> RiskReport:
    """The drop mode's share of a plan that takes no grasp: misplacing an object held from the start.

    The hand puts the object down where the estimate's grip (the object's pose in the hand,
    :attr:`World.grips`, the mean of ``looks`` observations of 1-sigma ``object_position`` per
    horizontal axis) says it is; the grip's error lands on the target. Beyond the detector's
    ``place_position_tol`` in the table plane it is misplaced: for an isotropic 2-D Gaussian
    error, P(|e| > tol) = exp(-tol^2 / (2 sigma^2 / looks)) (the Rayleigh distribution's tail).
    A plan that places nothing: 0.
    """
    severity = world.scenario.risk.severity.drop
    if not any(s.kind == "place" for s in plan.steps):
        return RiskReport("drop", 0.0, (0.0, 0.0), severity, 0.0, details={"grasp": "none"})
    grip = getattr(world, "grips", {}).get(plan.task.object)
    looks = max(1, int(getattr(grip, "looks", 1)))
    sigma = world.scenario.uncertainty.object_position / np.sqrt(looks)
    tol = DetectorThresholds().place_position_tol
    p = float(np.exp(-(tol**2) / (2 * sigma**2))) if sigma > 0 else 0.0
    details: dict[str, float | str] = {"grasp": "none: held from the start", "grip_looks": float(looks)}
    details["misplace_probability"] = p
    return RiskReport("drop", p, (p, p), severity, p, details=details)


def _grasp(
    world: World,
    side: str,
    obj: str,
    approach: Trajectory,
    path: np.ndarray,
    *,
    places: bool = True,
) -> RiskReport:
    """Grasp risk measured from the grasp point the plan intends, not the object's centre.

    A handover grasps the object off-centre on purpose; that planned offset is no error,
    but it uses up part of the geometric tolerance along the same axis.

    The object's error along the jaws (the lateral axis) is not corrected by closing them:
    the hand carries it to the target, so the object rests that far from it. The drop
    mode's failures include a placement beyond the failure detector's
    ``place_position_tol``; the same error ``e`` fails the grasp when ``|e|`` exceeds the
    lateral tolerance, so the union of the two is ``|e| > min(lateral, place_position_tol)``
    (exact: nested events of one Gaussian, not a bound). A thumb-against-fingers hand holds
    the object off its site across the jaws (:func:`executive.risk.pinch.closing_shift`); that
    shift's table-plane part ``mu`` lands on the target too, and the placement's bound on
    ``|e|`` becomes sqrt(place_position_tol^2 - mu^2) (:func:`executive.risk.pinch.placement_tolerance`;
    slide jaws: mu = 0). ``places`` False (a pick that keeps the object): no placement, the
    lateral tolerance is the grasp's own.

    Across the jaws, the hand must clear the object's sides all the way down, not only at
    the grasp pose: ``path`` (the grasping hand's poses before the grasp, e.g. its pre-grasp
    and approach knots) gives the envelope its geoms sweep below the object's top
    (:func:`executive.risk.grasp.approach_envelope`), and the offset and yaw errors are
    scored jointly against it (:func:`executive.risk.grasp.approach_miss_probability`).
    """
    scenario = world.scenario
    hand_pos, hand_rot = hand_pose_at(world, approach, side)
    obj_pos, obj_quat = world.object_pose(obj)
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, obj_quat)
    planned = grasp_error(hand_pos, hand_rot, obj_pos, rotation.reshape(3, 3))
    full = grasp_tolerance(world, side, obj)
    shift = closing_shift(world, side, obj) if places else 0.0
    mu = horizontal_shift(shift, hand_rot)
    tolerance = GraspTolerance(
        max(0.0, full.closing - abs(planned.closing)),
        min(
            max(0.0, full.lateral - abs(planned.lateral)),
            placement_tolerance(DetectorThresholds().place_position_tol, mu) if places else np.inf,
        ),
        max(0.0, full.yaw - abs(planned.yaw)),
    )
    # The intended grasp point: where the hand is, at the object's height.
    reference = np.array([hand_pos[0], hand_pos[1], obj_pos[2]])
    report = assess_grasp(
        world,
        side,
        obj,
        (hand_pos, hand_rot),
        scenario.risk,
        scenario.uncertainty,
        object_pose=(reference, obj_quat),
        tolerance=tolerance,
        approach=approach_envelope(world, side, obj, path),
    )
    if shift == 0.0:
        return report
    details: dict[str, float | str] = {**report.details, "pinch_shift": shift, "placement_shift": mu}
    return replace(report, details=details)


def assess_task(
    world: World,
    task: Task,
    planner: Planner | None = None,
    collision_model: CollisionModel | None = None,
    q_start: np.ndarray | None = None,
) -> list[AlternativeRisk]:
    """Plan and assess every alternative of ``task`` on the estimate ``world``, in the task's order.

    An alternative that stands in for another (the kind's ``instead_of``) is planned after the
    rest, and only when the one it stands in for, asked for too, could not be planned.
    """
    planner = planner or Planner(world)
    model = collision_model or CollisionModel(
        world, world.scenario.risk, uncertainty=world.scenario.uncertainty
    )
    kind = task_kind(task.kind)
    alternatives = kind.alternatives(task, world)
    asked = {a.name for a in alternatives}
    later = [a for a in alternatives if kind.instead_of.get(a.name) in asked]
    rows: dict[str, AlternativeRisk] = {}
    for alternative in [a for a in alternatives if a not in later] + later:
        name = alternative.name
        stands_in = kind.instead_of.get(name, "")
        if alternative in later and rows[stands_in].feasible and not alternative.unsupported:
            reason = f"not needed: '{stands_in}' can be planned from where the robot stands"
            rows[name] = AlternativeRisk(name, False, None, None, reason)
            continue
        rows[name] = _assess_alternative(world, task, alternative, planner, model, q_start)
    return [rows[a.name] for a in alternatives]


def _assess_alternative(
    world: World,
    task: Task,
    alternative: Alternative,
    planner: Planner,
    model: CollisionModel,
    q_start: np.ndarray | None,
) -> AlternativeRisk:
    """Plan and assess one alternative (a row with the reason when it cannot be planned)."""
    name = alternative.name
    if alternative.unsupported:
        return AlternativeRisk(name, False, None, None, alternative.unsupported)
    t0 = time.perf_counter()
    try:
        plan = plan_alternative(planner, world, task, name, q_start)
    except PlanningError as exc:
        return AlternativeRisk(name, False, None, None, str(exc), time.perf_counter() - t0)
    t1 = time.perf_counter()
    risk = assess_plan(world, plan, model)
    return AlternativeRisk(name, True, risk, plan, "", t1 - t0, time.perf_counter() - t1)


register_model("collision", _collision_model)
register_model("fall", _fall_model)
register_model("drop", _drop_model)
