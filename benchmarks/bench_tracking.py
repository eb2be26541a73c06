"""The tracking model against physics: a grid of loads and reaches, predicted vs observed stall rate.

Each cell is ``book_transfer`` reduced to one hand: the left hand carries a book of the cell's
mass (kg) from (0.40, 0.34) to a target ``reach`` m ahead of the robot on the same side (no stack,
one alternative, ``left``), the targets running to the edge of the hand's workspace. Per cell it
plans the motion on the estimate, predicts P(tracking) from the servos' statics
(:mod:`executive.risk.tracking`), refines it with a dry run's measured end errors, and runs
``count`` truths (object mass 10 %, CoM 1 cm, object pose 1 cm / 3 deg, 1-sigma) with the bundled
servos (:func:`executive.execution.runner.execute_plan`): the observed stall rate is the share of
trials that end with the verdict ``tracking`` (a hand farther from its planned end than the move's
3 cm), with the other outcomes counted beside it. A cell whose motion does not plan is reported so.

Run: ``python benchmarks/bench_tracking.py [count] [--jobs N]`` (defaults: 6 truths, 2 jobs).
Results: docs/risk_models.md, "Tracking".
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["cell_scenario", "main", "run_cell"]

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
MASSES = (0.5, 3.0, 5.0, 6.5, 8.0)
REACHES = (0.50, 0.62, 0.72, 0.80)


def cell_scenario(mass: float, reach: float) -> Any:
    """book_transfer with one book of ``mass`` kg at (0.40, 0.34), its target ``reach`` m ahead on
    the left, no stack, only the left hand's one-arm alternative."""
    import yaml

    from executive.scenario import from_dict

    doc = yaml.safe_load((SCENARIOS / "book_transfer.yaml").read_text())
    doc["scene"]["objects"][0].update(position=[0.40, 0.34], mass=mass)
    doc["scene"]["obstacles"] = []
    doc["mission"] = [{"transfer": {"object": "book", "to": [reach, 0.34], "alternatives": ["left"]}}]
    return from_dict(doc, f"tracking grid {mass} kg, {reach} m")


def run_cell(args: tuple[float, float, int]) -> dict[str, Any]:
    """Plan one cell, predict its P(tracking) (statics, then refined by the dry run), run its truths."""
    from executive.decision.assessment import assess_plan
    from executive.decision.physics_check import measured
    from executive.execution.runner import execute_plan, outcome_fields
    from executive.planning.planner import Planner, PlanningError
    from executive.risk.collision import CollisionModel
    from executive.tasks.steps import plan_alternative
    from executive.world.model import build, sample_perturbation

    mass, reach, count = args
    scenario = cell_scenario(mass, reach)
    world, task = build(scenario), scenario.mission[0]
    out: dict[str, Any] = {"mass": mass, "reach": reach}
    try:
        plan = plan_alternative(Planner(world), world, task, "left")
    except PlanningError as exc:
        return {**out, "planned": False, "why": str(exc)[:90]}
    risk = assess_plan(world, plan, CollisionModel(world, scenario.risk, uncertainty=scenario.uncertainty))
    report = risk.components["tracking"]
    dry = outcome_fields(execute_plan(plan, build(scenario), task))
    refined = measured(risk, dry, scenario.risk)
    outcomes: Counter[str] = Counter()
    for seed in range(1, count + 1):
        truth = build(scenario, sample_perturbation(scenario, np.random.default_rng(seed)), kind="truth")
        outcomes[_outcome(execute_plan, plan, truth, task)] += 1
    return {
        **out,
        "planned": True,
        "statics": report.probability,
        "dry_run": dry["outcome"],
        "measured": refined.components["tracking"].probability if refined is not None else None,
        "largest_error_mm": 1000 * float(report.details.get("largest_hand_error", 0.0)),
        "peak_torque_ratio": float(report.details.get("peak_torque_ratio", 0.0)),
        "outcomes": dict(outcomes),
        "count": count,
    }


def _outcome(execute: Any, plan: Any, truth: Any, task: Any) -> str:
    """One truth's outcome: ``success``, or the failure's verdict."""
    result = execute(plan, truth, task)
    if result.success:
        return "success"
    return result.failure.mode if result.failure is not None else result.outcome


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("count", nargs="?", type=int, default=6)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    cells = [(m, r, args.count) for m in MASSES for r in REACHES]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        rows = list(pool.map(run_cell, cells))
    print(
        "| mass (kg) | reach (m) | P(tracking) statics | dry run | P(tracking) after the dry run | "
        "observed stalls | other outcomes | largest predicted end error | peak torque / limit |"
    )
    print("|---:|---:|---:|---|---:|---:|---|---:|---:|")
    for row in rows:
        print(_row(row))
    wall = time.perf_counter() - t0
    print(f"\n{len(cells)} cells x {args.count} truths in {wall:.0f} s wall ({args.jobs} jobs)")


def _row(row: dict[str, Any]) -> str:
    """One cell's line of the table."""
    if not row["planned"]:
        return f"| {row['mass']} | {row['reach']} | does not plan: {row['why']} | | | | | | |"
    seen = row["outcomes"]
    other = ", ".join(f"{v} {k}" for k, v in sorted(seen.items()) if k not in ("tracking", "success")) or "-"
    refined = "-" if row["measured"] is None else f"{row['measured']:.3f}"
    return (
        f"| {row['mass']} | {row['reach']} | {row['statics']:.3f} | {row['dry_run']} | {refined} | "
        f"{seen.get('tracking', 0)}/{row['count']} | {other} | {row['largest_error_mm']:.1f} mm | "
        f"{row['peak_torque_ratio']:.2f} |"
    )


if __name__ == "__main__":
    main()
