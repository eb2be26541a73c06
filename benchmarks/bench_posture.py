"""The safe posture in physics: a turned book's alternatives, planned at several pelvis limits.

For each alternative of ``book_transfer`` with the book turned ``yaw`` degrees, and each
planner pelvis limit (``SafePosture.max_pelvis_drop`` of the estimate's robot; the truth keeps
the profile's, so its fall detector is the profile's), prints: the plan's lowest pelvis height
below standing, the fall model's P(fall) and its pelvis term on the profile's posture, and in
physics with truth = estimate the lowest pelvis height, the smallest CoM margin in the support
polygon of the feet's contacts (with the count of checks where it is negative: a foot rocking
onto an edge), the margin while the pelvis is more than 10 cm down, and the outcome.
Run: ``python benchmarks/bench_posture.py [yaw_deg] [limit_m ...]`` (default 30; profile, 0.10, 1.0).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import ClassVar

import numpy as np

import executive.execution.runner as runner
from executive.decision.assessment import concatenate
from executive.monitoring.detectors import DetectorThresholds, Failure, FailureDetector
from executive.planning.planner import Planner, PlanningError
from executive.risk.fall import assess_fall, support_polygon
from executive.robot.posture import standing_pelvis_height
from executive.scenario import loads
from executive.schema.types import Scenario
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build
from executive.world.polygon import signed_margin

__all__ = ["main"]

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


class _Recorder(FailureDetector):
    """The profile's detector, recording the pelvis height and the contact CoM margin per check."""

    records: ClassVar[list[tuple[float, float]]] = []

    def check(self) -> Failure | None:
        failure = super().check()
        world, data = self.world, self.world.data
        try:
            margin = signed_margin(
                support_polygon(world, data, True), data.subtree_com[world.ids.base_body][:2]
            )
        except ValueError:
            margin = float("nan")
        _Recorder.records.append((float(data.xpos[world.ids.base_body][2]), margin))
        return failure


def _scenario(yaw: float) -> Scenario:
    text = (SCENARIOS / "book_transfer.yaml").read_text().replace("orientation: 0 ", f"orientation: {yaw:g} ")
    return loads(text, source=f"book_transfer_yaw{yaw:g}.yaml", base_dir=SCENARIOS)


def _estimate(scenario: Scenario, limit: float | None) -> World:
    world = build(scenario)
    if limit is None:
        return world
    posture = dataclasses.replace(world.profile.safe_posture, max_pelvis_drop=limit)
    return dataclasses.replace(world, profile=dataclasses.replace(world.profile, safe_posture=posture))


def _row(scenario: Scenario, alternative: str, limit: float | None) -> str:
    """One alternative at one pelvis limit: plan, predict, execute, measure."""
    estimate = _estimate(scenario, limit)
    task = scenario.mission[0]
    label = f"{alternative:14s} limit {'profile' if limit is None else f'{limit:.2f} m':8s}"
    try:
        plan = plan_alternative(Planner(estimate), estimate, task, alternative)
    except PlanningError as exc:
        return f"{label} refused: {exc}"
    truth = build(scenario)
    ids = truth.ids
    standing = standing_pelvis_height(truth.model, ids.keyframe, ids.base_body)
    whole = concatenate(plan.ordered_trajectories(), alternative)
    fall = assess_fall(truth, whole, scenario.risk, scenario.uncertainty)
    _Recorder.records = []
    result = runner.execute_plan(plan, truth, task)
    heights, margins = np.array(_Recorder.records).T
    deep = heights < standing - 0.10
    margin_deep = f"{np.nanmin(margins[deep]) * 1000:.0f} mm" if deep.any() else "-"
    planned = (standing - fall.details["min_pelvis_height"]) * 100
    reached = (standing - heights.min()) * 100
    tipping = int(np.sum(margins < 0))
    return (
        f"{label} planned {planned:.1f} cm down, P(fall) {fall.probability:.3g} "
        f"(pelvis {fall.details['probability_pelvis']:.3g}); physics {reached:.1f} cm down, "
        f"contact CoM margin min {np.nanmin(margins) * 1000:.0f} mm ({tipping} checks < 0), "
        f">10 cm down {margin_deep}; {result.outcome}: {result.message[:120]}"
    )


def main(argv: list[str]) -> None:
    yaw = float(argv[0]) if argv else 30.0
    limits: list[float | None] = [float(a) for a in argv[1:]] or [None, 0.10, 1.0]
    scenario = _scenario(yaw)
    runner.FailureDetector = _Recorder  # type: ignore[misc]  # the runner makes its detector by this name
    print(f"book yaw {yaw:g} deg; detector thresholds {DetectorThresholds()}")
    for alternative in scenario.mission[0].alternatives:
        for limit in limits:
            print(_row(scenario, alternative, limit), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
