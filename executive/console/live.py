"""What the ticking loop hands the console: a throttled snapshot, taken in the tick, used elsewhere.

:class:`LiveFeed` is a tick listener (``Executive.tick_listeners``). At most ``rate_hz`` times
a second of wall time it copies the robot's ``qpos`` and time into a one-slot mailbox and
sets an event; every other tick it returns after one clock read and one comparison. It
never waits: the console's own thread takes the latest snapshot when it is ready, skipping
any it had no time for, and does all the drawing (kinematics, messages to the page) there.

:class:`RealTimePacer` lets a run with the console move at the speed of a real robot: the
bundled physics otherwise runs as fast as the processor allows (a 30 s motion in about
1 s), too fast to watch.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import py_trees
from numpy.typing import NDArray

__all__ = ["LiveFeed", "RealTimePacer", "Snapshot"]

RUNNING = py_trees.common.Status.RUNNING


@dataclass(frozen=True)
class Snapshot:
    """The robot's state at one tick: its full ``qpos`` (a copy), robot time, tick count, whether it
    was the mission's last tick."""

    qpos: NDArray[np.float64]
    time: float
    ticks: int
    done: bool
    wall: float  # perf_counter() when taken


class LiveFeed:
    """A tick listener that hands the console at most ``rate_hz`` snapshots a second.

    Args:
        rate_hz: the most snapshots per second of wall time (the page needs 20-30).
    """

    def __init__(self, rate_hz: float = 25.0) -> None:
        if rate_hz <= 0:
            raise ValueError(f"rate_hz must be positive, not {rate_hz}")
        self.period = 1.0 / rate_hz
        self.latest: Snapshot | None = None
        self.ready = threading.Event()
        self._next = 0.0
        self.taken = 0  # snapshots taken (for the benchmark and tests)

    def __call__(self, executive: Any) -> None:
        now = time.perf_counter()
        if now < self._next and executive.status == RUNNING:  # the mission's last tick is always taken
            return
        self._next = now + self.period
        robot = executive.robot
        self.latest = Snapshot(
            np.array(robot.data.qpos, dtype=float),
            float(robot.time),
            int(executive.ticks),
            executive.status != RUNNING,
            now,
        )
        self.taken += 1
        self.ready.set()

    def take(self, timeout: float) -> Snapshot | None:
        """The latest snapshot, waiting up to ``timeout`` s for one; None when none came."""
        if not self.ready.wait(timeout):
            return None
        self.ready.clear()
        return self.latest


class RealTimePacer:
    """Sleep in the ticking loop so robot time follows the wall clock (``speed`` x real time).

    Call :meth:`wait` after each tick with the robot's time. A loop that has fallen behind
    (planning, an answer awaited) starts counting again from where it is, rather than racing
    to catch up.
    """

    def __init__(self, speed: float = 1.0, max_lag_s: float = 0.25) -> None:
        if speed <= 0:
            raise ValueError(f"speed must be positive, not {speed}")
        self.speed, self.max_lag_s = speed, max_lag_s
        self._origin: tuple[float, float] | None = None  # (wall, robot time)

    def wait(self, robot_time: float) -> None:
        now = time.perf_counter()
        if self._origin is None:
            self._origin = (now, robot_time)
            return
        target = self._origin[0] + (robot_time - self._origin[1]) / self.speed
        if now > target + self.max_lag_s:
            self._origin = (now, robot_time)
        elif target > now:
            time.sleep(target - now)
