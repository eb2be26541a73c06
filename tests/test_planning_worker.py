"""The planning worker process (executive/decision/planning_worker.py): the selector's heavy work
off the ticking process, a worker that dies or hangs noticed, logged and replaced.

Real parts throughout: the worker is a spawned process that plans with mink, assesses with coal
and dry-runs in MuJoCo; it is killed with SIGKILL and stopped with SIGSTOP as an operating
system would; the mission's outcome is read from the truth world.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import struct
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from executive.decision.physics_check import with_rollouts
from executive.decision.planning_job import EstimateState, Planning, PlanningJob, PlanningResult, ranked
from executive.decision.planning_worker import HANG_S, JOB_S, PlanningWorker, WorkerLost
from executive.monitoring.live_risk import LiveRiskMonitor
from executive.runtime.mission import Executive
from executive.scenario import load
from executive.world.model import build

TARGET = (0.52, -0.26)  # book_transfer's target (x, y), m


def _bits(value: Any) -> Any:
    """``value`` as nested tuples of bytes: equal exactly when every number is equal bit for bit."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return (
            type(value).__name__,
            tuple((f.name, _bits(getattr(value, f.name))) for f in dataclasses.fields(value)),
        )
    if isinstance(value, dict):
        return ("dict", tuple(sorted((repr(k), _bits(v)) for k, v in value.items())))
    if isinstance(value, set | frozenset):  # iteration order follows the process's string hashing
        return ("set", tuple(sorted(repr(_bits(v)) for v in value)))
    if isinstance(value, list | tuple):
        return ("seq", tuple(_bits(v) for v in value))
    if isinstance(value, np.ndarray):
        return ("nd", value.dtype.str, value.shape, np.ascontiguousarray(value).tobytes())
    if isinstance(value, float | np.floating):
        return ("f", struct.pack("<d", float(value)))
    return ("v", repr(value))


def _untimed(result: PlanningResult) -> list[Any]:
    """The alternatives of ``result`` without their wall times (which differ run to run)."""
    return [dataclasses.replace(a, plan_s=0.0, assess_s=0.0) for a in result.results]


def _job(world: Any, physics: bool) -> PlanningJob:
    task = world.scenario.mission[0]
    return PlanningJob("task0", task, np.array(world.data.qpos), EstimateState.of(world), physics=physics)


def _wait(
    worker: PlanningWorker, ticket: int, timeout_s: float = 120.0, quiet: list[float] | None = None
) -> PlanningResult | None:
    """The result of ``ticket``, polled as a selector polls (None: none within ``timeout_s``, a hang
    guard). ``quiet`` collects the times (``time.monotonic``) at which a poll found nothing amiss."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        asked = time.monotonic()
        result = worker.poll(ticket)
        if result is not None:
            return result
        if quiet is not None:
            quiet.append(asked)
        time.sleep(0.01)
    return None


def test_the_worker_plans_what_this_process_plans_bit_for_bit() -> None:
    """book_transfer planned and assessed in the worker and here: the same choice, the same plans
    and risk numbers to the last bit, the same guard distances of the chosen alternative.

    The worker first served another scenario (pick_place_push) and was kept warm when closed; the
    next worker of this process is that process, and carries nothing of the first scenario."""
    other = load("pick_place_push")
    first = PlanningWorker(other, jobs=0)
    served = _wait(first, first.submit(_job(build(other), physics=False)))
    assert served is not None and served.failure is None
    first.close()  # idle and healthy: kept warm
    scenario = load("book_transfer")
    worker = PlanningWorker(scenario, jobs=0)
    try:
        assert worker.pid == first.pid == served.pid  # the same process, no new spawn
        world = build(scenario)
        job = _job(world, physics=False)
        ticket = worker.submit(job)  # the worker plans while this process does
        here = Planning(world, None, LiveRiskMonitor(world, scenario.risk.guard)).run(job)
        there = _wait(worker, ticket)
    finally:
        worker.close(wait=True)
    assert there is not None and here.failure is None and there.failure is None
    assert there.pid != os.getpid() and here.pid == os.getpid()
    ordering = scenario.risk.ordering
    chosen = [a.name for a in ranked(here.results, ordering)]
    print(f"ranking {chosen}; here {here.work_s:.2f} s, worker {there.work_s:.2f} s")
    assert [a.name for a in ranked(there.results, ordering)] == chosen and len(chosen) == 3
    for a, b in zip(_untimed(here), _untimed(there), strict=True):
        assert _bits(a) == _bits(b), a.name
    assert len(here.knots) == len(there.knots) > 0
    assert _bits(list(here.knots)) == _bits(list(there.knots))


def test_a_stopped_worker_is_noticed_at_the_first_poll_past_hang_s_and_a_long_job_is_not() -> None:
    """SIGSTOP (a hang: its heartbeat stops) is noticed by the first poll more than HANG_S after the
    stop; the fresh worker then does the same job, longer than HANG_S (dry runs in physics), without
    being taken for hung. (Judged by which poll noticed, not by a time: a loaded machine polls less
    often, and no poll may miss the hang.)"""
    scenario = with_rollouts(load("book_transfer"), 0)
    worker = PlanningWorker(scenario, jobs=1)
    try:
        assert worker.wait_ready(120.0)
        job = _job(build(scenario), physics=True)
        ticket = worker.submit(job)
        time.sleep(0.3)
        hung = worker.pid
        assert hung is not None
        os.kill(hung, signal.SIGSTOP)
        assert _until_stopped(hung)  # the heartbeat thread stopped with it: no beat after this
        stopped = time.monotonic()
        quiet: list[float] = []
        with pytest.raises(WorkerLost) as lost:
            _wait(worker, ticket, quiet=quiet)
        noticed = time.monotonic() - stopped
        print(f"noticed after {noticed:.2f} s, {len(quiet)} quiet polls before: {lost.value}")
        assert "hangs: stopped" in lost.value.reason and lost.value.pid == hung
        # The last heartbeat came before the stop: a poll that found nothing amiss was asked at most
        # HANG_S after the stop (0.05 s: a beat written while SIGSTOP was on its way).
        assert all(asked - stopped <= HANG_S + 0.05 for asked in quiet), (quiet[-1] - stopped, HANG_S)
        silence = float(lost.value.reason.split("no heartbeat for ")[1].split(" s")[0])
        assert silence >= HANG_S  # and not before the heartbeat was HANG_S old (printed to 0.01 s)
        fresh = worker.replace()
        assert fresh != hung
        ticket = worker.submit(job)
        result = _wait(worker, ticket)  # raises WorkerLost if the long job were taken for a hang
    finally:
        worker.close(wait=True)
    assert result is not None
    print(f"the fresh worker's job took {result.work_s:.2f} s")
    assert result.failure is None and result.pid == fresh and result.verdict is not None
    assert result.work_s > HANG_S
    assert _gone(hung)


def test_a_job_past_its_deadline_is_a_hang_though_the_worker_beats() -> None:
    """A job that runs longer than ``job_s`` (here book_transfer's planning, about a second, against
    0.3 s) is reported as a hang although the worker's heartbeat is fresh: how an endless loop is
    noticed. The default deadline is JOB_S plus the scenario's rollout budget."""
    scenario = load("book_transfer")
    assert PlanningWorker(scenario, jobs=0).job_s == JOB_S + scenario.risk.rollouts.budget_s
    worker = PlanningWorker(scenario, jobs=0, job_s=0.3)
    quiet: list[float] = []
    try:
        assert worker.wait_ready(120.0)
        job = _job(build(scenario), physics=False)
        sent = time.monotonic()
        ticket = worker.submit(job)
        submitted = time.monotonic()
        with pytest.raises(WorkerLost) as lost:  # a result instead: the job ended before its deadline
            _wait(worker, ticket, timeout_s=120.0, quiet=quiet)
        noticed = time.monotonic() - sent
    finally:
        worker.close(wait=True)
    print(f"{lost.value} after {noticed:.2f} s, {len(quiet)} quiet polls before")
    assert "hangs: a job has run for" in lost.value.reason and "limit 0.3 s" in lost.value.reason
    ran = float(lost.value.reason.split("has run for ")[1].split(" s")[0])
    assert 0.3 <= ran <= noticed + 0.05 and noticed >= 0.3  # never before the deadline
    # and by the first poll past it: every poll that found nothing amiss was asked within 0.3 s
    assert all(asked - submitted <= 0.3 for asked in quiet), quiet[-1] - submitted


def test_a_forked_child_does_not_take_its_parents_idle_worker() -> None:
    """A worker kept warm belongs to the process that started it: a child forked after (a host
    that forks, the kill tests here) starts its own worker instead of writing to the parent's pipe."""
    scenario = load("book_transfer")
    parked = PlanningWorker(scenario, jobs=0, nice=4)  # a key of its own: this test's worker
    assert parked.wait_ready(120.0)
    parked.close()  # idle and healthy: kept warm
    pid = os.fork()
    if pid == 0:  # the child: a worker of its own, not the parent's
        code = 1
        try:
            mine = PlanningWorker(scenario, jobs=0, nice=4)
            code = 0 if mine.pid != parked.pid and mine.wait_ready(120.0) else 2
            mine.close(wait=True)
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    again = PlanningWorker(scenario, jobs=0, nice=4)  # the parent still has it
    try:
        assert os.waitstatus_to_exitcode(status) == 0
        assert again.pid == parked.pid and again.wait_ready(120.0)
    finally:
        again.close(wait=True)


def _until_stopped(pid: int, within_s: float = 60.0) -> bool:
    """Wait until every thread of process ``pid`` is stopped (state T; a signal's delivery waits
    for the process to get a core); whether they were within ``within_s`` (a hang guard)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        stats = Path(f"/proc/{pid}/task").glob("*/stat")
        states = {p.read_text().rsplit(")", 1)[1].split()[0] for p in stats}
        if states and states <= {"T", "t"}:
            return True
        time.sleep(0.001)
    return False


def _gone(pid: int, within_s: float = 5.0) -> bool:
    """Whether process ``pid`` has ended (or is a zombie) within ``within_s``."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (FileNotFoundError, ProcessLookupError):
            return True
        if state in ("Z", "X"):
            return True
        time.sleep(0.05)
    return False


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux /proc; empty where the kernel does not list them)."""
    out: list[int] = []
    for path in Path(f"/proc/{pid}/task").glob("*/children"):
        out += [int(c) for c in path.read_text().split()]
    return out


def test_a_worker_killed_mid_plan_is_logged_and_replaced_and_the_mission_completes() -> None:
    """SIGKILL to the planning worker while it plans: the executive logs it at the next tick, starts a
    fresh worker, re-plans from where the robot holds and places the book (exact truth)."""
    scenario = with_rollouts(load("book_transfer"), 0)  # dry runs only: the test's time
    executive = Executive(scenario, approval="auto", truth="exact")
    worker = executive.planning
    assert worker is not None and worker.wait_ready(120.0)
    selector = executive.selectors[0]
    seen: dict[str, Any] = {}

    def killer(ex: Executive) -> None:
        planning = selector.phase == "planning" and len(ex.log.of_kind("planning")) == 1
        if "killed" not in seen and planning:
            seen.setdefault("planning_since", time.monotonic())
            if time.monotonic() - seen["planning_since"] > 0.3:  # well inside the plan (about 1 s)
                seen["pid"], seen["rollout_pids"] = worker.pid, _children(worker.pid or 0)
                os.kill(seen["pid"], signal.SIGKILL)
                assert _gone(seen["pid"], within_s=60.0)  # dead (a zombie) before the next tick
                seen["killed"] = ex.ticks
        if "killed" in seen and "noticed" not in seen and ex.log.of_kind("planning_worker"):
            seen["noticed"] = ex.ticks

    executive.tick_listeners.append(killer)
    held: list[np.ndarray] = []  # the robot's joints from the kill until the re-planned alternative starts
    while not executive.done:
        executive.tick()
        if "killed" in seen and not executive.log.of_kind("execute"):
            held.append(np.array(executive.robot.data.qpos[7:]))
    summary = executive.summary()
    lost = executive.log.of_kind("planning_worker")
    print(lost, f"noticed {seen['noticed'] - seen['killed']} tick(s) after the kill")
    assert len(lost) == 1 and lost[0]["pid"] == seen["pid"] and "SIGKILL" in lost[0]["reason"]
    assert lost[0]["replacement"] not in (None, seen["pid"]) and lost[0]["action"] == "replaced"
    assert seen["noticed"] - seen["killed"] >= 1  # in a tick after the death (4 ticks under load)
    sway = float(np.abs(np.array(held) - held[0]).max())
    print(f"{len(held)} ticks from the kill to the re-planned start; joints within {sway:.2e} rad")
    assert sway < 0.01  # the robot held
    kinds = [e["kind"] for e in executive.log.entries]
    after = kinds[kinds.index("planning_worker") :]
    assert after[:2] == ["planning_worker", "planning"] and "execute" in after  # re-planned, then ran
    assert kinds.count("planning") == 2 and kinds.count("execute") == 1
    assert summary["outcome"] == "success", summary
    assert executive.truth is not None
    pos, _ = executive.truth.object_pose("book")
    error = float(np.hypot(pos[0] - TARGET[0], pos[1] - TARGET[1]))
    print(f"book {error * 1000:.1f} mm from the target; old rollout processes {seen['rollout_pids']}")
    assert error < 0.02
    assert all(_gone(pid) for pid in seen["rollout_pids"])  # no orphan left behind


def test_a_worker_started_from_a_real_time_thread_runs_at_the_normal_policy() -> None:
    """A controller's SCHED_FIFO thread builds the executive's worker: the worker and its rollout
    process run at SCHED_OTHER (at the thread's priority they would take the cores from that very
    thread), and the thread keeps its policy."""
    scenario = load("book_transfer")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except PermissionError:
        pytest.skip("SCHED_FIFO needs root or CAP_SYS_NICE; run the suite as root (as .ci/run does)")
    try:
        worker = PlanningWorker(scenario, jobs=1, nice=3)  # a key no idle worker has: a fresh spawn
        kept = os.sched_getscheduler(0)
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    try:
        assert worker.wait_ready(120.0) and worker.pid is not None
        deadline = time.monotonic() + 60.0
        while not _children(worker.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        pids = [worker.pid, *_children(worker.pid)]
        policies = {pid: os.sched_getscheduler(pid) for pid in pids}
    finally:
        worker.close(wait=True)
    print(f"the thread's policy while it spawned: {kept}; worker and rollout processes: {policies}")
    assert kept == os.SCHED_FIFO
    assert len(pids) == 2 and set(policies.values()) == {os.SCHED_OTHER}
