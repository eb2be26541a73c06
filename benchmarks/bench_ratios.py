"""Every speed target of issue 31 in one run, as ratios measured side by side (docs/performance.md).

    python benchmarks/bench_ratios.py [--jobs J] [--repeat R] [--json FILE]

Prints the machine (CPU, cores, Python, MuJoCo, load average before and after) and, for
``book_transfer``:

1. planning plus analytic risk of every alternative (CPU s): the first in the process on a fresh
   world, as ``executive plan`` does it, and the best of ``R`` warm ones; also in raw ``mj_step``
   of the scene and in a fixed pure-Python loop, so machines can be compared (target: under 1 s
   on the docs' machine);
2. risk per knot against raw ``mj_kinematics`` + ``coal.distance`` on the same pairs (target 2x);
3. dry runs against the raw ``mj_step`` replay of the same steps (target 1.3x);
4. a whole physics-checked decision on ``J`` warm workers, the time budget lifted: its wall time
   over the raw ``mj_step`` time of the steps it simulated divided over the jobs, the physics
   check alone and with planning (target 1.3x); the same in CPU (the workers' CPU from
   ``/proc`` and this process's, over the raw CPU of the steps): what the load of other
   processes does not inflate;
5. ticking the mission against the raw replay of its steps, CPU of the ticking thread, guards
   on and off (targets 1.3x and 1.2x; median of ``R`` runs each, interleaved);
6. the planned robot time of every alternative of each bundled scenario's tasks.

Each part reuses the benchmark that measures it in detail (``bench_planning``,
``bench_physics_check``, ``bench_rollout_allocation``, ``bench_executive``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core: no BLAS threads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import concurrent.futures
import contextlib
import io
import json
import platform
import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from bench_executive import run as tick_run
from bench_physics_check import dry_run_overhead
from bench_planning import measure as plan_measure
from bench_rollout_allocation import decide_all, raw_step_s, with_config

from executive.decision.after_task import state_after
from executive.decision.assessment import assess_task
from executive.decision.physics_check import PhysicsCheck, RolloutPool
from executive.runtime.mission import freeze_startup_heap
from executive.scenario import load
from executive.world.model import build

SCENE = "book_transfer"
BUNDLED = ("book_transfer", "glovebox", "pick_place_push")


def machine() -> dict[str, Any]:
    """What the numbers were measured on."""
    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
        "load_before": [round(v, 1) for v in os.getloadavg()],
    }


def python_loop_s() -> float:
    """Best of 3: CPU seconds of a fixed pure-Python loop (one million float additions and calls)."""

    def f(x: float) -> float:
        return x + 1.0

    best = np.inf
    for _ in range(3):
        t, x = time.process_time(), 0.0
        for _ in range(1_000_000):
            x = f(x)
        best = min(best, time.process_time() - t)
    return float(best)


def process_cpu_s(pids: list[int]) -> float:
    """CPU seconds (user + system) the processes ``pids`` have used so far (Linux ``/proc``)."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for pid in pids:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])  # utime, stime (proc(5), fields 14 and 15)
    return total / tick


def decision_ratio(jobs: int) -> dict[str, float]:
    """Every task of book_transfer decided on warm workers: wall over raw steps / jobs, and CPU
    (the workers' and this process's) over the raw steps' CPU."""
    base = load(SCENE)
    step_s, step_cpu = raw_step_s(base), raw_step_s(base, cpu=True)
    pool = RolloutPool(jobs)
    concurrent.futures.wait(pool.warm())
    try:
        pids = list(pool.start()._processes)  # the warm workers
        c0, w0 = process_cpu_s(pids), time.process_time()
        run = decide_all(with_config(base), PhysicsCheck(jobs, run_map=pool))
        cpu = process_cpu_s(pids) - c0 + time.process_time() - w0
    finally:
        pool.close()
    raw = run["steps"] * step_s / jobs
    return {
        "check_cpu_x": cpu / (run["steps"] * step_cpu),
        "steps": run["steps"],
        "raw_step_us": step_s * 1e6,
        "check_s": run["check_s"],
        "plan_s": run["plan_s"],
        "check_x": run["check_s"] / raw,
        "with_planning_x": (run["check_s"] + run["plan_s"]) / raw,
    }


def ticking_ratio(repeat: int) -> dict[str, float]:
    """Median CPU ratio of the ticking thread to the raw replay, guards on and off, interleaved."""
    on, off = [], []
    for _ in range(repeat):
        for guard, out in ((True, on), (False, off)):
            out.append(tick_run(SCENE, guard).cpu_ratio)
    return {"on_x": float(np.median(on)), "off_x": float(np.median(off)), "runs": repeat}


def planned_durations() -> dict[str, dict[str, float | None]]:
    """Planned robot time (s) of every alternative of every task of the bundled scenarios."""
    out: dict[str, dict[str, float | None]] = {}
    for name in BUNDLED:
        scenario = load(name)
        world = build(scenario)
        q_start = None
        for i, task in enumerate(scenario.mission):
            results = assess_task(world, task, q_start=q_start)
            out[f"{name} task {i}"] = {a.name: (a.plan.duration if a.plan else None) for a in results}
            q_start = state_after(scenario, world, task, results, q_start)
    return out


def report(r: dict[str, Any]) -> None:
    """Prints the summary table of :func:`main`'s measurements."""
    m, p, d, c, t = r["machine"], r["planning"], r["dry_runs"], r["decision"], r["ticking"]
    print(f"\nmachine: {m['cpu']}, {m['cores']} cores, Python {m['python']}, MuJoCo {m['mujoco']}")
    print(f"load average before {m['load_before']}, after {m['load_after']}")
    loop, step = r["python_loop_s"], c["raw_step_us"]
    print(f"a pure-Python loop of 1e6 calls: {loop:.3f} s CPU; raw mj_step {step:.0f} us")
    rows = [
        ("plan + analytic risk, first in process (CPU s)", f"{r['planning_cold_s']:.2f}", "< 1 s (docs')"),
        ("plan + analytic risk, warm, best (CPU s)", f"{p['total']:.2f}", ""),
        ("  the same in raw mj_steps of the scene", f"{p['total'] / (c['raw_step_us'] * 1e-6):.0f}", ""),
        ("  the same in pure-Python loops of 1e6 calls", f"{p['total'] / r['python_loop_s']:.1f}", ""),
        ("risk per knot / raw kinematics + coal", f"{p['assess'] / p['raw']:.2f}x", "<= 2x"),
        ("dry runs / raw mj_step (thread CPU)", f"{d['cpu'] / d['raw_cpu']:.2f}x", "<= 1.3x"),
        ("decision: physics check / (raw steps / jobs), wall", f"{c['check_x']:.2f}x", "<= 1.3x"),
        ("decision with planning / (raw steps / jobs), wall", f"{c['with_planning_x']:.2f}x", ""),
        ("decision with planning, CPU / raw steps' CPU", f"{c['check_cpu_x']:.2f}x", ""),
        ("ticking, guards on / raw mj_step (thread CPU)", f"{t['on_x']:.2f}x", "<= 1.3x"),
        ("ticking, guards off / raw mj_step (thread CPU)", f"{t['off_x']:.2f}x", "<= 1.2x"),
    ]
    print(f"\n{'what':<52}{'measured':>10}  target")
    for what, value, target in rows:
        print(f"{what:<52}{value:>10}  {target}")
    print(f"decision: {c['steps']} physics steps, check {c['check_s']:.1f} s + planning {c['plan_s']:.1f} s")
    print("\nplanned robot time (s) per alternative:")
    for task, alts in r["durations"].items():
        cells = ", ".join(f"{k} {'-' if v is None else f'{v:.1f}'}" for k, v in alts.items())
        print(f"  {task}: {cells}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="worker processes of the decision (default 2)")
    parser.add_argument("--repeat", type=int, default=3, help="planning and tick runs (default 3)")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers to this file")
    args = parser.parse_args()
    freeze_startup_heap()  # as `executive run` does
    r: dict[str, Any] = {"machine": machine(), "python_loop_s": python_loop_s()}
    c0 = time.process_time()
    assess_task(build(load(SCENE)), load(SCENE).mission[0])
    r["planning_cold_s"] = time.process_time() - c0
    with contextlib.redirect_stdout(io.StringIO()):  # the detailed tables belong to each benchmark
        r["planning"] = plan_measure(args.repeat)
        r["dry_runs"] = dry_run_overhead(load(SCENE))
    print("1-3 planning, risk per knot, dry runs: done", flush=True)
    r["decision"] = decision_ratio(args.jobs)
    print("4 decision: done", flush=True)
    r["ticking"] = ticking_ratio(args.repeat)
    print("5 ticking: done", flush=True)
    r["durations"] = planned_durations()
    r["machine"]["load_after"] = [round(v, 1) for v in os.getloadavg()]
    report(r)
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
