"""Ticking overhead of the executive: its wall time vs raw ``mj_step`` time of the very same steps.

    python benchmarks/bench_executive.py [SCENARIO] [--repeat N] [--control-dt S]

Runs the mission with the :class:`executive.mission.Executive` (truth = estimate, auto
approval), with live risk guards on and off, ``N`` times each, interleaved. During each
run the controls of every physics step are recorded (a thin wrapper around the
``mj_step`` that ``SimulatedRobot.advance`` calls; its cost counts against the
executive). Right after the run the recorded controls are replayed from the run's initial
state in a bare loop (``data.ctrl[:] = row; mj_step``) on the same model: the same steps,
the same contacts, the same final state (checked bit for bit), with nothing else around
them. That replay is the "raw mj_step time of the same number of steps".

Per run it prints:

* execution phase (from the tick after the selector logged ``execute`` to the end: the
  robot moving under the tree, the contact detectors after every physics step and the
  full detector check after each control period, guards if on): wall time, raw time, and
  their ratio -- the ticking overhead the issue's target is about;
* the whole run (background planning included; while the worker plans the robot holds and
  the bundled physics is paced to the wall clock, so that ratio measures planning, not
  ticking);
* the tree's tick (physics excluded): mean and longest in the execution phase, and the
  longest of the whole run (which includes the tick that swaps the planned subtrees in).

The summary line takes the best (lowest) wall ratio of the ``N`` runs per setting (noise
on a shared machine only ever adds time) and the median ratio of CPU time of the ticking
thread (``time.thread_time``: the execution phase runs in that thread, the planning
worker is idle by then; other processes' load does not count in it, so it is the figure to
compare across loaded runs). Target (issue 5): at most 1.5.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import mujoco
import numpy as np

import executive.execution as execution
from executive.mission import Executive

STATE = mujoco.mjtState.mjSTATE_INTEGRATION


class _Recording:
    """Stands in for the ``mujoco`` module inside ``executive.execution``: records each
    step's ctrl before stepping; everything else is the real module."""

    def __init__(self, real: ModuleType) -> None:
        self._real = real
        self.rows: list[np.ndarray] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)

    def mj_step(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.rows.append(data.ctrl.copy())
        self._real.mj_step(model, data)


@dataclass
class Run:
    guard: bool
    ticks: int
    steps: int
    wall: float
    raw: float
    exec_ticks: int
    exec_steps: int
    exec_wall: float
    exec_raw: float
    exec_cpu: float  # CPU time of the ticking thread, execution phase
    exec_raw_cpu: float
    tick_mean: float  # tree only, execution phase
    tick_max_exec: float
    tick_max: float  # tree only, whole run
    identical: bool  # the replay ended in the run's final state, bit for bit

    @property
    def ratio(self) -> float:
        return self.exec_wall / self.exec_raw

    @property
    def cpu_ratio(self) -> float:
        return self.exec_cpu / self.exec_raw_cpu

    @property
    def whole_ratio(self) -> float:
        return self.wall / self.raw


def _replay(
    model: mujoco.MjModel, state0: np.ndarray, rows: np.ndarray, split: int
) -> tuple[float, float, float, Any]:
    """Raw stepping of the recorded controls from the initial state:
    (wall s before split, wall s after, thread CPU s after, data)."""
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state0, STATE)
    step, ctrl = mujoco.mj_step, data.ctrl
    t0 = time.perf_counter()
    for row in rows[:split]:
        ctrl[:] = row
        step(model, data)
    t1, c1 = time.perf_counter(), time.thread_time()
    for row in rows[split:]:
        ctrl[:] = row
        step(model, data)
    t2, c2 = time.perf_counter(), time.thread_time()
    return t1 - t0, t2 - t1, c2 - c1, data


def run(scenario: str, guard: bool, control_dt: float = 0.02) -> Run:
    ex = Executive(scenario, approval="auto", truth="exact", guard=guard, control_dt=control_dt)
    assert ex.truth is not None
    model, data = ex.truth.model, ex.truth.data
    state0 = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, state0, STATE)
    recording = _Recording(mujoco)
    execution.mujoco = recording  # type: ignore[assignment]
    try:
        seen = 0
        t_exec: float | None = None
        c_exec = 0.0
        steps_exec = ticks_exec = 0
        tick_s_exec = 0.0
        tick_max_exec = 0.0
        start = time.perf_counter()
        while not ex.done:
            before = ex.tick_s
            ex.tick()
            if t_exec is None:
                entries = ex.log.entries
                if len(entries) != seen:
                    if any(e["kind"] == "execute" for e in entries[seen:]):
                        t_exec, c_exec = time.perf_counter(), time.thread_time()
                        steps_exec, ticks_exec, tick_s_exec = len(recording.rows), ex.ticks, ex.tick_s
                    seen = len(entries)
            else:
                tick_max_exec = max(tick_max_exec, ex.tick_s - before)
        end, c_end = time.perf_counter(), time.thread_time()
    finally:
        execution.mujoco = mujoco  # type: ignore[assignment]
    if ex.outcome != "success" or t_exec is None:
        raise SystemExit(f"the run did not succeed: {ex.summary()}")
    rows = np.array(recording.rows)
    raw_before, raw_exec, raw_cpu, replayed = _replay(model, state0, rows, steps_exec)
    identical = bool(np.array_equal(replayed.qpos, data.qpos) and replayed.time == data.time)
    exec_ticks = ex.ticks - ticks_exec
    return Run(
        guard=guard,
        ticks=ex.ticks,
        steps=len(rows),
        wall=end - start,
        raw=raw_before + raw_exec,
        exec_ticks=exec_ticks,
        exec_steps=len(rows) - steps_exec,
        exec_wall=end - t_exec,
        exec_raw=raw_exec,
        exec_cpu=c_end - c_exec,
        exec_raw_cpu=raw_cpu,
        tick_mean=(ex.tick_s - tick_s_exec) / max(1, exec_ticks),
        tick_max_exec=tick_max_exec,
        tick_max=ex.max_tick_s,
        identical=identical,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument("--repeat", type=int, default=3, help="runs per setting (default 3)")
    parser.add_argument(
        "--control-dt", type=float, default=0.02, help="control period of a tick, s (default 0.02: 50 Hz)"
    )
    args = parser.parse_args()
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(
        f"{args.scenario}: truth = estimate, approval auto, ticks every {args.control_dt * 1000:g} ms; "
        f"{os.cpu_count()} cpus, load average {load}"
    )
    print(
        f"{'guards':<7}{'exec ticks':>11}{'steps':>7}{'wall s':>8}{'raw s':>7}{'ratio':>7}{'cpu':>6}  |"
        f"{'run s':>7}{'raw s':>7}{'ratio':>7}  |{'tick mean':>10}{'max':>7}{'max run':>9} ms  same"
    )
    runs: list[Run] = []
    for _ in range(max(1, args.repeat)):
        for guard in (True, False):
            r = run(args.scenario, guard, args.control_dt)
            runs.append(r)
            print(
                f"{'on' if guard else 'off':<7}{r.exec_ticks:>11}{r.exec_steps:>7}{r.exec_wall:>8.3f}"
                f"{r.exec_raw:>7.3f}{r.ratio:>7.2f}{r.cpu_ratio:>6.2f}  |"
                f"{r.wall:>7.2f}{r.raw:>7.3f}{r.whole_ratio:>7.1f}  |"
                f"{r.tick_mean * 1e3:>10.3f}{r.tick_max_exec * 1e3:>7.2f}{r.tick_max * 1e3:>9.2f}     "
                f"{'yes' if r.identical else 'NO'}",
                flush=True,
            )
    on = [r for r in runs if r.guard]
    off = [r for r in runs if not r.guard]
    per_step = min(r.exec_raw / r.exec_steps for r in runs)
    print(f"raw mj_step of these steps: {per_step * 1e6:.1f} us/step (best run)")
    print(
        f"executive wall / raw mj_step, execution phase (best of {len(on)}): "
        f"guards on {min(r.ratio for r in on):.2f}, guards off {min(r.ratio for r in off):.2f} "
        f"(median {np.median([r.ratio for r in on]):.2f} / {np.median([r.ratio for r in off]):.2f}; "
        f"target <= 1.5)"
    )
    print(
        f"the same in CPU time of the ticking thread (what other processes' load does not inflate): "
        f"guards on {np.median([r.cpu_ratio for r in on]):.2f}, guards off "
        f"{np.median([r.cpu_ratio for r in off]):.2f} (median)"
    )
    print(
        f"tree tick, execution phase: mean {np.median([r.tick_mean for r in on]) * 1e3:.3f} ms "
        f"(guards on) / {np.median([r.tick_mean for r in off]) * 1e3:.3f} ms (off); longest "
        f"{max(r.tick_max_exec for r in on) * 1e3:.2f} / {max(r.tick_max_exec for r in off) * 1e3:.2f} ms; "
        f"longest of the whole run {max(r.tick_max for r in on) * 1e3:.2f} / "
        f"{max(r.tick_max for r in off) * 1e3:.2f} ms"
    )


if __name__ == "__main__":
    main()
