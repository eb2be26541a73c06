"""Ticking overhead of the executive: its wall time vs raw ``mj_step`` time of the very same steps.

    python benchmarks/bench_executive.py [SCENARIO] [--repeat N] [--control-dt S] [--breakdown]

(SCENARIO: a bundled name or a file; scenarios/fall_steps.yaml measures a guarded walk.)

Runs the mission with the :class:`executive.runtime.mission.Executive` (truth = estimate, auto
approval), with live risk guards on and off, ``N`` times each, interleaved. During each
run the controls of every physics step are recorded, once per control period (thin
wrappers around ``SimulatedRobot.advance`` and the servo ctrl it steps with; their cost
counts against the executive). Right after the run the recorded controls are replayed from the run's initial
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

``--breakdown`` adds one instrumented run per setting: timers around the parts of a tick
(each physics step by its place in the control period, the contact detectors, the
end-of-period check and its clearance, the servo ctrl, the motion behaviour, the guard's
distance and CoM margin, the rest of the tree and of the executive), printed in us per tick
and as a fraction of the raw physics. The timers add a little (two clock reads per call).
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

import executive.execution.simulated as execution
import executive.monitoring.detectors as detectors
import executive.monitoring.live_risk as live_risk
from behaviours.move_hand import MoveHand
from behaviours.step import Step
from executive.runtime.mission import Executive, freeze_startup_heap

STATE = mujoco.mjtState.mjSTATE_INTEGRATION


class _PeriodRecording:
    """Records the controls of every physics step the executive takes, per control period.

    ``SimulatedRobot.advance`` writes, in step ``k`` of a period, row ``k`` of the
    :class:`executive.execution.simulated.ServoPeriod` that ``JointTargetController.period`` returned
    (row 0 for a fixed target) to the servo actuators, and leaves every other ctrl (the
    grippers) as it set them for the period. So a period is recorded by that ServoPeriod,
    ``data.ctrl`` after the period and the number of steps taken, and each step's ctrl is
    rebuilt from them afterwards: two wrapped calls per tick instead of one per physics step
    (a per-step recording cost 0.03x, charged to the executive). The replay's bit-identical
    final state checks the rebuild.
    """

    def __init__(self) -> None:
        self.periods: list[tuple[np.ndarray, execution.ServoPeriod, int]] = []
        self.steps = 0
        self._servo: execution.ServoPeriod | None = None
        self._saved: list[tuple[type, str, Any]] = []

    def install(self) -> None:
        real_period = execution.JointTargetController.__dict__["period"]
        real_advance = execution.SimulatedRobot.__dict__["advance"]
        recording = self

        def period(controller: execution.JointTargetController, *args: Any, **kwargs: Any) -> Any:
            servo = real_period(controller, *args, **kwargs)
            recording._servo = servo
            return servo

        def advance(robot: execution.SimulatedRobot) -> Any:
            before = robot.stats.physics_steps
            failure = real_advance(robot)
            taken = robot.stats.physics_steps - before
            assert recording._servo is not None
            recording.periods.append((robot.data.ctrl.copy(), recording._servo, taken))
            recording.steps += taken
            return failure

        for cls, name, f in (
            (execution.JointTargetController, "period", period),
            (execution.SimulatedRobot, "advance", advance),
        ):
            self._saved.append((cls, name, cls.__dict__[name]))
            setattr(cls, name, f)

    def uninstall(self) -> None:
        for cls, name, f in self._saved:
            setattr(cls, name, f)
        self._saved.clear()

    def rows(self) -> np.ndarray:
        """(steps, nu): the ctrl of every physics step, in order."""
        out = []
        for ctrl, servo, taken in self.periods:
            block = np.repeat(ctrl[None, :], taken, axis=0)
            block[:, servo.actuators] = servo.ctrl[:taken] if servo.moving else servo.ctrl[0]
            out.append(block)
        return np.concatenate(out) if out else np.zeros((0, 0))


class _StepRecording:
    """Stands in for the ``mujoco`` module inside ``executive.execution.simulated``: records each
    step's ctrl before stepping and times the ``mj_step`` call; everything else is the real
    module. For the breakdown's per-step physics times (it costs a wrapped call per step)."""

    def __init__(self) -> None:
        self.step_ctrl: list[np.ndarray] = []
        self.step_s: list[float] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(mujoco, name)

    def mj_step(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.step_ctrl.append(data.ctrl.copy())
        t0 = time.perf_counter()
        mujoco.mj_step(model, data)
        self.step_s.append(time.perf_counter() - t0)

    @property
    def steps(self) -> int:
        return len(self.step_ctrl)

    def install(self) -> None:
        execution.mujoco = self

    def uninstall(self) -> None:
        execution.mujoco = mujoco

    def rows(self) -> np.ndarray:
        return np.array(self.step_ctrl)


#: The parts of a tick the breakdown times: (label, class, method). A method called inside
#: another one listed is printed indented under it.
_PARTS: tuple[tuple[str, type, str], ...] = (
    ("contact detectors (after each step)", detectors.FailureDetector, "check_contacts"),
    ("end-of-period check", detectors.FailureDetector, "check"),
    ("  of which the closest-call clearance", detectors.FailureDetector, "_clearance"),
    ("servo ctrl of the period", execution.JointTargetController, "period"),
    ("motion behaviour (MoveHand.update)", MoveHand, "update"),
    ("footstep behaviour (Step.update)", Step, "update"),
    ("guard: distance now + look-ahead", live_risk.LiveRiskMonitor, "clearance"),
    ("guard: CoM margin", live_risk.LiveRiskMonitor, "com_margin"),
)


@contextmanager
def _timers() -> Iterator[dict[str, float]]:
    """Wrap each method of :data:`_PARTS` with a timer; yields label -> seconds (mutable)."""
    spent = {label: 0.0 for label, _, _ in _PARTS}
    saved: list[tuple[type, str, Any]] = []

    def timed(label: str, f: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return f(*args, **kwargs)
            finally:
                spent[label] += time.perf_counter() - t0

        return wrapper

    try:
        for label, cls, name in _PARTS:
            f = cls.__dict__[name]
            saved.append((cls, name, f))
            setattr(cls, name, timed(label, f))
        yield spent
    finally:
        for cls, name, f in saved:
            setattr(cls, name, f)


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
    substeps: int  # physics steps per tick
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


def run(
    scenario: str,
    guard: bool,
    control_dt: float = 0.02,
    recording: _PeriodRecording | _StepRecording | None = None,
    on_execute: Callable[[], None] | None = None,
    setup: Callable[[Executive], None] | None = None,
) -> Run:
    """One run; ``recording`` (default a fresh :class:`_PeriodRecording`) records the
    controls; ``on_execute`` is called when the execution phase starts; ``setup`` with the
    executive before its first tick (to add tick listeners)."""
    ex = Executive(scenario, approval="auto", truth="exact", guard=guard, control_dt=control_dt)
    if setup is not None:
        setup(ex)
    assert ex.truth is not None
    model, data = ex.truth.model, ex.truth.data
    state0 = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, state0, STATE)
    recording = recording if recording is not None else _PeriodRecording()
    recording.install()
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
                        if on_execute is not None:
                            on_execute()
                        t_exec, c_exec = time.perf_counter(), time.thread_time()
                        steps_exec, ticks_exec, tick_s_exec = recording.steps, ex.ticks, ex.tick_s
                    seen = len(entries)
            else:
                tick_max_exec = max(tick_max_exec, ex.tick_s - before)
        end, c_end = time.perf_counter(), time.thread_time()
    finally:
        recording.uninstall()
    if ex.outcome != "success" or t_exec is None:
        raise SystemExit(f"the run did not succeed: {ex.summary()}")
    rows = recording.rows()
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
        substeps=max(1, round(control_dt / model.opt.timestep)),  # as SimulatedRobot steps a tick
        identical=identical,
    )


def breakdown(scenario: str, guard: bool, control_dt: float) -> None:
    """One instrumented run: where a tick's time goes, in us per tick of the execution phase."""
    recording = _StepRecording()
    first = [0]
    with _timers() as spent:

        def start() -> None:
            for label in spent:
                spent[label] = 0.0
            first[0] = len(recording.step_s)

        r = run(scenario, guard, control_dt, recording, start)
    n, raw_step = r.exec_ticks, r.exec_raw / r.exec_steps
    steps = np.array(recording.step_s[first[0] :])
    by_place = [float(steps[k :: r.substeps].sum()) for k in range(r.substeps)]
    excess = [s / n - raw_step * len(steps[k :: r.substeps]) / n for k, s in enumerate(by_place)]
    raw_tick = r.exec_raw / n
    wall_tick = r.exec_wall / n
    tree_tick = r.tick_mean
    in_tree = (MoveHand, Step, live_risk.LiveRiskMonitor)
    inside_tree = sum(spent[label] for label, cls, _ in _PARTS if cls in in_tree)
    rows: list[tuple[str, float]] = [
        ("physics at the raw replay's speed", raw_tick),
        ("physics beyond it (cold caches), steps 0, 1, rest", sum(excess)),
    ]
    rows += [(label, spent[label] / n) for label, _, _ in _PARTS]
    rows += [
        ("rest of the tree tick (py_trees, selector, guard plumbing)", tree_tick - inside_tree / n),
    ]
    accounted = sum(v for label, v in rows if not label.startswith("  "))
    rows.append(("rest of the executive (loop, log, status; per-step recording)", wall_tick - accounted))
    print(
        f"\nbreakdown, guards {'on' if guard else 'off'} (one instrumented run, {n} ticks of "
        f"{r.substeps} steps): {wall_tick * 1e6:.0f} us per tick = {wall_tick / raw_tick:.2f}x raw"
    )
    for label, v in rows:
        extra = ""
        if label.startswith("physics beyond"):
            extra = "  (" + ", ".join(f"{e * 1e6:.0f}" for e in (excess[0], excess[1], sum(excess[2:]))) + ")"
        print(f"  {label:<62}{v * 1e6:>7.1f} us {v / raw_tick:>6.3f}x{extra}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument("--repeat", type=int, default=3, help="runs per setting (default 3)")
    parser.add_argument(
        "--control-dt", type=float, default=0.02, help="control period of a tick, s (default 0.02: 50 Hz)"
    )
    parser.add_argument(
        "--breakdown",
        action="store_true",
        help="one more instrumented run per setting: where a tick's time goes",
    )
    args = parser.parse_args()
    freeze_startup_heap()  # as `executive run` does: the libraries out of the collector's reach
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

    if args.breakdown:
        for guard in (True, False):
            breakdown(args.scenario, guard, args.control_dt)


if __name__ == "__main__":
    main()
