"""Speed of planning plus risk assessment of every alternative of book_transfer, on one core.

Measures, in one run (issue #4, "Speed"; issue #31, item 2):

1. planning plus risk assessment of all alternatives of ``book_transfer``
   (``executive.decision.assessment.assess_task``, what ``executive plan`` does), target under 1 s
   on the docs' machine;
2. the cost of the risk evaluation per knot (every failure mode's model and their combination,
   ``assess_plan``, divided by the knots of the alternative's trajectories) against the cost of
   raw ``mujoco.mj_kinematics`` plus raw ``coal.distance`` on exactly the pairs the collision
   model's broad phase sent to coal at those knots, target within 2x;
3. with ``--against TREE`` (another checkout of the project, e.g. main's), the same planning plus
   risk of that tree's code and of this one, measured in alternating processes of one run
   (``--rounds``), and their ratio: a before/after that holds on a noisy machine;
4. with ``--profile N``, instead: cProfile's N top entries of one planning + risk of all
   alternatives (after a warm-up), by cumulative and by own time (docs/performance.md).

Times are CPU seconds of the measuring process (``time.process_time``, best of the repeats): other
work on a shared machine inflates them less than wall time (also printed for the total). Ratios
divide times measured in the same run. Prints the targets next to the measured values; does not
assert. Run: ``python benchmarks/bench_planning.py [repeats] [--against TREE [--rounds R]] [--profile N]``
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: no BLAS threads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import cProfile
import json
import pstats
import subprocess
import sys
import time
from pathlib import Path

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
TARGET_PER_KNOT_RATIO = 2.0


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


def measure(repeats: int = 3, *, raw: bool = True) -> dict[str, float]:
    """Best CPU seconds of planning + risk of all alternatives (``total``), the sum over the
    alternatives of ``assess_plan`` (``assess``) and, if ``raw``, of the raw reference (``raw``),
    with the knots; prints the per-alternative table when ``raw``."""
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
    if raw:
        print(f"book_transfer: planner + collision model setup {setup * 1e3:.0f} ms (once per world)")
        print(
            f"{'alternative':<15}{'plan s*':>8}{'assess s':>10}{'knots':>7}"
            f"{'assess us/knot':>16}{'raw us/knot':>13}{'ratio':>7}"
        )
    sums = {"total": float(min(totals)), "wall": float(min(walls)), "assess": 0.0, "raw": 0.0, "knots": 0.0}
    for alt in best:
        if alt.plan is None:
            print(f"{alt.name:<15}infeasible: {alt.error}")
            continue
        knots = _knots(alt.plan)
        assess = _assess_seconds(world, alt.plan, model, repeats)
        sums["assess"] += assess
        sums["knots"] += knots
        if not raw:
            continue
        raw_s = _raw_seconds(world, model, alt.plan, repeats)
        sums["raw"] += raw_s
        print(
            f"{alt.name:<15}{alt.plan_s:>8.3f}{assess:>10.3f}{knots:>7d}"
            f"{assess / knots * 1e6:>16.1f}{raw_s / knots * 1e6:>13.1f}{assess / raw_s:>7.2f}"
        )
    return sums


def _child(tree: Path, repeats: int, raw: bool) -> dict[str, float]:
    """:func:`measure` in a fresh process running the code of ``tree`` (its ``executive``)."""
    code = (
        "import json, sys; sys.path.insert(1, sys.argv[1]); import bench_planning as b; "
        "print(json.dumps(b.measure(int(sys.argv[2]), raw=sys.argv[3] == '1')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent), str(repeats), "1" if raw else "0"],
        cwd=tree,
        env={**__import__("os").environ, "PYTHONPATH": str(tree)},
        capture_output=True,
        text=True,
        check=True,
    )
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def against(tree: Path, rounds: int, repeats: int) -> None:
    """Planning + risk of ``tree``'s code and of this one, alternating fresh processes, best of
    ``rounds`` each; this tree's processes also time the raw reference."""
    here = Path(__file__).resolve().parent.parent
    best: dict[str, dict[str, float]] = {}
    for _ in range(rounds):
        for label, root, with_raw in (("other", tree, False), ("this", here, True)):
            got = _child(root, repeats, with_raw)
            keep = best.setdefault(label, got)
            for key in ("total", "assess", "raw"):
                keep[key] = min(keep[key], got[key])
    old, new = best["other"], best["this"]
    print(f"\n{tree} against {here} (best of {rounds} alternating processes, CPU s):")
    for name, key in (
        ("planning + risk, 3 alternatives", "total"),
        ("risk (assess_plan) of the 3", "assess"),
    ):
        print(f"  {name:<33}{old[key]:.3f} -> {new[key]:.3f} ({new[key] / old[key]:.2f}x)")
    knots, raw = new["knots"], new["raw"]
    print(
        f"  per knot against raw mj_kinematics + coal ({raw / knots * 1e6:.1f} us/knot): risk "
        f"{old['assess'] / raw:.2f}x -> {new['assess'] / raw:.2f}x; planning + risk "
        f"{old['total'] / raw:.2f}x -> {new['total'] / raw:.2f}x"
    )


def profile(top: int) -> None:
    """cProfile's ``top`` entries of one planning + risk of all alternatives (after a warm-up)."""
    world = build(load("book_transfer"))
    task = world.scenario.mission[0]
    assess_task(world, task)  # warm-up: caches, imports
    profiler = cProfile.Profile()
    profiler.runcall(assess_task, world, task)
    stats = pstats.Stats(profiler)
    for key in ("cumulative", "tottime"):
        stats.sort_stats(key).print_stats(top)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("repeats", nargs="?", type=int, default=3)
    parser.add_argument("--against", type=Path, default=None, help="another checkout to compare with")
    parser.add_argument("--rounds", type=int, default=3, help="alternating processes per tree (--against)")
    parser.add_argument("--profile", type=int, default=0, metavar="N", help="print a profile's N top entries")
    args = parser.parse_args()
    if args.profile > 0:
        profile(args.profile)
        return
    sums = measure(args.repeats)
    total, raw, knots = sums["total"], sums["raw"], sums["knots"]
    print("(* plan s: wall time in the fastest run, as assess_task records it; the other columns are CPU)")
    print(
        f"planning + risk assessment, all alternatives: {total:.3f} s CPU (best of {args.repeats}; "
        f"wall {sums['wall']:.3f} s); target < {TARGET_TOTAL_S:.1f} s -> "
        f"{total / TARGET_TOTAL_S:.2f}x the target; {total / raw:.1f}x the raw kinematics + coal "
        "of its knots"
    )
    if raw > 0.0:
        ratio = sums["assess"] / raw
        print(
            f"risk evaluation per knot: {sums['assess'] / knots * 1e6:.1f} us vs raw mj_kinematics + "
            f"coal.distance on the same pairs {raw / knots * 1e6:.1f} us: {ratio:.2f}x; target <= "
            f"{TARGET_PER_KNOT_RATIO:.0f}x -> {ratio / TARGET_PER_KNOT_RATIO:.2f}x the target"
        )
    if args.against is not None:
        against(args.against.resolve(), args.rounds, args.repeats)


if __name__ == "__main__":
    main()
