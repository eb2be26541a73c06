"""What the physics check of a decision costs: dry runs against raw physics, and a whole decision.

    python benchmarks/bench_physics_check.py [SCENARIO] [--rollouts N] [--jobs J] [--repeat R]

1. **Dry runs against raw ``mj_step``.** Each alternative is planned on the estimate and
   dry-run in this process exactly as the physics check does it (:func:`run_job`: the world
   built, the subtree built and ticked, the detectors after every step). The controls of
   every physics step are recorded (``bench_executive``'s per-period recording) and replayed
   from the same initial state in a bare ``mj_step`` loop: the same steps, checked bit for
   bit by the final state. Printed: wall and thread-CPU ratio of the dry run to the replay,
   per alternative and for all of them (target: 1.3).
2. **A whole physics-checked decision** with ``J`` warm worker processes: plan and assess
   every alternative (analytic), dry-run them, roll out to the stopping rule. Printed: the
   wall time of each part, the rollouts used and why they stopped (target: under 10 s with
   2 jobs), and the same decision with a cold pool (processes started for it).
3. **Planning and analytic risk alone** (``executive plan`` without the physics check): CPU.

Ratios are measured within one run, so they hold on a noisy machine.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import time

import mujoco
import numpy as np
from bench_executive import STATE, _PeriodRecording, _replay

from executive.decision.assessment import assess_task
from executive.decision.physics_check import (
    RolloutJob,
    RolloutPool,
    check_alternatives,
    estimate_scenario,
    run_job,
    with_rollouts,
)
from executive.scenario import load
from executive.schema.types import Scenario
from executive.world.model import build


def dry_run_overhead(scenario: Scenario) -> dict[str, float]:
    """Prints each alternative's dry run against the raw replay of its steps; returns the sums
    (``wall``, ``cpu``, ``raw_wall``, ``raw_cpu``: seconds; ``steps``)."""
    world = build(scenario)
    results = assess_task(world, scenario.mission[0])
    estimate = estimate_scenario(world)
    print(f"{'alternative':<15}{'steps':>8}{'dry s':>8}{'raw s':>8}{'wall x':>8}{'cpu x':>8}  outcome")
    totals = np.zeros(4)
    steps = 0
    for alt in results:
        if alt.plan is None:
            print(f"{alt.name:<15}infeasible: {alt.error}")
            continue
        recording = _PeriodRecording()
        # the truth world the job builds: record its initial state by building it the same way
        probe = build(estimate)
        state0 = np.empty(mujoco.mj_stateSize(probe.model, STATE))
        mujoco.mj_getState(probe.model, probe.data, state0, STATE)
        recording.install()
        try:
            w0, c0 = time.perf_counter(), time.thread_time()
            record = run_job(RolloutJob(estimate, alt.plan, None))
            wall, cpu = time.perf_counter() - w0, time.thread_time() - c0
        finally:
            recording.uninstall()
        rows = recording.rows()
        raw_wall, _, _, _ = _replay(probe.model, state0, rows, len(rows))
        c1 = time.thread_time()
        _replay(probe.model, state0, rows, len(rows))
        raw_cpu = time.thread_time() - c1
        totals += (wall, cpu, raw_wall, raw_cpu)
        steps += len(rows)
        print(
            f"{alt.name:<15}{len(rows):>8}{wall:>8.2f}{raw_wall:>8.2f}{wall / raw_wall:>8.2f}"
            f"{cpu / raw_cpu:>8.2f}  {record['outcome']}"
        )
    print(
        f"{'all':<15}{'':>8}{totals[0]:>8.2f}{totals[2]:>8.2f}{totals[0] / totals[2]:>8.2f}"
        f"{totals[1] / totals[3]:>8.2f}  (target 1.3)"
    )
    sums = dict(zip(("wall", "cpu", "raw_wall", "raw_cpu"), map(float, totals), strict=True))
    return sums | {"steps": steps}


def decision(scenario: Scenario, pool: RolloutPool, label: str) -> None:
    t0 = time.perf_counter()
    world = build(scenario)
    results = assess_task(world, scenario.mission[0])
    t1 = time.perf_counter()
    plans = {a.name: a.plan for a in results if a.plan is not None}
    analytic = {a.name: a.risk for a in results if a.risk is not None}
    verdict = check_alternatives(plans, analytic, estimate_scenario(world), pool)
    t2 = time.perf_counter()
    order = sorted(verdict.alternatives.values(), key=lambda r: r.risk.value(scenario.risk.ordering))
    print(
        f"{label}: {t2 - t0:.2f} s wall (plan + analytic {t1 - t0:.2f}, "
        f"dry runs {verdict.dry_run_s:.2f}, rollouts {verdict.rollout_s:.2f}: {verdict.rollouts} "
        f"per alternative, stopped by {verdict.stopped}, P(choice clear) {verdict.confidence}); "
        f"chosen {order[0].alternative if order else None}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument(
        "--rollouts",
        type=int,
        default=None,
        help="risk.rollouts.count (default: the scenario's)",
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    scenario = with_rollouts(load(args.scenario), args.rollouts)
    print("1. dry runs in this process against raw mj_step of the same steps")
    dry_run_overhead(scenario)
    print(
        f"\n2. a whole decision with {args.jobs} worker processes, "
        f"{scenario.risk.rollouts.count} rollouts at most"
    )
    cold = RolloutPool(args.jobs)
    decision(scenario, cold, "cold pool (processes started by the decision)")
    cold.close()
    warm = RolloutPool(args.jobs)
    concurrent.futures.wait(warm.warm())  # started and idle, as the executive keeps it
    for k in range(args.repeat):
        decision(scenario, warm, f"warm pool, run {k + 1}")
    warm.close()
    print("\n3. planning and analytic risk alone (executive plan without the physics check)")
    world = build(scenario)
    c0, w0 = time.process_time(), time.perf_counter()
    assess_task(world, scenario.mission[0])
    print(
        f"   {time.process_time() - c0:.2f} s CPU, {time.perf_counter() - w0:.2f} s wall (target under 1 s)"
    )


if __name__ == "__main__":
    main()
