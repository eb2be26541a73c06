"""The jaws' approach window: planned (kinematics of the plan's knots) against physics.

For each scenario and alternative: plan on the estimate, then execute the plan in an exact
truth (the object where the estimate has it) until the grasping hand starts to close,
recording the robot's whole pose (floating base included) after every control period.
Both pose paths go through :func:`executive.risk.grasp.approach_envelope`; the window printed
is its (lo, hi) at zero yaw error: the object's offset along its closing axis (mm) at which
a hand geom first meets its -y or +y face. The differences (physics - plan) are the hand's
tracking error where it matters (servo lag, body sway), printed with their RMS.

    python benchmarks/bench_grasp_approach.py [scenario ...]   (default: book_transfer)
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import py_trees

from behaviours.robot_access import install
from executive.execution.simulated import SimulatedRobot
from executive.planning.plan import AlternativePlan
from executive.planning.planner import Planner, PlanningError
from executive.risk.grasp import approach_envelope
from executive.scenario import load
from executive.tasks.steps import build_subtree, plan_alternative
from executive.world.model import World, build


def physics_path(plan: AlternativePlan, truth: World, side: str) -> np.ndarray:
    """The robot's qpos after each control period until the ``side`` hand is told to close."""
    robot = SimulatedRobot(truth)
    install(robot)
    root = build_subtree(plan)
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    closed = np.array(truth.profile.arms[side].gripper.closed, dtype=float)
    path = []
    limit = plan.duration + 10.0
    while truth.data.time < limit:
        tree.tick()
        if root.status != py_trees.common.Status.RUNNING or np.allclose(robot.gripper_ctrl[side], closed):
            break
        robot.advance()
        path.append(truth.data.qpos.copy())
    tree.shutdown()
    return np.array(path)


def window(world: World, side: str, obj: str, path: np.ndarray) -> tuple[float, float]:
    hi, lo = approach_envelope(world, side, obj, path).clearances(0.0)
    return float(lo[0]), float(hi[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=["book_transfer"])
    args = parser.parse_args()
    diffs = []
    for name in args.scenarios:
        scenario = load(name)
        task = scenario.mission[0]
        for alt in task.alternatives:
            estimate = build(scenario)
            try:
                plan = plan_alternative(Planner(estimate), estimate, task, alt)
            except PlanningError:
                print(f"{name} {alt}: not planned")
                continue
            grasp = next(s for s in plan.steps if s.kind == "grasp")
            before = plan.steps[: plan.steps.index(grasp)]
            planned = np.concatenate(
                [
                    plan.trajectories[s.name].qpos
                    for s in before
                    if s.name in plan.trajectories and s.side == grasp.side
                ]
            )
            t0 = time.perf_counter()
            actual = physics_path(plan, build(scenario), grasp.side)
            lo_p, hi_p = window(estimate, grasp.side, task.object, planned)
            lo_a, hi_a = window(estimate, grasp.side, task.object, actual)
            diffs += [lo_a - lo_p, hi_a - hi_p]
            print(
                f"{name} {alt}: window plan [{lo_p * 1e3:.1f}, {hi_p * 1e3:.1f}] mm, physics "
                f"[{lo_a * 1e3:.1f}, {hi_a * 1e3:.1f}] mm ({time.perf_counter() - t0:.1f} s)"
            )
    if diffs:
        d = np.array(diffs) * 1e3
        print(
            f"physics - plan at the window's edges: RMS {np.sqrt(np.mean(d**2)):.2f} mm, "
            f"max |.| {np.abs(d).max():.2f} mm"
        )
        # an edge that moves inwards narrows the window: lo up, hi down
        inward = np.concatenate([d[0::2], -d[1::2]])
        print(f"inward (narrowing) mean {inward.mean():.2f} mm over {len(d)} edges")


if __name__ == "__main__":
    main()
