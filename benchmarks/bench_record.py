"""What the per-tick record costs the ticking loop: the executive with the recorder on vs off.

    python benchmarks/bench_record.py [SCENARIO] [--repeat N]

Uses the tick-cost benchmark of ``bench_executive.py`` (truth = estimate, auto approval,
live guards on; the execution phase's wall and thread-CPU time against a raw ``mj_step``
replay of the same steps) and runs it ``N`` times with the run folder's
:class:`executive.execution.tick_record.TickRecorder` attached and ``N`` times without,
interleaved, in one process. Prints per run the execution phase's ratio to raw physics, and
the recorder's own time per tick (its ``__call__`` timed with ``perf_counter``), the record's
bytes per second of robot time, then the on/off ratio of the medians.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_executive import run

from executive.execution.tick_record import TickRecorder, load_record
from executive.runtime.mission import Executive, freeze_startup_heap


class _Timed:
    """The recorder, its calls timed (the timer's two clock reads count against it)."""

    def __init__(self, recorder: TickRecorder) -> None:
        self.recorder = recorder
        self.spent = 0.0  # wall
        self.calls = 0

    def __call__(self, executive: Executive) -> None:
        t0 = time.perf_counter()
        self.recorder(executive)
        self.spent += time.perf_counter() - t0
        self.calls += 1


def steady_state(scenario: str, calls: int = 2000) -> tuple[float, float]:
    """The recorder's time for one tick of a motion, in isolation: (us warm, us between physics steps).

    A run is executed without the recorder; a recorder on its final tree then records ``calls``
    ticks (running path unchanged, no guard check), each after nothing (warm caches) or after
    the ten ``mj_step`` of a 50 Hz tick (the caches as the tick leaves them). The frames go to a
    temporary file.
    """
    ex = Executive(scenario, approval="auto", truth="exact", guard=True)
    while not ex.done:
        ex.tick()
    assert ex.truth is not None
    model, data = ex.truth.model, ex.truth.data
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        recorder = TickRecorder(Path(tmp), ex, truth="exact")  # records the last tick and closes
        recorder._frames = open(Path(tmp) / "frames", "ab", buffering=0)
        recorder._events = open(Path(tmp) / "events", "ab", buffering=0)
        recorder.closed = False
        for steps in (0, ex.robot.substeps):
            spent = 0.0
            for _ in range(calls):
                for _ in range(steps):
                    mujoco.mj_step(model, data)
                t0 = time.perf_counter()
                recorder._scan()
                recorder._write_frame(ex.ticks)
                spent += time.perf_counter() - t0
            out.append(spent / calls)
        recorder.close()
    return out[0], out[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument("--repeat", type=int, default=3, help="runs per setting (default 3)")
    args = parser.parse_args()
    freeze_startup_heap()
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f"{args.scenario}: guards on, truth = estimate; {os.cpu_count()} cpus, load average {load}")
    print(
        f"{'record':<8}{'exec ticks':>11}{'ratio':>7}{'cpu':>6}{'tick ms':>9}{'rec us/tick':>13}{'kB/s':>7}"
    )
    results: dict[bool, list[Any]] = {True: [], False: []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(max(1, args.repeat)):
            for on in (True, False):
                timed: list[_Timed] = []
                folder = Path(tmp) / f"run{i}"

                def attach(ex: Executive, folder: Path = folder, timed: list[_Timed] = timed) -> None:
                    timed.append(_Timed(TickRecorder(folder, ex, truth="exact")))
                    ex.tick_listeners.append(timed[0])

                r = run(args.scenario, True, setup=attach if on else None)
                per_tick = timed[0].spent / timed[0].calls if timed else 0.0
                rate = 0.0
                if on:
                    record = load_record(folder)
                    size = sum(p.stat().st_size for p in (folder / "record").iterdir())
                    rate = size / record.duration
                results[on].append((r, per_tick, rate))
                print(
                    f"{'on' if on else 'off':<8}{r.exec_ticks:>11}{r.ratio:>7.2f}{r.cpu_ratio:>6.2f}"
                    f"{r.exec_wall / r.exec_ticks * 1e3:>9.3f}"
                    f"{per_tick * 1e6:>13.1f}"
                    f"{rate / 1000:>7.1f}",
                    flush=True,
                )
    warm, stepped = steady_state(args.scenario)
    print(
        f"one tick's record in isolation: {warm * 1e6:.1f} us warm, {stepped * 1e6:.1f} us after a tick's "
        "physics steps"
    )
    on, off = results[True], results[False]
    med = {k: float(np.median([r.ratio for r, _, _ in v])) for k, v in ((True, on), (False, off))}
    cpu = {k: float(np.median([r.cpu_ratio for r, _, _ in v])) for k, v in ((True, on), (False, off))}
    rec = float(np.median([p for _, p, _ in on]))
    raw_tick = float(np.median([r.exec_raw / r.exec_ticks for r, _, _ in on]))
    print(
        f"execution phase / raw mj_step (median of {len(on)}): recorder on {med[True]:.3f}, "
        f"off {med[False]:.3f}, on/off {med[True] / med[False]:.3f}; "
        f"thread CPU on/off {cpu[True] / cpu[False]:.3f}"
    )
    print(
        f"the recorder itself (wall, all ticks): {rec * 1e6:.1f} us per tick = {rec / raw_tick:.3f}x "
        f"the raw physics of a tick ({raw_tick * 1e6:.0f} us); "
        f"record {np.median([b for _, _, b in on]) / 1000:.1f} kB per second of robot time"
    )


if __name__ == "__main__":
    main()
