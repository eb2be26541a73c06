"""The test suite's CPU time per test: a pytest plugin, and the report of what it wrote.

Wall time on a shared machine says how busy the machine was; CPU time says what a test costs.
The plugin charges each test (setup, call and teardown) with the CPU time of the pytest process
and of its descendants: those it reaped during the test (``RUSAGE_CHILDREN``) and those still
alive (a kept-warm planning worker, its rollout processes: their ``/proc/<pid>/stat`` times).
Each pytest process (each pytest-xdist worker) writes its own JSON file.

    PYTHONPATH=benchmarks SUITE_CPU_OUT=/tmp/suite_cpu python -m pytest -q -p suite_cpu
    python benchmarks/suite_cpu.py /tmp/suite_cpu [--top 20]

The sum over the tests is the suite's CPU time: what the suite costs whatever else the machine
runs. On two idle cores (pytest-xdist, two workers busy) the wall time is about half of it plus
the workers' start; docs/performance.md has the suite's numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from collections import defaultdict
from collections.abc import Generator
from pathlib import Path
from typing import Any

import pytest

_TICK = os.sysconf("SC_CLK_TCK")
_rows: list[dict[str, Any]] = []


def _live_descendants() -> dict[int, float]:
    """CPU seconds (user + system) of each live descendant of this process, by pid (Linux /proc)."""
    parent: dict[int, int] = {}
    cpu: dict[int, float] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            fields = Path(f"/proc/{entry}/stat").read_bytes().rsplit(b")", 1)[1].split()
        except OSError:
            continue
        parent[int(entry)] = int(fields[1])
        cpu[int(entry)] = (int(fields[11]) + int(fields[12])) / _TICK  # utime, stime: proc(5)
    me, mine = os.getpid(), {}
    for pid in parent:
        ancestor, hops = parent[pid], 0
        while ancestor > 1 and hops < 64:
            if ancestor == me:
                mine[pid] = cpu[pid]
                break
            ancestor, hops = parent.get(ancestor, 0), hops + 1
    return mine


def _own_and_reaped() -> tuple[float, float]:
    """CPU seconds of this process, and of its children reaped so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    reaped = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, reaped.ru_utime + reaped.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None, None, None]:
    """Charge ``item`` with the CPU time spent while it ran."""
    own0, reaped0 = _own_and_reaped()
    live0, wall0 = _live_descendants(), time.perf_counter()
    yield
    live1 = _live_descendants()
    own1, reaped1 = _own_and_reaped()
    live = sum(cpu - live0.get(pid, 0.0) for pid, cpu in live1.items())
    before = sum(cpu for pid, cpu in live0.items() if pid not in live1)  # reaped: counted in reaped1
    children = reaped1 - reaped0 + live - before
    _rows.append({"test": item.nodeid, "own": own1 - own0, "children": children})
    _rows[-1]["wall"] = time.perf_counter() - wall0


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Write this process's rows to ``$SUITE_CPU_OUT/<worker>.json``."""
    folder = Path(os.environ.get("SUITE_CPU_OUT", "suite_cpu"))
    folder.mkdir(parents=True, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    if _rows:
        (folder / f"{worker}.json").write_text(json.dumps(_rows))


def main() -> None:
    """Print the suite's CPU time, its slowest tests and its files by CPU time."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="the SUITE_CPU_OUT folder of a run")
    parser.add_argument("--top", type=int, default=20, help="how many tests to list (default 20)")
    args = parser.parse_args()
    rows = [r for f in sorted(args.folder.glob("*.json")) for r in json.loads(f.read_text())]
    for r in rows:
        r["cpu"] = r["own"] + r["children"]
    total = sum(r["cpu"] for r in rows)
    print(f"{len(rows)} tests: {total:.0f} s CPU ({total / 60:.1f} min), {total / 2 / 60:.1f} min on 2 cores")
    print(f"{'CPU s':>7} {'own':>6} {'child':>6} {'wall s':>7}  test")
    for r in sorted(rows, key=lambda r: -r["cpu"])[: args.top]:
        print(f"{r['cpu']:7.1f} {r['own']:6.1f} {r['children']:6.1f} {r['wall']:7.1f}  {r['test']}")
    files: dict[str, float] = defaultdict(float)
    for r in rows:
        files[r["test"].split("::")[0]] += r["cpu"]
    print("by file:")
    for name, cpu in sorted(files.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"{cpu:7.1f}  {name}")


if __name__ == "__main__":
    main()
