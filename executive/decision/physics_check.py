"""Risk checked in physics before the robot moves: dry runs and Monte Carlo rollouts.

Every feasible alternative is first *dry-run*: executed once in MuJoCo on the estimate itself
(truth = estimate), through the same subtree, servos and failure detectors as a real run
(:func:`executive.execution.runner.execute_plan`). A plan that fails with perfect knowledge is
infeasible. Then, when ``risk.rollouts.count`` > 0, *rollouts*: the surviving alternatives
executed on truths sampled from the scenario's uncertainty (the campaign's sampler), in rounds
of ``batch``: every alternative until it has ``min_count``, then only those the stopping rule
of :mod:`executive.risk.fusion` still finds in contention
(:mod:`executive.decision.rollout_allocation`), each up to ``count``, until none is left or
the next round would overrun ``budget_s``. Rollout ``j`` of every alternative uses the same
truth (common random numbers). A run ends at its outcome: the first failure a detector or a
behaviour reports ends it within the physics step or tick, a success on the tick its subtree
succeeds.

Jobs run through a ``run_map`` callable (jobs in, records out, in order): a
:class:`RolloutPool` of warm worker processes, the campaign's backends, or ``map`` itself.
"""

from __future__ import annotations

import concurrent.futures
import concurrent.futures.process
import dataclasses
import multiprocessing
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from executive.decision.priority import normal_policy_children
from executive.decision.risk_models import dry_run_update
from executive.decision.rollout_allocation import CLEAR, COUNT, GOING, allocate
from executive.errors import ExecutiveError
from executive.risk.combine import CombinedRisk, combine
from executive.risk.fusion import Contention, contention, fuse, posteriors
from executive.schema.types import RiskConfig, Scenario, SceneVariation

if TYPE_CHECKING:
    from executive.decision.assessment import AlternativeRisk
    from executive.planning.plan import AlternativePlan
    from executive.world.model import World

__all__ = [
    "PhysicsCheck",
    "PhysicsResult",
    "PhysicsVerdict",
    "RolloutError",
    "RolloutJob",
    "RolloutPool",
    "apply_verdict",
    "check_alternatives",
    "estimate_scenario",
    "exit_with_parent",
    "measured",
    "physics_text",
    "rollout_seed",
    "run_job",
    "with_rollouts",
]

#: Keeps rollout seeds apart from the campaign's trial seeds (``trials.seed + i``).
_ROLLOUT_STREAM = 0x5EED_0F_0


class RolloutError(ExecutiveError):
    """The physics check could not run (a worker process died)."""


RunMap = Callable[[Sequence["RolloutJob"]], list[dict[str, Any]]]


@dataclass(frozen=True)
class RolloutJob:
    """One physics run of a planned alternative: the dry run (``seed`` None) or a rollout."""

    scenario: Scenario  # the estimate as a scenario (see :func:`estimate_scenario`)
    plan: AlternativePlan  # its task is the one executed
    seed: int | None
    q_start: np.ndarray | None = None  # the robot's joints at the start (None: home)


def rollout_seed(base_seed: int, j: int) -> int:
    """The truth seed of rollout ``j`` (the same for every alternative), apart from trial seeds."""
    return int(np.random.SeedSequence([base_seed, _ROLLOUT_STREAM, j]).generate_state(1)[0])


def estimate_scenario(world: World) -> Scenario:
    """The scenario whose nominal scene is ``world``'s current estimate of the objects.

    Objects are put where the estimate has them now (position, yaw); the trial-to-trial scene
    variation is dropped: the rollouts' truths are sampled around this one estimate.
    """
    from executive.world.heading import yaw_of

    scenario = world.scenario
    objects = []
    for body in scenario.scene.objects:
        pos, quat = world.object_pose(body.name)
        yaw = yaw_of(quat)
        roll, pitch, _ = body.orientation_rad
        position = (float(pos[0]), float(pos[1]), float(pos[2]))
        objects.append(dataclasses.replace(body, position=position, orientation_rad=(roll, pitch, yaw)))
    scene = dataclasses.replace(scenario.scene, objects=tuple(objects))
    trials = dataclasses.replace(scenario.trials, scene_variation=SceneVariation())
    return dataclasses.replace(scenario, scene=scene, trials=trials)


def with_rollouts(scenario: Scenario, count: int | None) -> Scenario:
    """``scenario`` with ``risk.rollouts.count`` set to ``count`` (None: unchanged).

    The stopping rule's minimum is lowered to ``count`` when it is above it.

    Raises:
        ExecutiveError: a negative count.
    """
    if count is None:
        return scenario
    if count < 0:
        raise ExecutiveError(f"--rollouts must be 0 (off) or more; got {count}")
    cfg = scenario.risk.rollouts
    cfg = dataclasses.replace(cfg, count=count, min_count=min(cfg.min_count, max(count, 1)))
    return dataclasses.replace(scenario, risk=dataclasses.replace(scenario.risk, rollouts=cfg))


def _truth(job: RolloutJob) -> World:
    from executive.planning.plan import held_at_start
    from executive.world.model import build, sample_perturbation

    if job.seed is None:
        world = build(job.scenario)
    else:
        rng = np.random.default_rng(job.seed)
        world = build(job.scenario, sample_perturbation(job.scenario, rng), kind="truth")
    if job.q_start is not None:
        objects = [adr + k for adr in world.ids.object_qpos.values() for k in range(7)]
        robot = np.setdiff1d(np.arange(world.model.nq), objects)
        world.data.qpos[robot] = np.asarray(job.q_start, dtype=float)[robot]
        # An object in a hand is where the hand holds it (the estimate's pose), not drawn anew.
        for obj in held_at_start(job.plan.steps).values():
            adr = world.ids.object_qpos[obj]
            world.data.qpos[adr : adr + 7] = np.asarray(job.q_start, dtype=float)[adr : adr + 7]
        world.data.qvel[:] = 0.0
        mujoco.mj_forward(world.model, world.data)
    return world


def run_job(job: RolloutJob) -> dict[str, Any]:
    """Execute ``job`` in physics; its record: alternative, seed, outcome, failure, physics steps,
    wall time.

    ``outcome`` is ``success``, a failure detector's mode, ``timeout``, or ``error`` (the code
    raised: a defect, counted, never hidden). What follows a walk inside the plan is re-planned
    from the stance the robot measures (its odometry seeded by the rollout's truth), with no risk
    check: nothing is approved yet.
    """
    from executive.execution.runner import error_fields, execute_plan, outcome_fields

    t0 = time.perf_counter()
    record: dict[str, Any] = {"alternative": job.plan.name, "seed": job.seed, "failure": None}
    try:
        result = execute_plan(job.plan, _truth(job), job.plan.task, seed=job.seed)
        record.update(outcome_fields(result))
        record["physics_steps"] = result.physics_steps
    except Exception as exc:
        record.update(error_fields(exc))
    record["wall_s"] = time.perf_counter() - t0
    return record


@dataclass
class PhysicsResult:
    """What physics said of one alternative: its dry run, its rollouts, the fused risk.

    ``measured``: the analytic risk with what the dry run measured (the modes with a dry-run
    update, :func:`executive.decision.risk_models.register_dry_run_update`); None when no mode
    has one. It is the prior the rollouts update.
    """

    alternative: str
    dry_run: dict[str, Any]
    analytic: CombinedRisk
    counts: Counter[str] = field(default_factory=Counter)  # outcome -> rollouts
    rollouts: int = 0
    stopped: str = ""  # why it got no more rollouts: clear, count or budget (rollout_allocation)
    fused: CombinedRisk | None = None  # None: no rollouts ran (the prior stands)
    measured: CombinedRisk | None = None

    @property
    def dry_run_ok(self) -> bool:
        return bool(self.dry_run.get("outcome") == "success")

    @property
    def prior(self) -> CombinedRisk:
        """The risk before the rollouts: the analytic one with what the dry run measured."""
        return self.measured if self.measured is not None else self.analytic

    @property
    def risk(self) -> CombinedRisk:
        """The risk the selector ranks by: fused when rollouts ran, else the prior."""
        return self.fused if self.fused is not None else self.prior

    def dry_run_reason(self) -> str:
        failure = self.dry_run.get("failure") or {}
        detail = failure.get("detail") or self.dry_run.get("outcome", "")
        return f"fails in simulation with the scene as estimated: {detail}"

    def as_dict(self, confidence: float) -> dict[str, Any]:
        """JSON-safe: the dry run, and per mode the analytic probability, counts, fused value, interval."""
        out: dict[str, Any] = {"dry_run": _dry_json(self.dry_run), "rollouts": self.rollouts}
        if self.stopped:
            out["stopped"] = self.stopped
        out["outcomes"] = dict(self.counts)
        if self.fused is not None:
            modes = {}
            for mode, report in self.fused.components.items():
                modes[mode] = {
                    "analytic": self.analytic.components[mode].probability,
                    "failures": report.details.get("failures", 0),
                    "fused": report.probability,
                    "interval": list(report.probability_bounds),
                }
            out["modes"] = modes
            out["confidence"] = confidence
        if self.measured is not None:
            for mode, report in self.measured.components.items():
                if report is not self.analytic.components[mode]:
                    entry = out.setdefault("modes", {}).setdefault(mode, {})
                    entry.setdefault("analytic", self.analytic.components[mode].probability)
                    entry["measured"] = report.probability
        return out


def physics_text(physics: Mapping[str, Any]) -> str:
    """One line for people: the dry run's outcome and, if rollouts ran, their failures by mode."""
    dry = physics["dry_run"]
    text = "dry run: ok" if dry.get("outcome") == "success" else f"dry run: {dry.get('outcome')}"
    n = physics.get("rollouts", 0)
    if n:
        failed = {k: v for k, v in physics.get("outcomes", {}).items() if k != "success"}
        shown = ", ".join(f"{v} {k}" for k, v in sorted(failed.items())) or "no failure"
        text += f"; {n} rollouts: {shown}"
    return text


def _dry_json(record: Mapping[str, Any]) -> dict[str, Any]:
    keep = ("outcome", "failure", "sim_time_s", "wall_s")
    return {k: record[k] for k in keep if k in record}


@dataclass
class PhysicsVerdict:
    """The physics check of one decision: per alternative its result, and how the rollouts ended.

    ``stopped``: ``off`` (no rollouts configured), ``none left`` (every dry run failed),
    ``clear`` (every alternative stopped as the allocation's rule said), ``count`` (one was
    still unsure at the cap) or ``budget``. Each alternative's own count and reason are in
    :attr:`alternatives` (``rollouts``, ``stopped``).
    """

    alternatives: dict[str, PhysicsResult]
    rollouts: int = 0  # the most any alternative had
    stopped: str = "off"
    confidence: float | None = None  # the stopping rule's last P(choice within the indifference)
    opportunity_cost: float | None = None  # and the expected extra loss of that choice
    dry_run_s: float = 0.0
    rollout_s: float = 0.0
    physics_steps: int = 0  # simulated by the dry runs and the rollouts

    @property
    def rollouts_total(self) -> int:
        """Rollouts of all alternatives together."""
        return sum(r.rollouts for r in self.alternatives.values())

    def as_dict(self) -> dict[str, Any]:
        return {
            "rollouts": self.rollouts,
            "rollouts_total": self.rollouts_total,
            "allocation": {n: r.rollouts for n, r in self.alternatives.items() if r.dry_run_ok},
            "stopped": self.stopped,
            "physics_steps": self.physics_steps,
            "choice_confidence": self.confidence,
            "opportunity_cost": self.opportunity_cost,
            "dry_run_s": self.dry_run_s,
            "rollout_s": self.rollout_s,
        }


def check_alternatives(
    plans: Mapping[str, AlternativePlan],
    analytic: Mapping[str, CombinedRisk],
    scenario: Scenario,
    run_map: RunMap,
    *,
    q_start: np.ndarray | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> PhysicsVerdict:
    """Dry-run every planned alternative, then roll out the survivors (see the module docstring).

    Args:
        plans: the feasible alternatives' plans, by name.
        analytic: their analytic risk, by name.
        scenario: the estimate as a scenario (:func:`estimate_scenario`); its ``risk.rollouts``
            configures the rollouts and its ``trials.seed`` seeds them.
        run_map: runs jobs (in worker processes or here), records back in order.
        q_start: the robot's joints where the plans start (None: home).

    Returns:
        The verdict; an alternative whose dry run failed has no rollouts and no fused risk.
    """
    t0 = clock()
    dry = [RolloutJob(scenario, plan, None, q_start) for plan in plans.values()]
    results = {
        name: PhysicsResult(
            name, record, analytic[name], measured=measured(analytic[name], record, scenario.risk)
        )
        for name, record in zip(plans, run_map(dry), strict=True)
    }
    verdict = PhysicsVerdict(results, dry_run_s=clock() - t0)
    verdict.physics_steps = sum(int(r.dry_run.get("physics_steps", 0)) for r in results.values())
    alive = [name for name, r in results.items() if r.dry_run_ok]
    if scenario.risk.rollouts.count == 0:
        return verdict
    if not alive:
        verdict.stopped = "none left"
        return verdict
    _roll_out(verdict, [plans[a] for a in alive], scenario, run_map, q_start, clock)
    for name in alive:
        r = results[name]
        cfg = scenario.risk.rollouts
        r.fused = fuse(r.prior, r.counts, r.rollouts, cfg.prior_weight, cfg.confidence, scenario.risk)
    return verdict


def measured(analytic: CombinedRisk, record: Mapping[str, Any], config: RiskConfig) -> CombinedRisk | None:
    """``analytic`` with each mode's dry-run update applied to the dry run's ``record`` (None: no
    mode has one, or the run failed: an alternative that fails its dry run is not run)."""
    if record.get("outcome") != "success":
        return None
    reports, changed = [], False
    for mode, report in analytic.components.items():
        update = dry_run_update(mode)
        refined = update(report, record) if update is not None else report
        changed |= refined is not report
        reports.append(refined)
    return combine(reports, config, analytic.duration_s) if changed else None


def _roll_out(
    verdict: PhysicsVerdict,
    plans: Sequence[AlternativePlan],
    scenario: Scenario,
    run_map: RunMap,
    q_start: np.ndarray | None,
    clock: Callable[[], float],
) -> None:
    """Rounds of rollouts, each for the alternatives the allocation keeps going
    (:func:`executive.decision.rollout_allocation.allocate`), until none is left or the next
    round would overrun the time budget (once every alternative has its minimum; a round's
    time is foreseen from the last one's, per job)."""
    cfg, risk = scenario.risk.rollouts, scenario.risk
    results, t0 = verdict.alternatives, clock()
    by_name = {plan.name: plan for plan in plans}
    state, job_s = dict.fromkeys(by_name, GOING), 0.0  # wall time of the last round per job
    while going := [name for name, why in state.items() if why == GOING]:
        jobs = [
            RolloutJob(scenario, by_name[name], rollout_seed(scenario.trials.seed, j), q_start)
            for k in range(cfg.batch)
            for name in going
            if (j := results[name].rollouts + k) < cfg.count
        ]
        short = any(results[name].rollouts < cfg.min_count for name in going)
        if not short and clock() - t0 + job_s * len(jobs) > cfg.budget_s:
            state.update(dict.fromkeys(going, "budget"))
            break
        started = clock()
        for job, record in zip(jobs, run_map(jobs), strict=True):
            result = results[job.plan.name]
            result.counts[record["outcome"]] += 1
            result.rollouts += 1
            verdict.physics_steps += int(record.get("physics_steps", 0))
        job_s = (clock() - started) / len(jobs)
        view = _contention(results, plans, risk)
        verdict.confidence, verdict.opportunity_cost = view.choice.confidence, view.choice.opportunity_cost
        state = allocate(view, {name: results[name].rollouts for name in by_name}, cfg)
    for name, why in state.items():
        results[name].stopped = why
    reasons = set(state.values())
    verdict.stopped = "budget" if "budget" in reasons else COUNT if COUNT in reasons else CLEAR
    verdict.rollouts = max(results[name].rollouts for name in by_name)
    verdict.rollout_s = clock() - t0


def _contention(
    results: Mapping[str, PhysicsResult], plans: Sequence[AlternativePlan], risk: RiskConfig
) -> Contention:
    """The stopping rule's view of the choice now (:func:`contention`): P(the current best
    is within the indifference of the best), the expected opportunity cost of choosing it, each
    alternative's chance to beat it, and the chance that it needs approval. Its draws are seeded
    with the most rollouts any alternative has had."""
    cfg = risk.rollouts
    candidates = {
        p.name: posteriors(
            results[p.name].prior, results[p.name].counts, results[p.name].rollouts, cfg.prior_weight
        )
        for p in plans
    }
    offsets = {p.name: results[p.name].analytic.time_loss for p in plans}
    seed = max(results[p.name].rollouts for p in plans)
    return contention(candidates, risk.ordering, cfg.indifference, risk.threshold, seed=seed, offsets=offsets)


def exit_with_parent(parent: int, period_s: float = 0.2) -> threading.Thread:
    """Start a thread that ends this process (``os._exit``) once its parent ``parent`` is gone.

    A pool's worker waits on its task queue forever; when the process that owns the pool dies
    without closing it (a planning worker killed mid-plan), nobody else would end it. The parent
    is given, not read here: it may have died while this process was still starting.
    """

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(period_s)
        os._exit(1)

    thread = threading.Thread(target=watch, name="exit-with-parent", daemon=True)
    thread.start()
    return thread


def _init_worker(owner: int) -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")
    # Ctrl-C on a terminal reaches the whole foreground process group: the process that owns
    # the pool handles it and shuts the workers down; a worker must not die printing a traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    exit_with_parent(owner)


def _warm_up() -> None:
    """Import what a job runs (a worker's first job would pay for it)."""


class RolloutPool:
    """Warm worker processes that run :class:`RolloutJob` s; call it with jobs, get records.

    The processes are spawned (clean: no inherited MuJoCo or GL state, no threads) on
    :meth:`start` or the first call, and kept until :meth:`close`. A worker that dies takes
    the pool down with a :class:`RolloutError` (never a hang); the next call starts a new one.
    The workers end by themselves when the process that owns the pool dies (:func:`exit_with_parent`).
    """

    def __init__(self, jobs: int) -> None:
        if jobs < 1:
            raise ValueError(f"a rollout pool needs at least 1 worker; got {jobs}")
        self.jobs = jobs
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None

    def start(self) -> concurrent.futures.ProcessPoolExecutor:
        """The worker processes, spawned now if they are not yet running."""
        if self._pool is None:
            ctx = multiprocessing.get_context("spawn")
            self._pool = concurrent.futures.ProcessPoolExecutor(
                self.jobs, mp_context=ctx, initializer=_init_worker, initargs=(os.getpid(),)
            )
        return self._pool

    def warm(self) -> list[concurrent.futures.Future[None]]:
        """Start the workers and have each import the physics (returns at once; the futures
        finish when they are ready). Workers already running are left alone (no futures)."""
        if self._pool is not None:
            return []
        return self._submit([(_warm_up,)] * self.jobs)

    def __call__(self, jobs: Sequence[RolloutJob]) -> list[dict[str, Any]]:
        try:
            return [future.result() for future in self._submit([(run_job, job) for job in jobs])]
        except concurrent.futures.process.BrokenProcessPool as exc:
            self.close()
            raise RolloutError(f"a physics worker process died: {exc}") from exc

    def _submit(self, calls: Sequence[tuple[Any, ...]]) -> list[concurrent.futures.Future[Any]]:
        """Submit each ``(function, *args)``; the pool spawns its processes as calls are submitted,
        here at the normal policy whatever the calling thread's."""
        pool = self.start()
        with normal_policy_children():
            return [pool.submit(*call) for call in calls]

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


def apply_verdict(
    results: Sequence[AlternativeRisk], verdict: PhysicsVerdict, confidence: float
) -> list[AlternativeRisk]:
    """``results`` as physics left them: failed dry runs infeasible, the rest with their fused risk.

    Every checked alternative carries its physics summary (``physics``); one whose dry run failed
    keeps its analytic risk there, and its reason names the detector's verdict.
    """
    out = []
    for alt in results:
        checked = verdict.alternatives.get(alt.name)
        if checked is None:
            out.append(alt)
            continue
        physics = checked.as_dict(confidence)
        if not checked.dry_run_ok:
            physics["analytic"] = checked.analytic.as_dict()
            out.append(
                dataclasses.replace(
                    alt, feasible=False, risk=None, error=checked.dry_run_reason(), physics=physics
                )
            )
        else:
            out.append(dataclasses.replace(alt, risk=checked.risk, physics=physics))
    return out


class PhysicsCheck:
    """The physics check of the executive's decisions: a warm :class:`RolloutPool` and the rule.

    Args:
        jobs: worker processes (``risk.rollouts.jobs``).
        run_map: runs the physics jobs instead of the pool (e.g. in the calling process, as a
            campaign's worker does); None: the pool's ``jobs`` worker processes.

    Use :meth:`check` on a decision's assessed alternatives; :meth:`close` when done.
    """

    def __init__(self, jobs: int, run_map: RunMap | None = None) -> None:
        self.pool = RolloutPool(jobs)
        self.run_map: RunMap = self.pool if run_map is None else run_map

    def check(
        self, world: World, results: Sequence[AlternativeRisk], q_start: np.ndarray | None = None
    ) -> tuple[list[AlternativeRisk], PhysicsVerdict]:
        """Dry-run and roll out the feasible ``results`` planned on the estimate ``world``."""
        feasible = [a for a in results if a.plan is not None and a.risk is not None]
        plans = {a.name: a.plan for a in feasible if a.plan is not None}
        analytic = {a.name: a.risk for a in feasible if a.risk is not None}
        scenario = estimate_scenario(world)
        verdict = (
            check_alternatives(plans, analytic, scenario, self.run_map, q_start=q_start)
            if plans
            else PhysicsVerdict({})
        )
        return apply_verdict(results, verdict, scenario.risk.rollouts.confidence), verdict

    def close(self) -> None:
        self.pool.close()
