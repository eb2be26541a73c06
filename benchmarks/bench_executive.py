"""Ticking overhead of the executive: a whole mission's wall time vs raw ``mj_step`` time.

    python benchmarks/bench_executive.py [SCENARIO]

Runs the mission with the Executive (exact truth, auto approval, guards on), then
times raw ``mj_step`` for the same number of physics steps on a fresh truth world
(the robot holding its keyframe), in the same process. Prints:

* the whole run (background planning included) vs raw stepping,
* the execution phase alone (from the first ``execute`` decision),
* the longest single tick of the tree (tree only, physics excluded),
* the same execution without guards, to show what the guards cost.

Target (issue 5): run wall time at most 1.5x raw ``mj_step`` time; ratios are from
one run on this machine.
"""

from __future__ import annotations

import sys
import time

import mujoco

from executive.mission import Executive
from executive.world import build


def run(scenario: str, guard: bool) -> dict[str, float]:
    executive = Executive(scenario, approval="auto", truth="exact", guard=guard)
    robot = executive.robot
    t_exec = None
    steps_at_exec = 0
    start = time.perf_counter()
    while not executive.done:
        executive.tick()
        if t_exec is None and any(e["kind"] == "execute" for e in executive.log.entries[-3:]):
            t_exec, steps_at_exec = time.perf_counter(), robot.stats.physics_steps
    end = time.perf_counter()
    assert executive.outcome == "success", executive.summary()
    assert t_exec is not None
    return {
        "wall": end - start,
        "exec_wall": end - t_exec,
        "steps": robot.stats.physics_steps,
        "exec_steps": robot.stats.physics_steps - steps_at_exec,
        "physics_wall": robot.stats.physics_wall_s,
        "max_tick": executive.max_tick_s,
        "ticks": executive.ticks,
    }


def raw_step_time(scenario: str, steps: int) -> float:
    from executive.scenario import load

    world = build(load(scenario))
    world.data.ctrl[:] = world.home_ctrl()
    start = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(world.model, world.data)
    return time.perf_counter() - start


def main() -> None:
    scenario = sys.argv[1] if len(sys.argv) > 1 else "book_transfer"
    guarded = run(scenario, guard=True)
    bare = run(scenario, guard=False)
    per_step = raw_step_time(scenario, int(guarded["steps"])) / guarded["steps"]
    raw_all = per_step * guarded["steps"]
    raw_exec = per_step * guarded["exec_steps"]
    raw_bare = per_step * bare["exec_steps"]
    print(f"scenario {scenario}: {guarded['ticks']:.0f} ticks, {guarded['steps']:.0f} physics steps")
    print(f"raw mj_step             {per_step * 1e6:8.1f} us/step")
    ratio = guarded["wall"] / raw_all
    print(f"whole run (planning in a thread)  {guarded['wall']:7.2f} s  = {ratio:5.2f} x raw")
    print(
        f"execution, guards on    {guarded['exec_wall']:7.2f} s  = "
        f"{guarded['exec_wall'] / raw_exec:5.2f} x raw "
        f"(target <= 1.5)"
    )
    print(f"execution, guards off   {bare['exec_wall']:7.2f} s  = {bare['exec_wall'] / raw_bare:5.2f} x raw")
    on, off = guarded["max_tick"] * 1000, bare["max_tick"] * 1000
    print(f"longest tick (tree only): guards on {on:.2f} ms, off {off:.2f} ms")


if __name__ == "__main__":
    main()
