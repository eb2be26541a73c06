"""``executive plan``: every alternative of every task planned, its risk assessed and checked in
physics (dry runs, rollouts), printed as a table (or ``--json``), nothing executed.

Each task is planned from where the one before leaves the robot and the objects (its chosen
alternative's plan: :func:`executive.decision.after_task.state_after`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from executive.cli.arguments import (
    EXIT_OK,
    ROLLOUTS,
    ROLLOUTS_HELP,
    SCENARIO_HELP,
    THRESHOLD_HELP,
    load_gated,
)
from executive.cli.output_paths import check_folder
from executive.schema.types import Scenario
from executive.world.model import World, build

if TYPE_CHECKING:
    from executive.decision.assessment import AlternativeRisk

__all__ = ["add_parser", "run_plan"]

FloatArray = NDArray[np.float64]


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The plan command."""
    p = sub.add_parser("plan", help="plan every alternative and print its predicted risk (no execution)")
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.add_argument("--json", action="store_true", help="print the table as JSON for machines")
    p.add_argument("--plot", metavar="DIR", help="write CoM/support-polygon and distance plots to DIR")
    p.add_argument("--rollouts", type=ROLLOUTS, metavar="N", help=ROLLOUTS_HELP)
    p.add_argument("--threshold", type=float, metavar="X", help=THRESHOLD_HELP)
    p.set_defaults(func=run_plan)


def run_plan(args: argparse.Namespace) -> int:
    """``executive plan``: each task's alternatives planned, assessed and checked in physics."""
    from executive.decision.after_task import state_after
    from executive.decision.assessment import assess_task
    from executive.decision.physics_check import PhysicsCheck
    from executive.report.plots import risk_json, risk_table

    if args.plot:
        check_folder(args.plot, "--plot")
    scenario = load_gated(args)
    world = build(scenario)
    tasks = []
    physics = PhysicsCheck(scenario.risk.rollouts.jobs)
    physics.pool.warm()  # the workers start while the planner works
    q_start: FloatArray | None = None  # home; then where the task before leaves the robot
    try:
        for i, task in enumerate(scenario.mission):
            label = f"{i}: {task.label()}"
            analytic = assess_task(world, task, q_start=q_start)
            if not args.json:  # the analytic answer at once, the physics check's after it
                print(risk_table(scenario, f"{label}, analytic", analytic))
                print(_checking_text(scenario, analytic), flush=True)
            alternatives, _ = physics.check(world, analytic, q_start=q_start)
            tasks.append((label, alternatives))
            q_start = state_after(scenario, world, task, alternatives, q_start)
            _print_plan(args, scenario, world, i, label, alternatives)
    finally:
        physics.close()
    if args.json:
        print(risk_json(scenario, tasks))
    return EXIT_OK


def _checking_text(scenario: Scenario, analytic: list[AlternativeRisk]) -> str:
    feasible = [a.name for a in analytic if a.feasible]
    n = scenario.risk.rollouts.count
    rolls = f" and up to {n} rollouts each on sampled truths" if n else ""
    return f"checking {', '.join(feasible) or 'nothing'} in physics: a dry run on the estimate{rolls} ..."


def _print_plan(
    args: argparse.Namespace,
    scenario: Scenario,
    world: World,
    i: int,
    label: str,
    alternatives: list[AlternativeRisk],
) -> None:
    """One task's risk table (unless ``--json``) and its plots (``--plot DIR``)."""
    import mujoco

    from executive.report.plots import plot_alternatives, risk_table
    from executive.risk.fall import support_polygon

    if not args.json:
        print(risk_table(scenario, label, alternatives))
    if args.plot:
        mujoco.mj_forward(world.model, world.data)
        polygon = support_polygon(world, world.data, from_contacts=False)
        for path in plot_alternatives(scenario, alternatives, polygon, Path(args.plot) / f"task{i}"):
            if not args.json:
                print(f"plot      {path}")
