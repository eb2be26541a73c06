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
* drop: the grasps off the table, where they leave the object on its target, and the hold
  (:mod:`executive.decision.drop_model`), with the hands' predicted execution errors; a dry
  run's measured placement refines it (:func:`executive.decision.drop_model.drop_measured`);
* tracking: each hand move's end against its tolerance, from the servos' statics
  (:mod:`executive.risk.tracking`); a dry run's measured end errors refine it
  (:func:`_tracking_measured`);
* combined: :func:`executive.risk.combine.combine`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from executive.decision.drop_model import drop_measured, drop_model, drop_union
from executive.decision.risk_models import PlanContext, register_dry_run_update, register_model, risk_model
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner, PlanningError
from executive.planning.timing import concatenate
from executive.risk.collision import CollisionModel, CollisionProfile, KnotDistance, report_from_profile
from executive.risk.combine import CombinedRisk, combine
from executive.risk.fall import assess_fall
from executive.risk.fall_balance import walk_phases
from executive.risk.press import press_forces
from executive.risk.push import plan_forces
from executive.risk.report import RiskReport
from executive.risk.tracking import TrackingReport, tracking_report
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
    # What held a move that stalled back (PlanningError.binding as plain data; empty: not known).
    binding: tuple[dict[str, str | float], ...] = ()


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
        binding = tuple(b.as_dict() for b in exc.binding)
        return AlternativeRisk(name, False, None, None, str(exc), time.perf_counter() - t0, binding=binding)
    t1 = time.perf_counter()
    risk = assess_plan(world, plan, model)
    return AlternativeRisk(name, True, risk, plan, "", t1 - t0, time.perf_counter() - t1)


def _tracking_model(ctx: PlanContext) -> RiskReport:
    """The tracking mode: each hand move's end against its tolerance (:mod:`executive.risk.tracking`)."""
    return tracking_report(ctx.tracking, ctx.severity("tracking"))


def _tracking_measured(report: RiskReport, record: Mapping[str, Any]) -> RiskReport:
    """The tracking report with the hands' end errors the dry run measured (its ``end_errors``)."""
    if not isinstance(report, TrackingReport) or report.prediction is None:
        return report
    return tracking_report(report.prediction.measured(record.get("end_errors")), report.severity)


register_model("collision", _collision_model)
register_model("fall", _fall_model)
register_model("drop", drop_model)
register_model("tracking", _tracking_model)
register_dry_run_update("tracking", _tracking_measured)
register_dry_run_update("drop", drop_measured)
