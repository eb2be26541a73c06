"""Process priority of the executive's helper processes (planning worker, rollout processes).

A host may call the executive from a real-time thread (``SCHED_FIFO`` or ``SCHED_RR``: a
controller's). A process spawned from such a thread inherits its policy, and a planning worker
at real-time priority would take the cores from the very loop it should spare. Spawn helper
processes inside :func:`normal_policy_children`: their policy is reset to the normal one
(``SCHED_RESET_ON_FORK``, sched(7)), the calling thread's is left as it was.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

__all__ = ["normal_policy_children"]

_REAL_TIME = {getattr(os, "SCHED_FIFO", -2), getattr(os, "SCHED_RR", -2)}


@contextlib.contextmanager
def normal_policy_children() -> Iterator[None]:
    """Processes started inside this block run at the normal policy even if the calling thread
    is real-time (Linux; elsewhere, and for a normal thread, this does nothing)."""
    flag = getattr(os, "SCHED_RESET_ON_FORK", 0)
    try:
        policy = os.sched_getscheduler(0) & ~flag
        param = os.sched_getparam(0)
    except (AttributeError, OSError):  # no POSIX scheduling here
        policy, param = -1, None
    if policy not in _REAL_TIME or not flag or param is None:
        yield
        return
    os.sched_setscheduler(0, policy | flag, param)
    try:
        yield
    finally:
        os.sched_setscheduler(0, policy, param)
