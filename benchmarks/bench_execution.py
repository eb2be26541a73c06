"""Planning and execution cost of each alternative of book_transfer (truth = estimate).

Prints per alternative: planning wall time, planned motion duration, simulated
time, execution wall time, real-time factor, longest tick, the share of the
execution loop spent stepping physics, outcome and placement error. Ratios are
measured in one run, so they hold on a noisy machine.

Run: ``python benchmarks/bench_execution.py [alternative ...]``
"""

from __future__ import annotations

import sys

from executive.execution.runner import run_alternative
from executive.scenario import load


def main(argv: list[str]) -> None:
    scenario = load("book_transfer")
    names = argv or list(scenario.mission[0].alternatives)
    print(
        f"{'alternative':<15}{'plan s':>8}{'motion s':>10}{'sim s':>8}{'wall s':>8}{'RTF':>6}"
        f"{'tick ms':>9}{'physics %':>11}  outcome"
    )
    for name in names:
        r = run_alternative(scenario, name, exact=True)
        share = 100 * r.physics_wall_s / r.wall_s if r.wall_s else float("nan")
        place = f", {r.placement_error_m * 1000:.1f} mm" if r.placement_error_m is not None else ""
        print(
            f"{name:<15}{r.plan_s:>8.2f}{r.planned_duration_s:>10.1f}{r.sim_time_s:>8.1f}{r.wall_s:>8.2f}"
            f"{r.real_time_factor:>6.1f}{r.max_tick_s * 1000:>9.2f}{share:>10.0f}%  {r.outcome}{place}"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
