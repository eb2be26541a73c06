"""Speed of the whole-body planner on the book_transfer scene.

Plans a typical 8-segment alternative (the left arm moves the book over the
stack: pre-grasp, grasp, lift, carry, place, retreat, left hand home, both
hands to the ready pose) several times and prints the mean IK step time,
iterations and knots per segment, and the total planning time.

Run: ``python benchmarks/bench_planning.py [repeats]``
"""

from __future__ import annotations

import sys
import time

import mujoco
import numpy as np

from executive.planning import HandTarget, Planner, Trajectory, hand_top_down_quat
from executive.scenario import load
from executive.world import World, build

__all__ = ["home_pose", "main", "plan_left_alternative"]

GRASP_Z = 0.835


def plan_left_alternative(planner: Planner, world: World) -> list[tuple[Trajectory, int, float, float]]:
    """The 8 segments; per segment (trajectory, IK iterations, IK seconds, total seconds)."""
    quat = hand_top_down_quat()
    home = world.home_qpos()
    ready = {side: home_pose(world, side) for side in ("left", "right")}
    book, goal = np.array([0.48, 0.26]), np.array([0.48, -0.26])

    def tgt(side: str, xy: np.ndarray, z: float) -> list[HandTarget]:
        return [HandTarget(side, np.array([*xy, z]), quat)]

    steps: list[tuple[str, list[HandTarget], dict[str, object]]] = [
        ("left.pregrasp", tgt("left", book, GRASP_Z + 0.10), {}),
        ("left.grasp", tgt("left", book, GRASP_Z), {"allow_contact": ("book",)}),
        (
            "left.lift",
            tgt("left", book, GRASP_Z + 0.12),
            {"carried": ("left", "book"), "allow_contact": ("book",)},
        ),
        ("left.carry", tgt("left", goal, 0.90), {"carried": ("left", "book")}),
        (
            "left.place",
            tgt("left", goal, GRASP_Z),
            {"carried": ("left", "book"), "allow_contact": ("table_top",)},
        ),
        ("left.retreat", tgt("left", goal, GRASP_Z + 0.10), {"allow_contact": ("book",)}),
        ("left.home", [ready["left"]], {}),
        ("both.ready", [ready["left"], ready["right"]], {}),
    ]
    out = []
    q = home
    for name, targets, kwargs in steps:
        traj = planner.move(q, targets, name=name, **kwargs)  # type: ignore[arg-type]
        stats = planner.last_stats
        if stats is None:
            raise RuntimeError("the planner recorded no statistics")
        out.append((traj, stats.iterations, stats.ik_time_s, stats.total_time_s))
        q = traj.qpos[-1]
    return out


def home_pose(world: World, side: str) -> HandTarget:
    """The hand site's pose at the keyframe."""
    data = world.data
    world.reset()
    site = world.ids.hand_sites[side]
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, data.site_xmat[site])
    return HandTarget(side, data.site_xpos[site].copy(), quat)


def main(argv: list[str]) -> None:
    repeats = int(argv[1]) if len(argv) > 1 else 3
    world = build(load("book_transfer"))
    tick = time.perf_counter()
    planner = Planner(world)
    setup = time.perf_counter() - tick
    totals, per_step = [], []
    rows: list[tuple[Trajectory, int, float, float]] = []
    for _ in range(repeats):
        tick = time.perf_counter()
        rows = plan_left_alternative(planner, world)
        totals.append(time.perf_counter() - tick)
        per_step += [ik / max(it, 1) for _, it, ik, _ in rows]
    print(f"planner setup: {setup * 1e3:.1f} ms")
    print(
        f"{'segment':<14} {'iterations':>10} {'IK ms/step':>10} {'plan ms':>8} "
        f"{'knots':>6} {'duration s':>10}"
    )
    for traj, it, ik, total in rows:
        print(
            f"{traj.name:<14} {it:>10d} {ik / max(it, 1) * 1e3:>10.2f} {total * 1e3:>8.1f} "
            f"{len(traj.times):>6d} {traj.duration:>10.2f}"
        )
    its = [it for _, it, _, _ in rows]
    knots = [len(t.times) for t, _, _, _ in rows]
    print(f"mean IK step time: {np.mean(per_step) * 1e3:.2f} ms")
    print(f"iterations per segment: mean {np.mean(its):.1f}, max {max(its)}")
    print(f"knots per segment: mean {np.mean(knots):.1f}, max {max(knots)}")
    print(
        f"total planning time, 8-segment alternative: mean {np.mean(totals):.3f} s, "
        f"min {min(totals):.3f} s over {repeats} runs"
    )


if __name__ == "__main__":
    main(sys.argv)
