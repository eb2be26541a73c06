"""Which hold keeps a robot up when a live guard stops its step: pushes mid-step, four holds.

One forward step (the humanoid's right foot 12 cm on scenarios/fall_steps.yaml's floor; the G1's
10 cm on the open floor of tests/test_stepping.py, skipped when the shared G1 is absent), planned
on the estimate and run on the exact truth. A 0.2 s push on the pelvis (four directions, two
magnitudes per robot) comes at the end of the lift, in the middle of the swing or in the
touchdown. Per push, four runs: unguarded (the step goes on; a step that fails holds), and
guarded with each of the Step's holds (:data:`behaviours.step.HOLDS`): ``auto``, ``freeze``,
``plan``. Each run ends 5 s after its step did: ``both`` when no detector fired and each foot
carries at least :data:`SHARE` of the weight (on both feet), ``one`` when no detector fired but
a foot carries less (standing on the other), ``FALLS`` when a detector fired (a fall, or the
tipping robot's hand on the table).

    python -m benchmarks.bench_step_hold [--robot humanoid|g1|both]

About a second per run (96 runs per robot). Results: docs/stepping.md, "When a guard stops a step".
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import py_trees

from behaviours.guard import RiskGuard, install_monitor
from behaviours.robot_access import install
from behaviours.step import HOLDS, Step, foot_force
from benchmarks.g1_scenes import G1_MJCF, g1_floor_yaml
from executive.execution.simulated import SimulatedRobot
from executive.monitoring.live_risk import LiveRiskMonitor
from executive.planning.stepping import Foothold, StepPlan, StepPlanner
from executive.scenario import load, loads
from executive.schema.types import Scenario
from executive.world.model import build

ROOT = Path(__file__).resolve().parents[1]
Status = py_trees.common.Status
#: Per robot: the step (dx, m) and the push magnitudes (N), about 0.2 and 0.35 of its weight.
ROBOTS = {"humanoid": (0.12, (150.0, 250.0)), "g1": (0.10, (40.0, 70.0))}
DIRECTIONS = {
    "towards the swing foot": (0, -1),
    "away from it": (0, 1),
    "forwards": (1, 0),
    "backwards": (-1, 0),
}
#: The least share of the weight each foot carries for the robot to stand on both feet.
SHARE = 0.05
#: When the push starts: (phase index, fraction of the phase).
WHEN = {"lift end": (1, 0.8), "mid-swing": (2, 0.5), "touchdown": (3, 0.4)}


def scene(robot: str) -> Scenario:
    """The robot on open floor."""
    if robot == "humanoid":
        return load(ROOT / "scenarios" / "fall_steps.yaml")
    return loads(g1_floor_yaml(G1_MJCF), source="g1_floor.yaml")


def plan_step(scenario: Scenario, dx: float) -> StepPlan:
    """The right foot ``dx`` forward from the standing start."""
    world = build(scenario)
    planner = StepPlanner(world)
    q = world.home_qpos()
    start = planner.footholds(q)["right"]
    return planner.plan_step(q, "right", Foothold("right", start.x + dx, start.y, start.yaw))


def run(
    scenario: Scenario, plan: StepPlan, hold: str | None, push: np.ndarray, at: float
) -> tuple[str, str, tuple[float, float]]:
    """One run (``hold`` None: unguarded): ``both``, ``one`` or ``FALLS`` (module doc), how the step
    ended, and the share of the weight on each foot (left, right) at the end."""
    truth = build(scenario)
    robot = SimulatedRobot(truth)
    install(robot)
    install_monitor(LiveRiskMonitor(build(scenario), scenario.risk.guard) if hold is not None else None)
    guard = RiskGuard(Step("step", plan, hold=hold or "auto"), side="right", kind="step", obj="")
    tree = py_trees.trees.BehaviourTree(guard)
    tree.setup()
    base, ended, how = truth.ids.base_body, -1.0, ""
    while robot.time < (plan.duration + 3.0 if ended < 0 else ended + 5.0):
        truth.data.xfrc_applied[base, :3] = push if at <= robot.time < at + 0.2 else 0.0
        if ended < 0:
            tree.tick()
            if guard.status != Status.RUNNING:
                ended, how = robot.time, guard.feedback_message
        if robot.advance() is not None:
            return "FALLS", robot.failure.detail if robot.failure else how, (0.0, 0.0)
    weight = truth.robot_mass * float(np.linalg.norm(truth.model.opt.gravity))
    left, right = (foot_force(robot, side)[0] / weight for side in ("left", "right"))
    return ("both" if min(left, right) >= SHARE else "one"), how, (left, right)


def bench(robot: str) -> None:
    dx, magnitudes = ROBOTS[robot]
    scenario = scene(robot)
    plan = plan_step(scenario, dx)
    starts = np.cumsum([0.0] + [p.trajectory.duration for p in plan.phases])
    settings: list[str | None] = [None, *HOLDS]
    names = ["unguarded", *HOLDS]
    both = dict.fromkeys(names, 0)
    falls = dict.fromkeys(names, 0)
    print(
        f"\n{robot}, step {dx * 100:.0f} cm forward\n  {'push (0.2 s on the pelvis)':<50}"
        + "".join(f"{n:>11}" for n in names)
    )
    for force in magnitudes:
        for direction, (ux, uy) in DIRECTIONS.items():
            for when, (phase, fraction) in WHEN.items():
                at = starts[phase] + fraction * plan.phases[phase].trajectory.duration
                push = force * np.array([ux, uy, 0.0])
                row = [run(scenario, plan, s, push, at)[0] for s in settings]
                for name, outcome in zip(names, row, strict=True):
                    both[name] += outcome == "both"
                    falls[name] += outcome == "FALLS"
                label = f"{force:.0f} N {direction}, {when}"
                print(f"  {label:<50}" + "".join(f"{outcome:>11}" for outcome in row), flush=True)
    total = len(magnitudes) * len(DIRECTIONS) * len(WHEN)
    print(f"  {'on both feet, of ' + str(total):<50}" + "".join(f"{both[n]:>11}" for n in names))
    print(f"  {'fell, of ' + str(total):<50}" + "".join(f"{falls[n]:>11}" for n in names))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", choices=("humanoid", "g1", "both"), default="both")
    args = parser.parse_args()
    robots = ["humanoid", "g1"] if args.robot == "both" else [args.robot]
    for robot in robots:
        if robot == "g1" and not G1_MJCF.is_file():
            print(f"the shared G1 is not at {G1_MJCF}: skipped", file=sys.stderr)
            continue
        bench(robot)


if __name__ == "__main__":
    main()
