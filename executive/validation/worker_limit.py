"""How many worker processes this machine holds: the limit on ``campaign`` and ``fidelity --jobs``.

A campaign's worker holds its own MuJoCo worlds, planner and plans (:data:`WORKER_BYTES` each)
and keeps one core busy: more workers than cores run no faster, and more than the memory holds
make the machine swap or the kernel kill them. :func:`max_workers` is the smaller of the
usable cores (the process's CPU affinity, a cgroup's CPU quota) and the available memory (the
kernel's ``MemAvailable``, or a cgroup's limit less its use) over :data:`WORKER_BYTES`, at
least 1. :func:`check_jobs` refuses more (docs/embedding.md, "Worker processes").
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import NamedTuple

from executive.errors import ExecutiveError

__all__ = ["WORKER_BYTES", "Capacity", "capacity", "check_jobs", "max_workers"]

#: What one campaign worker holds, about (measured 200-300 MB: docs/embedding.md).
WORKER_BYTES = 300 * 2**20

_PROC = Path("/proc")
_CGROUP = Path("/sys/fs/cgroup")


class Capacity(NamedTuple):
    """What this process may use: cores, and bytes of memory (None: unknown)."""

    cpus: int
    memory: int | None

    @property
    def workers(self) -> int:
        """The worker processes that fit: the cores, or fewer if the memory holds fewer; at least 1."""
        by_memory = self.cpus if self.memory is None else self.memory // WORKER_BYTES
        return max(1, min(self.cpus, by_memory))


def _affinity() -> int:
    """The cores this process may run on (its CPU affinity; the machine's where unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _cpus(cpus: int, cgroup: Path | None) -> int:
    """``cpus``, fewer under a cgroup's CPU quota (``cpu.max``: quota and period)."""
    if cgroup is not None:
        try:
            quota, period = (cgroup / "cpu.max").read_text().split()[:2]
            if quota != "max":
                cpus = min(cpus, max(1, math.ceil(int(quota) / int(period))))
        except (OSError, ValueError):
            pass
    return max(1, cpus)


def _memory(proc: Path, cgroup: Path | None) -> int | None:
    """Bytes of memory available: ``MemAvailable`` (proc(5)), less under a cgroup's limit."""
    available: int | None = None
    try:
        for line in (proc / "meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if cgroup is not None:
        try:
            limit = (cgroup / "memory.max").read_text().strip()
            if limit != "max":
                room = max(0, int(limit) - int((cgroup / "memory.current").read_text()))
                available = room if available is None else min(available, room)
        except (OSError, ValueError):
            pass
    return available


def _own_cgroup(proc: Path, root: Path) -> Path | None:
    """This process's cgroup v2 folder (``0::/path`` in ``/proc/self/cgroup``), None without one."""
    try:
        for line in (proc / "self" / "cgroup").read_text().splitlines():
            if line.startswith("0::"):
                folder = root / line[3:].strip().lstrip("/")
                return folder if folder.is_dir() else None
    except OSError:
        pass
    return None


def capacity(proc: Path = _PROC, cgroup_root: Path = _CGROUP, cores: int | None = None) -> Capacity:
    """This machine's cores and available memory, as this process sees them.

    Args:
        proc, cgroup_root: where ``/proc`` and ``/sys/fs/cgroup`` are (others: tests).
        cores: the cores before a cgroup's quota (default: this process's CPU affinity).
    """
    cgroup = _own_cgroup(proc, cgroup_root)
    return Capacity(_cpus(_affinity() if cores is None else cores, cgroup), _memory(proc, cgroup))


def max_workers() -> int:
    """The most worker processes this machine holds now (:attr:`Capacity.workers`)."""
    return capacity().workers


def check_jobs(jobs: int, option: str = "--jobs", machine: Capacity | None = None) -> None:
    """Refuse more worker processes than the machine holds.

    Args:
        jobs: the worker processes asked for.
        option: how the user gave them, for the message.
        machine: the capacity to check against (default: this machine's now).

    Raises:
        ExecutiveError: ``jobs`` is above :attr:`Capacity.workers`; the message names the limit
            and why (exit 2 in the command).
    """
    machine = machine if machine is not None else capacity()
    limit = machine.workers
    if jobs <= limit:
        return
    memory = (
        "available memory unknown"
        if machine.memory is None
        else f"{machine.memory / 2**30:.1f} GiB of memory available at about "
        f"{WORKER_BYTES // 2**20} MB per worker"
    )
    raise ExecutiveError(
        f"{option} {jobs}: this machine holds at most {limit} worker process(es) "
        f"({machine.cpus} usable core(s), {memory}); use {option} {limit} or fewer"
    )
