"""What the operator's console costs the ticking loop: the executive with the console (and a headless
browser on its page) vs without.

    python benchmarks/bench_console_tick.py [SCENARIO] [--repeat N] [--no-browser]

Uses the tick-cost benchmark of ``bench_executive.py`` (truth = estimate, auto approval, live
guards on; the execution phase's wall time and the ticking thread's CPU time, each against a
raw ``mj_step`` replay of the same steps) and runs it ``N`` times with a
:class:`executive.console.console.Console` attached and ``N`` times without, interleaved, in one
process. With the console, a headless Chromium (Debian's ``/usr/bin/chromium``, driven by
Playwright) has the page open before the first tick, and the console's thread draws the scene
(25 updates a second at most), the decision, the ghosts and the tree while the loop ticks.
The bundled physics is not paced to the wall clock here (``executive run --console`` paces
it): the loop runs flat out, the worst case for the console's share.

Prints per run the execution phase's ratio to raw physics (wall, and CPU of the ticking
thread), the snapshots the console took, the console thread's CPU time and the browser's
(all its processes) per second of the execution phase; then the on/off ratio of the medians.
Target (issue 18): the console costs the ticking loop less than 5 % (on/off < 1.05).
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import py_trees

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_executive import run

from executive.console.console import Console
from executive.runtime.mission import Executive, freeze_startup_heap

CHROMIUM = "/usr/bin/chromium"
RUNNING = py_trees.common.Status.RUNNING
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def _cpu_s(stat: str) -> float:
    """utime + stime (s) of a /proc ``stat`` file."""
    try:
        with open(stat) as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def _descendants(pid: int) -> list[int]:
    """Every process started below ``pid`` (the browser's)."""
    out: list[int] = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                children = [int(c) for c in f.read().split()]
        except OSError:
            continue
        for child in children:
            out += [child, *_descendants(child)]
    return out


class _Meter:
    """CPU seconds between two readings: this process (all its threads) and the browser's
    processes (a process that ends or starts in between counts for the time both readings saw it)."""

    def __init__(self) -> None:
        self.start: tuple[float, dict[int, float]] = (0.0, {})
        self.stop: tuple[float, dict[int, float]] | None = None

    @staticmethod
    def read() -> tuple[float, dict[int, float]]:
        return _cpu_s("/proc/self/stat"), {p: _cpu_s(f"/proc/{p}/stat") for p in _descendants(os.getpid())}

    def begin(self) -> None:
        self.start = self.read()

    def __call__(self, executive: Executive) -> None:
        """A tick listener: the second reading at the mission's last tick."""
        if executive.status != RUNNING and self.stop is None:  # (done is set after the listeners)
            self.stop = self.read()

    def spent(self) -> tuple[float, float]:
        """(this process, the browser) from :meth:`begin` to the last tick."""
        assert self.stop is not None
        process, browser = self.stop
        before = self.start[1]
        used = sum(v - before[p] for p, v in browser.items() if p in before and v >= before[p])
        return process - self.start[0], used


def _renice(nice: int) -> None:
    """Lower every thread of the browser's processes (every process below this one) to ``nice``
    (Linux keeps a niceness per thread)."""
    for pid in _descendants(os.getpid()):
        try:
            threads = os.listdir(f"/proc/{pid}/task")
        except OSError:  # it ended meanwhile
            continue
        for tid in threads:
            try:
                os.setpriority(os.PRIO_PROCESS, int(tid), nice)
            except OSError:
                pass


def _browser(no_browser: bool) -> tuple[Any, Any]:
    """(playwright, page) of a headless Chromium, or (None, None)."""
    if no_browser:
        return None, None
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    browser = pw.chromium.launch(
        executable_path=CHROMIUM, args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
    )
    return pw, browser.new_page(viewport={"width": 1280, "height": 800})


class _Timed:
    """A tick listener with its calls timed (the timer's two clock reads count against it)."""

    def __init__(self, listener: Any) -> None:
        self.listener = listener
        self.spent = 0.0
        self.calls = 0

    def __call__(self, executive: Executive) -> None:
        t0 = time.perf_counter()
        self.listener(executive)
        self.spent += time.perf_counter() - t0
        self.calls += 1


@dataclass
class Sample:
    """One run: the tick-cost benchmark's numbers and, over its execution phase, the CPU of this
    process's threads other than the ticking one (the console's, viser's), of the browser, and
    the feed's mean time in a tick."""

    run: Any
    snapshots: int
    others_s: float
    browser_s: float
    feed_s: float

    def per_s(self, seconds: float) -> float:
        return seconds / self.run.exec_wall


def _one(scenario: str, on: bool, page: Any, nice: int) -> Sample:
    """One run with (``on``) or without the console."""
    consoles: list[Console] = []
    listeners: list[_Timed] = []
    meter = _Meter()

    def attach(ex: Executive) -> None:
        ex.tick_listeners.append(meter)
        if not on:
            return
        console = Console(0, title=scenario)
        console.attach(ex)
        ex.tick_listeners[-1] = timed = _Timed(console.feed)  # the feed, its calls timed (after the meter)
        listeners.append(timed)
        consoles.append(console)
        if page is not None:
            page.goto(console.url)
            page.get_by_text("robot time").first.wait_for(timeout=60_000)
            _renice(nice)  # a page load may start a new renderer

    def execute() -> None:
        meter.begin()
        for timed in listeners:  # the execution phase's ticks only
            timed.spent, timed.calls = 0.0, 0

    try:
        r = run(scenario, True, setup=attach, on_execute=execute)
        process, browser = meter.spent()
        taken = consoles[0].feed.taken if consoles else 0
        feed = listeners[0].spent / max(1, listeners[0].calls) if listeners else 0.0
    finally:
        for console in consoles:
            console.close()
    return Sample(r, taken, max(0.0, process - r.exec_cpu), browser if on else 0.0, feed)


def _retried(scenario: str, on: bool, page: Any, nice: int, tries: int = 3) -> Sample:
    """:func:`_one`, run again when the mission did not succeed (bench_executive exits then)."""
    for attempt in range(tries):
        try:
            return _one(scenario, on, page, nice)
        except SystemExit as exc:
            print(f"(run {attempt + 1} did not succeed, again: {str(exc)[:160]})", flush=True)
    raise SystemExit(f"no successful run in {tries} tries")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument("--repeat", type=int, default=3, help="runs per setting (default 3)")
    parser.add_argument("--no-browser", action="store_true", help="the console without a page open")
    parser.add_argument(
        "--browser-nice",
        type=int,
        default=19,
        help="niceness of the browser's processes (default 19: it gets what the robot's loop leaves, as "
        "a browser on the operator's own machine would; 0: it competes for the cores as an equal)",
    )
    args = parser.parse_args()
    freeze_startup_heap()
    pw, page = _browser(args.no_browser)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    browser = "no browser" if page is None else f"headless Chromium on the page (nice {args.browser_nice})"
    print(
        f"{args.scenario}: guards on, truth = estimate, {browser}; {os.cpu_count()} cpus, load average {load}"
    )
    print(
        f"{'console':<8}{'exec ticks':>11}{'exec s':>8}{'ratio':>7}{'cpu':>6}{'snapshots':>10}"
        f"{'others cpu/s':>13}{'browser cpu/s':>14}{'feed us':>9}"
    )
    samples: dict[bool, list[Sample]] = {True: [], False: []}
    try:
        for _ in range(max(1, args.repeat)):
            for on in (True, False):
                x = _retried(args.scenario, on, page, args.browser_nice)
                samples[on].append(x)
                r = x.run
                print(
                    f"{'on' if on else 'off':<8}{r.exec_ticks:>11}{r.exec_wall:>8.2f}{r.ratio:>7.2f}"
                    f"{r.cpu_ratio:>6.2f}{x.snapshots:>10}{x.per_s(x.others_s):>13.3f}"
                    f"{x.per_s(x.browser_s):>14.3f}{x.feed_s * 1e6:>9.2f}",
                    flush=True,
                )
    finally:
        if pw is not None:
            pw.stop()
    _summary(samples)


def _summary(samples: dict[bool, list[Sample]]) -> None:
    """The on/off ratios of the medians, and the console's own share of the loop's time."""
    on, off = samples[True], samples[False]

    def median(xs: list[Sample], f: Any) -> float:
        return float(np.median([f(x) for x in xs]))

    wall = (median(on, lambda x: x.run.ratio), median(off, lambda x: x.run.ratio))
    cpu = (median(on, lambda x: x.run.cpu_ratio), median(off, lambda x: x.run.cpu_ratio))
    best = (min(x.run.ratio for x in on), min(x.run.ratio for x in off))
    print(
        f"execution phase / raw mj_step (median of {len(on)}): console on {wall[0]:.3f}, off {wall[1]:.3f}; "
        f"on/off {wall[0] / wall[1]:.3f} (wall), {cpu[0] / cpu[1]:.3f} (CPU of the ticking thread); "
        f"best of {len(on)}: on/off {best[0] / best[1]:.3f} (wall); target < 1.05"
    )
    others = median(on, lambda x: x.per_s(x.others_s)) - median(off, lambda x: x.per_s(x.others_s))
    feed = median(on, lambda x: x.per_s(x.feed_s * x.run.exec_ticks))
    print(
        f"the console's own time per second of execution (median): its threads (console, viser) "
        f"{others:.4f} s of CPU more than without it, the feed inside the tick {feed:.5f} s: "
        f"{others + feed:.3f} of the loop's time at most (a thread delays the loop only while it "
        f"holds the interpreter); the browser {median(on, lambda x: x.per_s(x.browser_s)):.2f} cores"
    )
    alive = [t.name for t in threading.enumerate() if t.name == "console"]
    if alive:
        print(f"(console threads still alive: {len(alive)})")


if __name__ == "__main__":
    main()
