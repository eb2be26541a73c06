"""How far standing feet slide on normal walks, and where a slippery floor trips the foot-slip check.

Normal floor: each robot's walk (the humanoid: walk_to_table's 0.4 m walk forward; the G1: 0.15 m
forward on open floor, ``uncertainty.com`` 1 cm as the G1 book scene; skipped without the shared
G1), either foot first, on the exact truth and on ``--truths`` sampled truths, every footstep
guarded as the executive runs it, the detector's slip limits out of reach. Per run: the largest
slide and turn of a standing foot's sole middle (the check's own measure,
``FailureDetector.largest_slip``: any load), and the largest slide of a foot's points on the
floor while it carries at least ``foot_slip_load`` of the weight (``foot_slip_now`` every control
period: the measure a slip is called on), against the robot's default limits.

Slippery floor (``--friction``): the floor's sliding friction lowered (its geom's priority makes
it the contacts'), the exact truth, the default limits; the walk (right foot first): where the
slip tripped (time, phase, foot, how far, how fast, how the step held) or, with no trip, the
largest slide.

    python -m benchmarks.bench_foot_slip [--robot humanoid|g1|both] [--truths N] [--friction MU ...]

About 10 s (humanoid) and 12 s (G1) per walk. Results: docs/detectors.md, "Foot slip".
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import py_trees

from behaviours.guard import install_monitor
from behaviours.robot_access import install
from behaviours.step import Step
from benchmarks.g1_scenes import G1_MJCF, g1_floor_yaml
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.detectors import DetectorThresholds, FailureDetector
from executive.monitoring.live_risk import LiveRiskMonitor
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner
from executive.scenario import load, loads
from executive.schema.types import Scenario
from executive.tasks.steps import build_subtree, plan_alternative
from executive.world.model import World, build, sample_perturbation

ROOT = Path(__file__).resolve().parents[1]
Status = py_trees.common.Status
#: Limits no walk reaches: the largest slides are measured, nothing trips.
OUT_OF_REACH = DetectorThresholds(foot_slip=1.0, foot_slip_yaw_deg=90.0)


def scene(robot: str) -> Scenario:
    """The robot's walk: its first task."""
    if robot == "humanoid":
        return load(ROOT / "scenarios" / "walk_to_table.yaml")
    walk = g1_floor_yaml(
        G1_MJCF,
        0.01,
        name="g1_walk",
        description="The G1 walks 0.15 m forward on open floor, a table behind it.",
        mission="  - step: {to: [0.15, 0.0]}\n",
    )
    return loads(walk, source="g1_walk.yaml")


def slippery(world: World, friction: float) -> World:
    """``world`` with its floor's sliding friction ``friction`` in every contact with it."""
    floor = world.ids.floor_geom
    world.model.geom_friction[floor, 0] = friction
    world.model.geom_priority[floor] = int(world.model.geom_priority.max()) + 1
    return world


def walk(
    scenario: Scenario, plan: AlternativePlan, truth: World, limits: DetectorThresholds | None
) -> tuple[str, FailureDetector, float, list[Step]]:
    """The walk on ``truth``, guarded; how it ended, its detector, the largest slide (m) of a
    loaded standing foot's points on the floor, and its steps."""
    detector = FailureDetector(truth, limits, distance_stride=0)
    robot = SimulatedRobot(truth, detector=detector)
    py_trees.blackboard.Blackboard.clear()
    install(robot)
    install_monitor(LiveRiskMonitor(build(scenario), scenario.risk.guard))
    root = build_subtree(plan, guard=True)
    steps = [n for n in root.iterate() if isinstance(n, Step)]
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    loaded = 0.0
    while robot.time < plan.duration + 10.0:
        tree.tick()
        if root.status != Status.RUNNING:
            break
        robot.advance()
        for side in truth.profile.feet:
            now = detector.foot_slip_now(side)
            if now is not None and now.load >= detector.foot_slip_load:
                loaded = max(loaded, now.distance)
    tip = root.tip()
    return f"{root.status.name}: {tip.feedback_message if tip else ''}", detector, loaded, steps


def normal_floor(robot: str, truths: int) -> None:
    """The largest slides on the normal floor, exact truth and ``truths`` sampled ones."""
    scenario = scene(robot)
    estimate = build(scenario)
    defaults = FailureDetector(estimate)
    print(
        f"\n{robot}: default limits {defaults.foot_slip * 1000:.2f} mm, "
        f"{defaults.foot_slip_yaw_deg:.2f} deg, load {defaults.foot_slip_load:.2f} of the weight"
    )
    print("alternative  truth  middle (mm)  loaded (mm)  turn (deg)  outcome")
    worst = [0.0, 0.0, 0.0]
    for alternative in ("left_first", "right_first"):
        plan = plan_alternative(Planner(estimate), estimate, scenario.mission[0], alternative)
        for seed in [None, *range(truths)]:
            if seed is None:
                truth = build(scenario)
            else:
                rng = np.random.default_rng(seed)
                truth = build(scenario, sample_perturbation(scenario, rng), kind="truth")
            outcome, detector, loaded, _ = walk(scenario, plan, truth, OUT_OF_REACH)
            slide, turn = detector.largest_slip
            worst = [max(worst[0], slide.distance), max(worst[1], loaded), max(worst[2], turn.turn)]
            print(
                f"{alternative:11}  {'exact' if seed is None else seed:>5}  {slide.distance * 1000:11.2f}  "
                f"{loaded * 1000:11.2f}  {math.degrees(turn.turn):10.3f}  {outcome[:90]}",
                flush=True,
            )
    print(
        f"{robot} largest: middle {worst[0] * 1000:.2f} mm ({defaults.foot_slip / worst[0]:.1f}x under the "
        f"limit), loaded {worst[1] * 1000:.2f} mm ({defaults.foot_slip / max(worst[1], 1e-9):.1f}x), turn "
        f"{math.degrees(worst[2]):.3f} deg ({defaults.foot_slip_yaw_deg / math.degrees(worst[2]):.0f}x)"
    )


def slippery_floor(robot: str, frictions: list[float]) -> None:
    """The walk (right foot first) on floors of each of ``frictions``, the default limits."""
    scenario = scene(robot)
    estimate = build(scenario)
    plan = plan_alternative(Planner(estimate), estimate, scenario.mission[0], "right_first")
    print(f"\n{robot}, right foot first, default limits:")
    for mu in frictions:
        outcome, detector, _, steps = walk(scenario, plan, slippery(build(scenario), mu), None)
        slip = detector.slipped
        if slip is None:
            slide = detector.largest_slip[0]
            print(f"friction {mu:g}: no slip (largest slide {slide.distance * 1000:.1f} mm); {outcome[:120]}")
            continue
        step = next(s for s in steps if s.slipped is not None)
        print(
            f"friction {mu:g}: {step.name}: {step.feedback_message}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", choices=("humanoid", "g1", "both"), default="both")
    parser.add_argument("--truths", type=int, default=10, help="sampled truths per alternative")
    parser.add_argument("--friction", type=float, nargs="*", default=[0.1, 0.05, 0.02, 0.01, 0.005])
    args = parser.parse_args()
    robots = ["humanoid", "g1"] if args.robot == "both" else [args.robot]
    for robot in robots:
        if robot == "g1" and not G1_MJCF.is_file():
            print(f"g1: skipped (no shared model at {G1_MJCF})")
            continue
        normal_floor(robot, args.truths)
        slippery_floor(robot, args.friction)


if __name__ == "__main__":
    main()
