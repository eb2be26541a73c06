"""Running one named alternative end to end: plan on the estimate, execute in the truth.

This is the host loop of the executive in its simplest form: tick the tree
once, step physics one control period, repeat, until the tree is done or a
time limit passes. Risk-based selection between alternatives builds on it.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import py_trees

from behaviours.restance import Restance, install_replanner
from behaviours.robot_access import NAMESPACE, install
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.detectors import Failure, FailureDetector
from executive.planning.plan import AlternativePlan, held_at_start
from executive.planning.planner import Planner, PlanningError
from executive.planning.restance import LocalReplanner, Replanner
from executive.schema.failure_modes import mode_of_verdict
from executive.schema.types import Scenario
from executive.tasks.base import Task
from executive.tasks.registry import get as task_kind
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build, sample_perturbation
from executive.world.observation import SimulatedSensor

__all__ = [
    "RunResult",
    "behaviour_failure",
    "end_errors",
    "error_fields",
    "execute_plan",
    "outcome_fields",
    "run_alternative",
]

Status = py_trees.common.Status


@dataclass
class RunResult:
    """What happened when one alternative ran (or failed to plan)."""

    alternative: str
    outcome: str  # "success" | "failed" | "planning_failed" | "timeout"
    failure: Failure | None = None
    message: str = ""
    plan_s: float = 0.0  # wall time to plan every step
    planned_duration_s: float = 0.0  # sum of the trajectories' durations
    sim_time_s: float = 0.0
    wall_s: float = 0.0  # wall time of the execution loop
    physics_wall_s: float = 0.0  # of which stepping physics (+ detectors + servo targets)
    physics_steps: int = 0  # mj_step calls
    ticks: int = 0
    max_tick_s: float = 0.0
    statuses: list[str] = field(default_factory=list)  # root status after each tick, run-length encoded
    placement_error_m: float | None = None
    placement_offset: tuple[float, float] | None = None  # where the object rests less its target (x, y; m)
    behaviour: str = ""  # the behaviour that failed (its message is the failure's detail)
    #: per move that ended, per hand: where its site ended less its planned end (m, world frame)
    end_errors: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    restances: list[dict[str, Any]] = field(default_factory=list)  # re-plans after walks (their log records)

    @property
    def success(self) -> bool:
        return self.outcome == "success"

    @property
    def real_time_factor(self) -> float:
        return self.sim_time_s / self.wall_s if self.wall_s > 0 else float("nan")


def execute_plan(
    plan: AlternativePlan,
    truth: World,
    task: Task,
    control_dt: float = 0.02,
    time_limit_s: float | None = None,
    *,
    replanner: Replanner | None = None,
    seed: int | None = None,
) -> RunResult:
    """Tick the plan's subtree against the truth world until it finishes; check the placement.

    The detectors decide every failure as in a mission; the closest call (a report, never a
    failure) is not computed: nothing reads it from a batch run.

    Args:
        plan, truth, task: the plan (made on the estimate), the world physics runs, its task.
        control_dt, time_limit_s: the control period; the simulated time allowed (None: the
            plan's duration and 10 s).
        replanner: re-plans what follows a walk from the measured stance
            (:mod:`executive.planning.restance`); None: a :class:`LocalReplanner` on the
            estimate of ``truth``'s scenario, with no risk check.
        seed: the seed of the robot's sensors (its odometry); None: the scenario's ``trials.seed``.
    """
    detector = FailureDetector(truth, distance_stride=0)
    sensor = SimulatedSensor(truth, seed) if seed is not None else None
    robot = SimulatedRobot(truth, control_dt=control_dt, detector=detector, sensor=sensor)
    install(robot)
    install_replanner(replanner if replanner is not None else LocalReplanner(truth.scenario))
    hold_from_start(robot, held_at_start(plan.steps))
    root = task_kind(task.kind).subtree(plan)
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    limit = time_limit_s if time_limit_s is not None else plan.duration + 10.0
    result = RunResult(plan.name, "timeout", planned_duration_s=plan.duration)
    start = time.perf_counter()
    last = None
    while truth.data.time < limit:
        t0 = time.perf_counter()
        tree.tick()
        result.max_tick_s = max(result.max_tick_s, time.perf_counter() - t0)
        result.ticks += 1
        status = root.status
        if status != last:
            result.statuses.append(status.name)
            last = status
        if status != Status.RUNNING:
            break
        robot.advance()
    result.wall_s = time.perf_counter() - start
    result.end_errors = end_errors(root)
    result.physics_wall_s = robot.stats.physics_wall_s
    result.physics_steps = robot.stats.physics_steps
    result.sim_time_s = float(truth.data.time)
    result.restances = [n.record for n in root.iterate() if isinstance(n, Restance) and n.record is not None]
    if root.status == Status.SUCCESS:
        _verify(result, task, truth, robot.detector)
    elif root.status == Status.FAILURE:
        tip = root.tip()
        feedback = tip.feedback_message if tip else ""
        result.failure = robot.failure or behaviour_failure(tip, float(truth.data.time))
        result.behaviour = tip.name if tip else ""
        result.outcome = "failed"
        result.message = f"{tip.name if tip else plan.name}: {feedback}"
    else:
        robot.hold()
        tree.interrupt()
        result.message = f"not finished after {limit:.1f} s of simulated time"
    tree.shutdown()
    return result


def end_errors(root: py_trees.behaviour.Behaviour) -> dict[str, dict[str, list[float]]]:
    """Per hand move of ``root``'s tree that ended, per hand, its end error (executed less
    planned, m): what the moves measured of their tracking (:attr:`MoveHand.end_error`)."""
    out: dict[str, dict[str, list[float]]] = {}
    for behaviour in root.iterate():
        error = getattr(behaviour, "end_error", None)
        if error is not None:
            out[behaviour.name] = {side: [round(float(v), 6) for v in e] for side, e in error.items()}
    return out


def hold_from_start(robot: SimulatedRobot, held: dict[str, str]) -> None:
    """A plan that starts with objects in hand (``held``, side -> object): grippers closed on them.

    The blackboard's ``holding`` map says so to the behaviours and the detectors (as a grasp
    earlier in the mission would have left it).
    """
    if not held:
        return
    for side in held:
        robot.set_gripper(side, closed=True)
    client = py_trees.blackboard.Client(name="executive.runner", namespace=NAMESPACE)
    client.register_key("holding", access=py_trees.common.Access.WRITE)
    client.holding = dict(held)
    robot.detector.set_phase(carried=next(iter(held.items())))


def _verify(result: RunResult, task: Task, truth: World, detector: FailureDetector) -> None:
    """The task kind's check of a subtree that succeeded (a transfer: the object at its target)."""
    verdict = task_kind(task.kind).verify(task, truth, detector)
    to = getattr(task, "to", None)
    if to is not None and task.object:
        pos = truth.data.xpos[truth.ids.object_bodies[task.object]]
        result.placement_error_m = float(np.hypot(pos[0] - to[0], pos[1] - to[1]))
        result.placement_offset = (float(pos[0] - to[0]), float(pos[1] - to[1]))
    if verdict is None or verdict.ok:
        done = (
            f"{task.object} placed at the target" if verdict is not None and verdict.event == "placed" else ""
        )
        result.outcome, result.message = "success", done or f"{task.label()}: done"
    else:
        result.outcome, result.failure = "failed", verdict.failure
        result.message = str(verdict.fields.get("detail", ""))


def behaviour_failure(behaviour: py_trees.behaviour.Behaviour | None, time_s: float) -> Failure:
    """The failure a behaviour reported itself: its ``verdict`` and its feedback message.

    The verdict is one of the failure-mode table's (:mod:`executive.schema.failure_modes`):
    ``drop`` (a grasp that holds nothing), ``tracking`` (a hand stalled short of its plan),
    ``guard``, ``task`` (a press whose force was not reached). A behaviour that fails without
    one did not do its task: ``task``. The detail is the behaviour's message (which does not
    repeat its own name: the run's message and record name the behaviour once).

    Raises:
        ExecutiveError: the verdict is not in the table.
    """
    verdict = str(getattr(behaviour, "verdict", "") or "task")
    mode_of_verdict(verdict)  # raises for a verdict the table does not know
    return Failure(verdict, behaviour.feedback_message if behaviour is not None else "", time_s)


def run_alternative(
    scenario: Scenario,
    alternative: str,
    *,
    task_index: int = 0,
    exact: bool = False,
    seed: int | None = None,
    control_dt: float = 0.02,
) -> RunResult:
    """Plan ``alternative`` of a task on the estimate and execute it in a (sampled) truth world.

    What follows a walk inside the alternative is re-planned from the measured stance with the
    same planner (no risk check: nothing was approved).
    """
    task = scenario.mission[task_index]
    estimate = build(scenario)
    if exact:
        truth = build(scenario)
    else:
        rng = np.random.default_rng(scenario.trials.seed if seed is None else seed)
        truth = build(scenario, sample_perturbation(scenario, rng), kind="truth")
    t0 = time.perf_counter()
    planner = Planner(estimate)
    try:
        plan = plan_alternative(planner, estimate, task, alternative)
    except PlanningError as exc:
        return RunResult(alternative, "planning_failed", message=str(exc), plan_s=time.perf_counter() - t0)
    plan_s = time.perf_counter() - t0
    replanner = LocalReplanner(estimate, planner)
    result = execute_plan(plan, truth, task, control_dt=control_dt, replanner=replanner, seed=seed)
    result.plan_s = plan_s
    return result


def error_fields(exc: BaseException) -> dict[str, Any]:
    """The record of a physics run whose code raised (a defect, counted as outcome ``error``)."""
    last = traceback.extract_tb(exc.__traceback__)[-1]
    detail = f"{type(exc).__name__}: {exc} ({Path(last.filename).name}:{last.lineno})"
    return {"outcome": "error", "failure": {"mode": "error", "detail": detail}}


def outcome_fields(result: RunResult) -> dict[str, Any]:
    """What a physics run's record says of its outcome: outcome, failure, sim time, placement error,
    and the moves' end errors (``end_errors``, :func:`end_errors`).

    ``outcome`` is ``success``, ``timeout`` or the verdict of the failure (a detector's or a
    behaviour's; ``task`` when the run failed without one).
    """
    out: dict[str, Any] = {"sim_time_s": round(result.sim_time_s, 6)}
    if result.end_errors:
        out["end_errors"] = result.end_errors
    if result.placement_error_m is not None:
        out["placement_error_m"] = round(result.placement_error_m, 6)
    if result.placement_offset is not None:
        out["placement_offset"] = [round(v, 6) for v in result.placement_offset]
    if result.restances:
        out["restance"] = result.restances
    if result.outcome == "success":
        out["outcome"] = "success"
    elif result.outcome == "timeout":
        out["outcome"] = "timeout"
        out["failure"] = {"mode": "timeout", "detail": result.message}
    else:
        failure = result.failure
        mode = failure.mode if failure is not None else "task"
        out["outcome"] = mode
        out["failure"] = {
            "mode": mode,
            "behaviour": result.behaviour,
            "detail": failure.detail if failure is not None else result.message,
            "time": round(failure.time, 6) if failure is not None else None,
            "bodies": list(failure.bodies) if failure is not None else [],
            "force": round(failure.force, 3) if failure is not None else 0.0,
        }
    return out
