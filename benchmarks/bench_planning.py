"""Speed of planning plus risk assessment of every alternative of book_transfer, on one core.

Measures, in one run (issue #4, "Speed"):

1. planning plus risk assessment of all alternatives of ``book_transfer``
   (``executive.decision.assessment.assess_task``, what ``executive plan`` does), target under 1 s;
2. the cost of the risk evaluation per knot (collision profile, fall, grasp and their
   combination, divided by the knots of the alternative's trajectories) against the cost of
   raw ``mujoco.mj_kinematics`` plus raw ``coal.distance`` on exactly the pairs the collision
   model's broad phase sent to coal at those knots, target within 3x.

Times are CPU seconds of this process (``time.process_time``, best of the repeats): other work
on a shared machine inflates them less than wall time (also printed for the total).
Prints the targets next to the measured values; does not assert.
Run: ``python benchmarks/bench_planning.py [repeats]``
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: no BLAS threads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys
import time

import numpy as np
from raw_reference import raw_distances, record_pairs

from executive.decision.assessment import AlternativeRisk, assess_plan, assess_task
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner
from executive.risk.collision import CollisionModel
from executive.scenario import load
from executive.world.model import World, build

__all__ = ["main"]

TARGET_TOTAL_S = 1.0
TARGET_PER_KNOT_RATIO = 3.0


def _knots(plan: AlternativePlan) -> int:
    return sum(len(t.times) for t in plan.trajectories.values())


def _raw_seconds(world: World, model: CollisionModel, plan: AlternativePlan, repeats: int) -> float:
    """Best CPU time of mj_kinematics + coal.distance on the knots and pairs assess_plan visits."""
    run = raw_distances(world.model, record_pairs(model, lambda: assess_plan(world, plan, model)))
    best = np.inf
    for _ in range(repeats):
        t0 = time.process_time()
        run()
        best = min(best, time.process_time() - t0)
    return float(best)


def _assess_seconds(world: World, plan: AlternativePlan, model: CollisionModel, repeats: int) -> float:
    """Best CPU time of assess_plan (collision, fall, grasp, combined) on one planned alternative."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.process_time()
        assess_plan(world, plan, model)
        best = min(best, time.process_time() - t0)
    return float(best)


def main(repeats: int = 3) -> None:
    world = build(load("book_transfer"))
    task = world.scenario.mission[0]
    tick = time.perf_counter()
    planner = Planner(world)
    model = CollisionModel(world, world.scenario.risk, uncertainty=world.scenario.uncertainty)
    setup = time.perf_counter() - tick
    assess_task(world, task, planner, model)  # warm-up: caches, imports
    totals: list[float] = []
    walls: list[float] = []
    runs: list[list[AlternativeRisk]] = []
    for _ in range(repeats):
        tick, wall = time.process_time(), time.perf_counter()
        runs.append(assess_task(world, task, planner, model))
        totals.append(time.process_time() - tick)
        walls.append(time.perf_counter() - wall)
    best = runs[int(np.argmin(totals))]
    print(f"book_transfer: planner + collision model setup {setup * 1e3:.0f} ms (once per world)")
    print(
        f"{'alternative':<15}{'plan s*':>8}{'assess s':>10}{'knots':>7}"
        f"{'assess us/knot':>16}{'raw us/knot':>13}{'ratio':>7}"
    )
    sum_assess = sum_raw = 0.0
    sum_knots = 0
    for alt in best:
        if alt.plan is None:
            print(f"{alt.name:<15}infeasible: {alt.error}")
            continue
        knots = _knots(alt.plan)
        assess = _assess_seconds(world, alt.plan, model, repeats)
        raw = _raw_seconds(world, model, alt.plan, repeats)
        sum_assess, sum_raw, sum_knots = sum_assess + assess, sum_raw + raw, sum_knots + knots
        print(
            f"{alt.name:<15}{alt.plan_s:>8.3f}{assess:>10.3f}{knots:>7d}"
            f"{assess / knots * 1e6:>16.1f}{raw / knots * 1e6:>13.1f}{assess / raw:>7.2f}"
        )
    total = float(min(totals))
    print("(* plan s: wall time in the fastest run, as assess_task records it; the other columns are CPU)")
    print(
        f"planning + risk assessment, all alternatives: {total:.3f} s CPU (best of {repeats}; "
        f"wall {min(walls):.3f} s); target < {TARGET_TOTAL_S:.1f} s -> "
        f"{total / TARGET_TOTAL_S:.2f}x the target"
    )
    if sum_raw > 0.0:
        ratio = sum_assess / sum_raw
        print(
            f"risk evaluation per knot: {sum_assess / sum_knots * 1e6:.1f} us vs raw mj_kinematics + "
            f"coal.distance on the same pairs {sum_raw / sum_knots * 1e6:.1f} us: {ratio:.2f}x; target <= "
            f"{TARGET_PER_KNOT_RATIO:.0f}x -> {ratio / TARGET_PER_KNOT_RATIO:.2f}x the target"
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
