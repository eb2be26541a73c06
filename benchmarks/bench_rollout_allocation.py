"""Physics steps and wall time of physics-checked decisions: a fixed count against the allocation.

    python benchmarks/bench_rollout_allocation.py [SCENARIO ...] [--jobs J] [--fixed N]

Every task of each scenario (default: book_transfer, glovebox, pick_place_push) is decided as
``executive plan`` decides it (plan, analytic risk, dry runs, rollouts, fusion; a walk's end
starts the next task) twice, on the same warm pool of ``J`` worker processes:

* **fixed**: ``N`` rollouts for every alternative (``count = min_count = batch = N``: the
  rollouts before the allocation, default 4);
* **allocated**: the scenario's ``risk.rollouts`` (the minimum for every alternative, then
  rounds only for those still in contention, up to ``count``;
  :mod:`executive.decision.rollout_allocation`).

The time budget is lifted in both, so the machine's load does not change the counts. Per task
it prints each alternative's rollouts, the physics steps the dry runs and rollouts simulated,
the choice, whether it needs approval and the largest change of a fused value. Per scenario:
the steps and the wall time of both, and the wall time over the raw ``mj_step`` time of the
same number of steps divided over the jobs (the raw time of a step measured by replaying a dry
run's recorded controls in a bare ``mj_step`` loop, ``bench_executive``'s replay; target 1.3),
for the physics check alone and with planning.

Ratios are measured within one run, so they hold on a noisy machine.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import time
from typing import Any

import mujoco
import numpy as np
from bench_executive import STATE, _PeriodRecording, _replay

from executive.decision.after_task import chosen_index, state_after
from executive.decision.assessment import assess_task
from executive.decision.physics_check import PhysicsCheck, RolloutJob, RolloutPool, estimate_scenario, run_job
from executive.scenario import load
from executive.schema.types import Scenario
from executive.world.model import build


def with_config(scenario: Scenario, **fields: Any) -> Scenario:
    rollouts = dataclasses.replace(scenario.risk.rollouts, budget_s=3600.0, **fields)
    return dataclasses.replace(scenario, risk=dataclasses.replace(scenario.risk, rollouts=rollouts))


def raw_step_s(scenario: Scenario, cpu: bool = False) -> float:
    """Seconds of a bare ``mj_step`` on this scene: a dry run's controls replayed (best of two;
    ``cpu``: thread CPU seconds, else wall)."""
    world = build(scenario)
    plan = next(a.plan for a in assess_task(world, scenario.mission[0]) if a.plan is not None)
    estimate = estimate_scenario(world)
    probe = build(estimate)
    state0 = np.empty(mujoco.mj_stateSize(probe.model, STATE))
    mujoco.mj_getState(probe.model, probe.data, state0, STATE)
    recording = _PeriodRecording()
    recording.install()
    try:
        run_job(RolloutJob(estimate, plan, None))
    finally:
        recording.uninstall()
    rows = recording.rows()
    best = min(_replay(probe.model, state0, rows, 0)[2 if cpu else 1] for _ in range(2))
    return best / len(rows)


def decide_all(scenario: Scenario, physics: PhysicsCheck) -> dict[str, Any]:
    """Every task decided as ``executive plan`` does; per task what the check did and chose."""
    world = build(scenario)
    q_start, tasks, steps, check_s, plan_s = None, [], 0, 0.0, 0.0
    ordering = scenario.risk.ordering
    for task in scenario.mission:
        t0 = time.perf_counter()
        analytic = assess_task(world, task, q_start=q_start)
        t1 = time.perf_counter()
        alternatives, verdict = physics.check(world, analytic, q_start=q_start)
        check_s, plan_s = check_s + time.perf_counter() - t1, plan_s + t1 - t0
        steps += verdict.physics_steps
        chosen = chosen_index(alternatives, ordering)
        best = alternatives[chosen] if chosen is not None else None
        tasks.append(
            {
                "rollouts": {n: r.rollouts for n, r in verdict.alternatives.items() if r.dry_run_ok},
                "stopped": verdict.stopped,
                "steps": verdict.physics_steps,
                "chosen": best.name if best is not None else None,
                "approval": best is not None
                and best.risk is not None
                and best.risk.value(ordering) > scenario.risk.threshold,
                "values": {a.name: a.risk.value(ordering) for a in alternatives if a.risk is not None},
            }
        )
        q_start = state_after(scenario, world, task, alternatives, q_start)
    return {"tasks": tasks, "steps": steps, "check_s": check_s, "plan_s": plan_s}


def compare(name: str, jobs: int, fixed: int, pool: RolloutPool) -> None:
    base = load(name)
    step_s = raw_step_s(base)
    runs = {}
    for label, scenario in (
        ("fixed", with_config(base, count=fixed, min_count=fixed, batch=fixed)),
        ("allocated", with_config(base)),
    ):
        runs[label] = decide_all(scenario, PhysicsCheck(jobs, run_map=pool))
    before, after = runs["fixed"], runs["allocated"]
    print(f"\n{name}: raw mj_step {step_s * 1e6:.0f} us a step; {jobs} jobs")
    for i, (b, a) in enumerate(zip(before["tasks"], after["tasks"], strict=True)):
        drift = max(
            (abs(a["values"][k] - v) for k, v in b["values"].items() if k in a["values"]), default=0.0
        )
        print(
            f"  task {i}: rollouts {b['rollouts']} -> {a['rollouts']} (stopped by {a['stopped']}); "
            f"steps {b['steps']} -> {a['steps']}; chosen {b['chosen']} -> {a['chosen']}; "
            f"approval {b['approval']} -> {a['approval']}; largest fused change {drift:.4f}"
        )
    for label, run in runs.items():
        raw = run["steps"] * step_s / jobs
        print(
            f"  {label:<9}: {run['steps']:>8} steps, physics check {run['check_s']:6.2f} s wall = "
            f"{run['check_s'] / raw:.2f}x raw/jobs; with planning ({run['plan_s']:.2f} s) "
            f"{(run['check_s'] + run['plan_s']) / raw:.2f}x (target 1.3)"
        )
    print(f"  steps allocated / fixed: {after['steps'] / before['steps']:.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=["book_transfer", "glovebox", "pick_place_push"])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--fixed", type=int, default=4, help="rollouts per alternative of the fixed run")
    args = parser.parse_args()
    pool = RolloutPool(args.jobs)
    concurrent.futures.wait(pool.warm())  # started and idle, as the executive keeps it
    try:
        for name in args.scenarios:
            compare(name, args.jobs, args.fixed, pool)
    finally:
        pool.close()


if __name__ == "__main__":
    main()
