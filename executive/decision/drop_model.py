"""The drop mode's model: the grasps off the table, where they leave the object, and the hold.

Per alternative (:func:`drop_model`, registered by :mod:`executive.decision.assessment`):

* a push that holds nothing: falling short (:func:`executive.risk.push.assess_placement`);
* every grasp that takes the object off the table (a regrasp takes it twice), against the
  scene's object pose uncertainty (a handover's second grasp takes the object from a hand whose
  pose the robot knows; it is the hold model's): the jaws must clear the object's sides all the
  way down the planned approach, and the placement it leads to: the jaws centre the object
  across them, but its error along them stays in the hand and lands on the target, where the
  failure detector calls it misplaced beyond ``place_position_tol`` (:func:`_grasp`);
* an object held from the start: its grip's error lands on the target (:func:`_placed_from_hand`);
* the union with the hold model (:mod:`executive.risk.hold`) is the drop mode (:func:`drop_union`).

Execution (:mod:`executive.risk.tracking`): the hand's predicted error at the end of the move
onto the object shifts the approach's window and the grip along the jaws; its error at the end
of the place moves where the object rests (:mod:`executive.risk.placement_spread`); an object
set down and taken again (a regrasp) carries the set-down's spread into its next grasp. What
the statics do not predict (the releases, slips in the grip, the base's lag) a dry run measures:
where the object came to rest on the estimate (its record's ``placement_offset``), which
:func:`drop_measured` puts in place of the predicted offset of the final placement.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import mujoco
import numpy as np

from executive.decision.risk_models import PlanContext
from executive.monitoring.detectors import DetectorThresholds
from executive.planning.plan import AlternativePlan, Step
from executive.planning.planner import Trajectory
from executive.risk.grasp import (
    GraspTolerance,
    approach_envelope,
    assess_grasp,
    closing_axis,
    grasp_error,
    grasp_tolerance,
    hand_pose_at,
)
from executive.risk.hold import assess_hold
from executive.risk.model_geometry import site_pose_at
from executive.risk.pinch import closing_shift, horizontal_shift, placement_tolerance
from executive.risk.placement_spread import (
    MEASURED_PLACEMENT_SIGMA,
    SET_DOWN_SIGMA,
    ExecutionSpread,
    gaussian_exceed,
    misplace_probability,
)
from executive.risk.push import assess_placement
from executive.risk.report import RiskReport
from executive.risk.tracking import TrackingPrediction
from executive.world.model import World

__all__ = ["HandExecution", "drop_measured", "drop_model", "drop_union"]

#: The details a drop report keeps of its final placement, for :func:`drop_measured`.
_PLACEMENT_KEYS = (
    "placement_probability",
    "placement_lateral_mean",
    "placement_lateral_sigma",
    "placement_lateral_tolerance",
    "placement_axis_x",
    "placement_axis_y",
)


@dataclass(frozen=True)
class HandExecution:
    """The grasping hand's predicted execution error (:meth:`TrackingPrediction.hand_at`): at the
    end of the move onto the object and at the end of the place that sets it down (zeros where
    a move is not tracked), with the place step (None: the object is not set down)."""

    approach: np.ndarray
    approach_sigma: float
    place: np.ndarray
    place_sigma: float
    place_step: Step | None

    @classmethod
    def of(cls, tracking: TrackingPrediction, plan: AlternativePlan, i: int) -> HandExecution:
        """The hand of grasp step ``i``, as ``tracking`` predicts it."""
        step = plan.steps[i]
        moves = [s for s in plan.steps[:i] if s.side == step.side and s.name in plan.trajectories]
        place = next((s for s in plan.steps[i:] if s.kind == "place" and s.name in plan.trajectories), None)
        none = (np.zeros(3), 0.0)
        at = (tracking.hand_at(moves[-1].name, step.side) if moves else None) or none
        there = (tracking.hand_at(place.name, place.side) if place is not None else None) or none
        return cls(at[0], at[1], there[0], there[1], place)

    def spread(self) -> ExecutionSpread:
        """Where the place's predicted hand error puts the object, in the table plane (the
        release's own shift is not predicted: a dry run measures it, :func:`drop_measured`)."""
        return ExecutionSpread(np.asarray(self.place[:2], dtype=float), float(self.place_sigma))


def drop_model(ctx: PlanContext) -> RiskReport:
    """The drop mode: a push falling short; else the grasps off the table (or a placement from
    the hand) united with the hold model (:func:`drop_union`)."""
    world, plan, scenario = ctx.world, ctx.plan, ctx.world.scenario
    grasp_step = next((s for s in plan.steps if s.kind == "grasp"), None)
    if ctx.pushes is not None and grasp_step is None:  # a push holds nothing: its drop mode is falling short
        tol = DetectorThresholds().place_position_tol
        return assess_placement(world, plan, ctx.pushes, scenario.risk, scenario.uncertainty, tol)
    if grasp_step is None:  # the object is in hand from the start (a place) or never taken
        grasp = _placed_from_hand(world, plan, ctx.tracking)
    else:
        # Every grasp that takes the object off the table (a regrasp takes it twice); a
        # handover's grasp in the air is the hold model's.
        grasps = [
            _table_grasp(world, plan, i, ctx.tracking)
            for i, s in enumerate(plan.steps)
            if _off_table(plan, i)
        ]
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


def _table_grasp(
    world: World, plan: AlternativePlan, i: int, tracking: TrackingPrediction | None = None
) -> RiskReport:
    """The grasp risk of step ``i``: the jaws down its side's moves onto the object, and the place
    after (with the hand's predicted execution error when ``tracking`` is given)."""
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
    execution = HandExecution.of(tracking, plan, i) if tracking is not None else None
    if carries and execution is not None:  # where the set-down left it: its error grows by one
        u = world.scenario.uncertainty
        u = replace(u, object_position=float(np.hypot(u.object_position, SET_DOWN_SIGMA)))
        world = replace(world, scenario=replace(world.scenario, uncertainty=u))
    place = None
    if execution is not None and execution.place_step is not None:
        place = plan.trajectories[execution.place_step.name]
    return _grasp(
        world,
        step.side,
        obj,
        plan.trajectories[moves[-1].name],
        down,
        places=places,
        execution=execution,
        place=place,
    )


def _with_object_at(world: World, obj: str, qpos: np.ndarray) -> World:
    """A view of ``world`` with its own MuJoCo data, ``obj`` where ``qpos`` has it (the rest as is)."""
    data = mujoco.MjData(world.model)
    data.qpos[:] = world.data.qpos
    adr = world.ids.object_qpos[obj]
    data.qpos[adr : adr + 7] = qpos[adr : adr + 7]
    mujoco.mj_kinematics(world.model, data)
    return replace(world, data=data)


def _union(reports: list[RiskReport]) -> RiskReport:
    """Failure of any of independent ``reports`` of one mode: 1 - prod(1 - p); the first's
    details, with the last's final placement (:data:`_PLACEMENT_KEYS`)."""
    if len(reports) == 1:
        return reports[0]
    p = 1.0 - float(np.prod([1.0 - r.probability for r in reports]))
    lower = max(r.probability_bounds[0] for r in reports)
    upper = min(1.0, sum(r.probability_bounds[1] for r in reports))
    final = {k: reports[-1].details[k] for k in _PLACEMENT_KEYS if k in reports[-1].details}
    details = {**reports[0].details, **final, "grasps": float(len(reports))}
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


def _placed_from_hand(
    world: World, plan: AlternativePlan, tracking: TrackingPrediction | None = None
) -> RiskReport:
    """The drop mode's share of a plan that takes no grasp: misplacing an object held from the start.

    The hand puts the object down where the estimate's grip (the object's pose in the hand,
    :attr:`World.grips`, the mean of ``looks`` observations of 1-sigma ``object_position`` per
    horizontal axis) says it is; the grip's error lands on the target. Beyond the detector's
    ``place_position_tol`` in the table plane it is misplaced: for an isotropic 2-D Gaussian
    error, P(|e| > tol) = exp(-tol^2 / (2 sigma^2 / looks)) (the Rayleigh distribution's tail).
    With ``tracking``, the place's predicted hand error adds its bias and spread (a non-central
    tail, :func:`executive.risk.placement_spread.gaussian_exceed`). A plan that
    places nothing: 0.
    """
    severity = world.scenario.risk.severity.drop
    place = next((s for s in plan.steps if s.kind == "place" and s.name in plan.trajectories), None)
    if place is None and not any(s.kind == "place" for s in plan.steps):
        return RiskReport("drop", 0.0, (0.0, 0.0), severity, 0.0, details={"grasp": "none"})
    grip = getattr(world, "grips", {}).get(plan.task.object)
    looks = max(1, int(getattr(grip, "looks", 1)))
    sigma = world.scenario.uncertainty.object_position / np.sqrt(looks)
    tol = DetectorThresholds().place_position_tol
    at = tracking.hand_at(place.name, place.side) if tracking is not None and place is not None else None
    if at is None:
        p = float(np.exp(-(tol**2) / (2 * sigma**2))) if sigma > 0 else 0.0
    else:
        p = gaussian_exceed(at[0][:2], float(np.hypot(sigma, at[1])), tol)
    details: dict[str, float | str] = {"grasp": "none: held from the start", "grip_looks": float(looks)}
    details["misplace_probability"] = p
    details.update(
        placement_probability=p,
        placement_lateral_mean=0.0,
        placement_lateral_sigma=sigma,
        placement_lateral_tolerance=np.inf,
        placement_axis_x=0.0,
        placement_axis_y=0.0,
    )
    return RiskReport("drop", p, (p, p), severity, p, details=details)


def _grasp(
    world: World,
    side: str,
    obj: str,
    approach: Trajectory,
    path: np.ndarray,
    *,
    places: bool = True,
    execution: HandExecution | None = None,
    place: Trajectory | None = None,
) -> RiskReport:
    """Grasp risk measured from the grasp point the plan intends, not the object's centre.

    A handover grasps the object off-centre on purpose: no error, but it uses up tolerance there.

    The object's error along the jaws (the lateral axis) is not corrected by closing them: the hand
    carries it to the target, so the object rests that far from it. The drop mode's failures include a
    placement beyond the failure detector's ``place_position_tol``; the same error ``e`` fails the grasp
    when ``|e|`` exceeds the lateral tolerance, so the union of the two is ``|e| > min(lateral,
    place_position_tol)`` (exact: nested events of one Gaussian, not a bound). A thumb-against-fingers
    hand holds the object off its site across the jaws (:func:`executive.risk.pinch.closing_shift`);
    that shift's table-plane part ``mu`` lands on the target too, and the placement's bound on ``|e|``
    becomes sqrt(place_position_tol^2 - mu^2) (:func:`executive.risk.pinch.placement_tolerance`; slide
    jaws: mu = 0). ``places`` False (a pick that keeps the object): no placement, the lateral tolerance
    is the grasp's own.

    Across the jaws, the hand must clear the object's sides all the way down, not only at the grasp pose:
    ``path`` (the grasping hand's poses before the grasp, e.g. its pre-grasp and approach knots) gives the
    envelope its geoms sweep below the object's top (:func:`executive.risk.grasp.approach_envelope`), and
    the offset and yaw errors are scored jointly against it
    (:func:`executive.risk.grasp.approach_miss_probability`).

    ``execution`` (the hand's predicted errors) moves the approach's window by the hand's error at the end
    of ``approach`` and adds its spread; the lateral error then lands on the target with the place's
    (``place``, the trajectory that sets the object down) hand error and the release's spread
    (:func:`executive.risk.placement_spread.misplace_probability`). None: as if executed exactly. Every
    axis is the grasp's own (:func:`executive.risk.grasp.closing_axis`).
    """
    scenario = world.scenario
    hand_pos, hand_rot = hand_pose_at(world, approach, side)
    obj_pos, obj_quat = world.object_pose(obj)
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, obj_quat)
    closing = closing_axis(rotation.reshape(3, 3), hand_rot)
    planned = grasp_error(hand_pos, hand_rot, obj_pos, rotation.reshape(3, 3), closing_axis_object=closing)
    full = grasp_tolerance(world, side, obj, closing_axis_object=closing)
    shift = closing_shift(world, side, obj) if places else 0.0
    mu = horizontal_shift(shift, hand_rot)
    own = max(0.0, full.lateral - abs(planned.lateral))
    tol = DetectorThresholds().place_position_tol
    tolerance = GraspTolerance(
        max(0.0, full.closing - abs(planned.closing)),
        min(own, placement_tolerance(tol, mu) if places else np.inf),
        max(0.0, full.yaw - abs(planned.yaw)),
    )
    # The intended grasp point: where the hand is, at the object's height.
    reference = np.array([hand_pos[0], hand_pos[1], obj_pos[2]])
    extra: dict[str, Any] = {}
    placement: dict[str, float] = {}
    if execution is not None:
        extra, placement = _executed(
            world, side, obj, (hand_pos, hand_rot), reference, rotation, own, shift, execution, place, places
        )
    report = assess_grasp(
        world,
        side,
        obj,
        (hand_pos, hand_rot),
        scenario.risk,
        scenario.uncertainty,
        object_pose=(reference, obj_quat),
        tolerance=tolerance,
        approach=approach_envelope(world, side, obj, path, closing_axis_object=closing),
        closing_axis_object=closing,
        **extra,
    )
    details: dict[str, float | str] = {**report.details, **placement}
    if shift != 0.0:
        details.update(pinch_shift=shift, placement_shift=mu)
    return replace(report, details=details) if details != report.details else report


def _executed(
    world: World,
    side: str,
    obj: str,
    hand_pose: tuple[np.ndarray, np.ndarray],
    reference: np.ndarray,
    rotation: np.ndarray,
    own: float,
    shift: float,
    execution: HandExecution,
    place: Trajectory | None,
    places: bool,
) -> tuple[dict[str, Any], dict[str, float]]:
    """What the hand's execution error does to a grasp: the arguments it adds to
    :func:`executive.risk.grasp.assess_grasp` (the approach window's shift and spread, the
    lateral event's probability) and the final placement's details (for :func:`drop_measured`).

    ``own``: the grasp's own lateral tolerance; ``shift``: the pinch's shift along the site's y.
    """
    hand_pos, hand_rot = hand_pose
    sigma = world.scenario.uncertainty.object_position
    closing_obj = rotation.reshape(3, 3)[:, 1].copy()  # the envelope's frame (approach_envelope)
    closing_obj[2] = 0.0
    closing_obj /= np.linalg.norm(closing_obj)
    lateral_obj = np.array([closing_obj[1], -closing_obj[0], 0.0])
    lateral_hand = _lateral_axis(hand_rot)
    err = grasp_error(hand_pos, hand_rot, reference, rotation.reshape(3, 3))
    e_a, s_a = execution.approach, execution.approach_sigma
    mean = err.lateral - float(e_a @ lateral_hand)
    spread_sigma = float(np.hypot(sigma, s_a))
    if places:
        placer = execution.place_step.side if execution.place_step is not None else side
        rot = hand_rot if place is None else site_pose_at(world, place.qpos[-1], placer)[1]
        axis = _lateral_axis(rot)[:2]
        y = np.array(rot[:, 1], dtype=float)
        shift_vec = shift * y[:2]
        tol = DetectorThresholds().place_position_tol
        p_lat = misplace_probability(mean, spread_sigma, own, axis, shift_vec, execution.spread(), tol)
    else:
        axis = lateral_hand[:2]
        p_lat = misplace_probability(
            mean, spread_sigma, own, axis, np.zeros(2), ExecutionSpread(np.zeros(2), 0.0), np.inf
        )
    extra = {
        "hand": (float(e_a @ closing_obj), float(e_a @ lateral_obj)),
        "hand_sigma": float(s_a),
        "lateral_probability": p_lat,
    }
    placement = {
        "placement_probability": p_lat,
        "placement_lateral_mean": float(err.lateral),
        "placement_lateral_sigma": float(sigma),
        "placement_lateral_tolerance": float(own),
        "placement_axis_x": float(axis[0]),
        "placement_axis_y": float(axis[1]),
    }
    return extra, (placement if places else {})


def _lateral_axis(hand_rotation: np.ndarray) -> np.ndarray:
    """The hand site's lateral axis in the table plane (3,): its closing axis (y) levelled,
    turned a quarter (as :func:`executive.risk.grasp_tolerance.grasp_error` takes it)."""
    y = np.array(np.asarray(hand_rotation).reshape(3, 3)[:, 1], dtype=float)
    y[2] = 0.0
    y /= np.linalg.norm(y)
    return np.array([y[1], -y[0], 0.0])


def drop_measured(report: RiskReport, record: Mapping[str, Any]) -> RiskReport:
    """The drop report with the final placement a dry run measured in place of the predicted one.

    On the estimate the object's pose is known, so the dry run's ``placement_offset`` (where the
    object came to rest less its target, m) is what execution does to it: the hands' errors, the
    pinch, the release, a regrasp's set-downs. The truth's grip error along the jaws is added to
    it (:func:`executive.risk.placement_spread.misplace_probability` with the offset as the bias
    and :data:`executive.risk.placement_spread.MEASURED_PLACEMENT_SIGMA` as the spread); the rest
    of the mode (the approach, the hold, earlier grasps) stays as predicted, as independent.
    """
    offset = record.get("placement_offset")
    d = report.details
    if offset is None or "placement_probability" not in d:
        return report
    before = float(d["placement_probability"])
    if before >= 1.0:
        return report
    other = max(0.0, 1.0 - (1.0 - report.probability) / (1.0 - before))
    bias = np.asarray(offset, dtype=float)
    tol = DetectorThresholds().place_position_tol
    sigma = float(d["placement_lateral_sigma"])
    axis = np.array([float(d["placement_axis_x"]), float(d["placement_axis_y"])])
    if not np.any(axis):  # held from the start: the grip's error is isotropic
        p = gaussian_exceed(bias, float(np.hypot(sigma, MEASURED_PLACEMENT_SIGMA)), tol)
    else:
        spread = ExecutionSpread(bias, MEASURED_PLACEMENT_SIGMA)
        lateral = (float(d["placement_lateral_mean"]), sigma, float(d["placement_lateral_tolerance"]))
        p = misplace_probability(*lateral, axis, np.zeros(2), spread, tol)
    total = 1.0 - (1.0 - other) * (1.0 - p)
    details = {
        **d,
        "placement_probability": p,
        "measured_offset_x": float(bias[0]),
        "measured_offset_y": float(bias[1]),
    }
    return replace(
        report, probability=total, probability_bounds=(max(other, p), min(1.0, other + p)), details=details
    )
