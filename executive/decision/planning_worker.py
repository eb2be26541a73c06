"""The planning worker: one warm process that does the selectors' heavy work, off the ticking process.

Planning in a thread of the process that ticks would hold the interpreter lock the ticks need. A
:class:`PlanningWorker` runs :mod:`executive.decision.planning_job` in a spawned process of its
own, with its own estimate world, live risk monitor and warm rollout processes, at a lower
priority (:data:`NICE`). A selector :meth:`~PlanningWorker.submit` s a job (plain data) and
:meth:`~PlanningWorker.poll` s on later ticks; a receiving thread unpickles the result, so a poll
only takes it.

A poll raises :class:`WorkerLost` when the worker died (its exit code), hangs (no heartbeat
for :data:`HANG_S` while it uses no CPU, or it is stopped), or a job has run past its deadline
(:data:`JOB_S` plus the scenario's rollout budget: an endless loop keeps beating);
:meth:`~PlanningWorker.replace` starts a fresh one. A healthy idle worker that is closed is kept
warm (at most :data:`KEEP_IDLE`) for this process's next :class:`PlanningWorker`, which gives it
its scenario. docs/workers.md has the design and the measurements.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import multiprocessing.process
import multiprocessing.util
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from executive.decision.priority import normal_policy_children
from executive.errors import ExecutiveError

if TYPE_CHECKING:
    from executive.decision.planning_job import PlanningJob, PlanningResult, RestanceJob
    from executive.planning.restance import RestanceResult
    from executive.schema.types import Scenario

__all__ = [
    "BEAT_S",
    "END_S",
    "HANG_S",
    "JOB_S",
    "KEEP_IDLE",
    "NICE",
    "START_S",
    "PlanningWorker",
    "WorkerLost",
]

#: The worker's heartbeat period (s).
BEAT_S = 0.1
#: A heartbeat older than this (s) is a hung worker: noticed within a second of the hang.
HANG_S = 0.75
#: How long (s) a starting worker may take to its first heartbeat (the interpreter's imports).
START_S = 120.0
#: How long (s) a job may plan and dry-run before it is taken for stuck; its rollout budget
#: (``risk.rollouts.budget_s``) is added.
JOB_S = 300.0
#: The worker's niceness (added to the ticking process's): the ticks get the cores first.
NICE = 10
#: How often (s) a busy worker's CPU time is read while its heartbeat is fresh.
_SAMPLE_S = 0.2
#: Idle workers a process keeps warm for its next executives (0: close them).
KEEP_IDLE = 2
#: How long (s) a worker told to end at once (SIGTERM) has to do so before it is killed.
END_S = 10.0


class WorkerLost(ExecutiveError):
    """The planning worker died or hangs; ``reason`` says which, ``pid`` was its process."""

    def __init__(self, reason: str, pid: int | None) -> None:
        self.reason = reason
        self.pid = pid
        super().__init__(f"the planning worker (pid {pid}) {reason}")


def _beat(beat: Any, parent: int, stop: threading.Event) -> None:
    """The worker's heartbeat thread: the time now, every BEAT_S; the worker ends with its parent."""
    while True:
        if os.getppid() != parent:  # the ticking process is gone: nobody will ask for work
            os._exit(0)
        beat.value = time.monotonic()
        if stop.wait(BEAT_S):
            return


def _end_now(signum: int, frame: object) -> None:
    """The worker's SIGTERM (and SIGHUP): kill its rollout processes, then leave by the normal
    exit (``SystemExit``), which closes the pool and releases its semaphores; a kill would leave
    them to the resource tracker, which warns of them as leaked."""
    try:
        children = multiprocessing.active_children()
    except RuntimeError:  # the list changed under this handler: the pool then waits for their jobs
        children = []
    for child in children:
        child.kill()
    raise SystemExit(0)


def _serve(
    conn: multiprocessing.connection.Connection,
    beat: Any,
    scenario: Scenario,
    jobs: int,
    nice: int,
    parent: int,
) -> None:
    """The worker process: heartbeat first, then build everything once, then serve jobs until told to stop."""
    stop = threading.Event()
    threading.Thread(target=_beat, args=(beat, parent, stop), name="heartbeat", daemon=True).start()
    # Ctrl-C reaches the whole foreground process group: the ticking process stops the worker.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # SIGTERM: the ticking process ends a busy worker (_Instance.end); SIGHUP, a hung-up terminal's
    # group, too, unless ignored (nohup).
    signal.signal(signal.SIGTERM, _end_now)
    if signal.getsignal(signal.SIGHUP) is signal.SIG_DFL:
        signal.signal(signal.SIGHUP, _end_now)
    os.environ.setdefault("MUJOCO_GL", "egl")
    if nice:
        os.nice(nice)
    from executive.decision.planning_job import Planning

    planning = Planning.of_scenario(scenario, jobs)
    conn.send(("ready", 0, os.getpid()))
    try:
        while True:
            try:
                message = conn.recv()
            except EOFError:
                break
            if message is None:
                break
            kind, ticket, payload = message
            if kind == "scenario":  # taken by another executive: its world, the same rollout processes
                planning = Planning.of_scenario(payload, jobs, physics=planning.physics)
                conn.send(("ready", ticket, os.getpid()))
            else:
                conn.send(("result", ticket, planning.serve(payload)))
    finally:
        stop.set()
        planning.close()


@dataclass
class _Instance:
    """One worker process and what the ticking process keeps of it."""

    process: multiprocessing.process.BaseProcess
    conn: multiprocessing.connection.Connection
    beat: Any  # shared double: the worker's last heartbeat (time.monotonic), 0 before the first
    started: float
    key: tuple[int, int]  # (rollout jobs, niceness): what a worker taken from the idle ones must have
    inbox: dict[int, PlanningResult | RestanceResult] = field(default_factory=dict)
    pending: set[int] = field(default_factory=set)  # tickets sent and neither answered nor forgotten
    unanswered: dict[int, float] = field(default_factory=dict)  # ticket -> when sent; forgotten too
    generation: int = 0  # scenarios it was given after its first: its "ready" for the last one counts
    ready: bool = False
    cpu: int = -1  # the process's CPU time (clock ticks) when last read
    sampled: float = 0.0  # when it was last read (time.monotonic)
    computed: float = 0.0  # when it was first seen to have used CPU time since the read before

    def receive(self) -> None:
        """The receiving thread: results into the inbox until the worker's end of the pipe closes."""
        while True:
            try:
                kind, ticket, payload = self.conn.recv()
            except (EOFError, OSError):
                self.conn.close()
                break
            if kind == "ready":
                self.ready = ticket == self.generation
                continue
            self.unanswered.pop(ticket, None)
            if ticket in self.pending:  # not forgotten meanwhile
                self.inbox[ticket] = payload.native()
                self.pending.discard(ticket)

    def send_job(self, ticket: int, job: PlanningJob | RestanceJob) -> None:
        """Send ``job`` under ``ticket`` (raises OSError if the worker's end is closed)."""
        self.pending.add(ticket)
        self.unanswered[ticket] = time.monotonic()
        try:
            self.conn.send(("job", ticket, job))
        except (BrokenPipeError, OSError):
            self.pending.discard(ticket)
            self.unanswered.pop(ticket, None)
            raise

    def rebuild(self, scenario: Scenario) -> None:
        """Have the idle worker build ``scenario``'s world (it answers "ready" when it has)."""
        self.generation += 1
        self.ready = False
        self.inbox.clear()
        self.pending.clear()
        self.conn.send(("scenario", self.generation, scenario))

    def stop(self) -> None:
        """Tell the worker to stop (it ends its rollout processes); end it at once if it is busy
        or starting."""
        if self.unanswered or not self.ready:  # busy (or still building): nothing to wait for
            self.end()
            return
        try:
            self.conn.send(None)
        except (BrokenPipeError, OSError):
            self.end()

    def end(self, grace_s: float = END_S) -> None:
        """End the worker now: SIGTERM (it kills its rollout processes and exits, releasing what
        it holds), then SIGKILL if it is still there after ``grace_s``. Returns at once."""
        self.process.terminate()
        killer = threading.Timer(grace_s, self._kill_if_running)
        killer.daemon = True
        killer.start()

    def _kill_if_running(self) -> None:
        if self.process.exitcode is None:
            self.process.kill()

    def fault(self, now: float, hang_s: float, job_s: float) -> str | None:
        """Why this worker can no longer answer (None: it can)."""
        code = self.process.exitcode
        if code is not None:
            if code < 0:
                return f"died (killed by {signal.Signals(-code).name})"
            return f"exited with code {code}"
        running = now - min(self.unanswered.values()) if self.unanswered else 0.0
        if running > job_s:
            return f"hangs: a job has run for {running:.1f} s (limit {job_s:g} s)"
        beat = self.beat.value
        if beat == 0.0:
            if now - self.started > START_S:
                return f"did not start: no heartbeat {now - self.started:.0f} s after it was spawned"
            return None
        stale = now - beat > hang_s
        if stale or now - self.sampled > _SAMPLE_S:
            cpu = _cpu_time(self.process.pid)
            self.sampled = now
            if cpu != self.cpu:  # it computes
                self.cpu, self.computed = cpu, now
        if not stale:
            return None
        states = _thread_states(self.process.pid)
        if states & {"T", "t"}:
            return f"hangs: stopped (no heartbeat for {now - beat:.2f} s)"
        if "R" in states:  # a thread waits for a core (the lock's holder, preempted)
            self.computed = now
        if now - max(beat, self.computed) > hang_s:
            return f"hangs: no heartbeat and no CPU time for {now - beat:.2f} s (limit {hang_s:g} s)"
        return None


def _cpu_time(pid: int | None) -> int:
    """Process ``pid``'s CPU time (user + system, clock ticks; fields 14 and 15 of Linux's
    ``/proc/<pid>/stat``, proc(5)); -1 where it cannot be read."""
    try:
        fields = _stat(f"/proc/{pid}/stat")
        return int(fields[11]) + int(fields[12])
    except (OSError, IndexError, ValueError):
        return -1


def _thread_states(pid: int | None) -> set[str]:
    """The state letters of process ``pid``'s threads (``/proc/<pid>/task/*/stat``); empty
    where they cannot be read."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
        return {_stat(f"/proc/{pid}/task/{task}/stat")[0].decode() for task in tasks}
    except (OSError, IndexError):
        return set()


def _stat(path: str) -> list[bytes]:
    """The fields of a ``stat`` file after the command name (field 3, the state, first)."""
    with open(path, "rb") as f:
        return f.read().rsplit(b")", 1)[1].split()


class _Idle:
    """The healthy idle workers this process keeps warm for its next executives."""

    def __init__(self) -> None:
        self.workers: list[_Instance] = []
        self.lock = threading.Lock()
        self.exiting = False

    def park(self, instance: _Instance) -> bool:
        """Keep ``instance`` for later if it is alive and has no job (False: the caller stops it)."""
        if self.exiting or KEEP_IDLE < 1 or instance.unanswered or instance.process.exitcode is not None:
            return False
        with self.lock:
            self.workers.append(instance)
            surplus = self.workers[:-KEEP_IDLE]
            del self.workers[:-KEEP_IDLE]
        for old in surplus:
            old.stop()
        return True

    def take(self, key: tuple[int, int], scenario: Scenario) -> _Instance | None:
        """An idle worker with ``key``, now building ``scenario`` (None: there is none)."""
        with self.lock:
            found = [w for w in self.workers if w.key == key and w.process.exitcode is None]
            if not found:
                return None
            self.workers.remove(found[-1])
        try:
            found[-1].rebuild(scenario)
        except (BrokenPipeError, OSError):  # it died just now: start a fresh one instead
            found[-1].process.kill()
            return None
        return found[-1]

    def forget(self) -> None:
        """Drop the list without stopping anything: in a forked child, whose parent owns them."""
        self.workers, self.lock = [], threading.Lock()

    def close(self) -> None:
        """Stop every idle worker; none is kept from now on (the interpreter is exiting)."""
        self.exiting = True
        with self.lock:
            workers, self.workers = self.workers, []
        for instance in workers:
            instance.stop()


_IDLE = _Idle()
os.register_at_fork(after_in_child=_IDLE.forget)  # a forked child must not take its parent's workers
# At the interpreter's exit, before the workers' own finalizers (priority 10) and the join of its children.
multiprocessing.util.Finalize(None, _IDLE.close, exitpriority=11)


class _Processes:
    """The worker process serving now and those replaced; kept apart from :class:`PlanningWorker`
    so that the interpreter's exit can close them without keeping the worker object alive."""

    def __init__(self, now: _Instance) -> None:
        self.now = now
        self.retired: list[multiprocessing.process.BaseProcess] = []
        self.closed = False

    def close(self, wait: bool = False) -> None:
        """Keep the worker warm for this process's next executive if it is idle (:class:`_Idle`),
        else tell it to stop (it ends its rollout processes; killed if busy or still starting).
        ``wait``: stop it in any case and wait for it (killed if it has not stopped in 10 s).

        Without ``wait`` a stopped worker ends on its own; the interpreter waits for it at exit.
        """
        now = self.now
        if not self.closed:
            self.closed = True
            if wait or not _IDLE.park(now):
                now.stop()
        if wait:
            now.process.join(timeout=10.0)
            if now.process.exitcode is None:
                now.process.kill()
                now.process.join(timeout=5.0)
            for process in self.retired:
                process.join(timeout=5.0)


class PlanningWorker:
    """A warm process that does the selectors' planning, assessment and physics checks.

    Args:
        scenario: the scenario whose estimate the worker builds.
        jobs: the physics check's rollout processes (``risk.rollouts.jobs``), started by the
            worker (0: the worker runs no physics check).
        nice: the worker's niceness increment (0: none; None: :data:`NICE`).
        hang_s: a heartbeat older than this (s) is a hang.
        job_s: a job running longer than this (s) is a hang (None: :data:`JOB_S` plus the
            scenario's rollout budget).

    The process is spawned at once (or an idle one of this process is taken) and builds its world
    while the caller goes on. Use
    :meth:`submit` and :meth:`poll` per job, :meth:`replace` after :class:`WorkerLost`,
    :meth:`close` at the end (also done when the interpreter exits, or this object is collected).
    """

    def __init__(
        self,
        scenario: Scenario,
        jobs: int,
        *,
        nice: int | None = None,
        hang_s: float = HANG_S,
        job_s: float | None = None,
    ) -> None:
        self.scenario = scenario
        self.jobs = jobs
        self.nice = NICE if nice is None else nice
        self.hang_s = hang_s
        self.job_s = JOB_S + scenario.risk.rollouts.budget_s if job_s is None else job_s
        self.replaced = 0  # workers replaced so far
        self._ctx = multiprocessing.get_context("spawn")
        self._next_ticket = 0
        warm = _IDLE.take((jobs, self.nice), scenario)
        self._processes = _Processes(warm if warm is not None else self._start())
        # Before the interpreter joins its children at exit: a worker left running would be waited for.
        multiprocessing.util.Finalize(self, self._processes.close, exitpriority=10)

    def _start(self) -> _Instance:
        conn, child = self._ctx.Pipe()
        beat = self._ctx.RawValue("d", 0.0)
        args = (child, beat, self.scenario, self.jobs, self.nice, os.getpid())
        process = self._ctx.Process(target=_serve, args=args, name="planning-worker")
        with normal_policy_children():  # not at the priority of a host's real-time thread
            process.start()
        child.close()
        instance = _Instance(process, conn, beat, time.monotonic(), (self.jobs, self.nice))
        threading.Thread(target=instance.receive, name="planning-results", daemon=True).start()
        return instance

    @property
    def _now(self) -> _Instance:
        return self._processes.now

    @property
    def pid(self) -> int | None:
        """The worker process's id."""
        return self._now.process.pid

    @property
    def ready(self) -> bool:
        """Whether the worker has built its world and serves jobs."""
        return self._now.ready

    def wait_ready(self, timeout_s: float = START_S) -> bool:
        """Block until the worker serves jobs (False: it did not within ``timeout_s``, or it died)."""
        deadline = time.monotonic() + timeout_s
        while not self._now.ready and time.monotonic() < deadline:
            if self._now.process.exitcode is not None:
                return False
            time.sleep(0.01)
        return self._now.ready

    def submit(self, job: PlanningJob | RestanceJob) -> int:
        """Send ``job`` to the worker (queued while it starts); the ticket to :meth:`poll` with.

        A :class:`PlanningJob` is answered with a :class:`PlanningResult`, a :class:`RestanceJob`
        (the rest of a running alternative re-planned after a walk) with a :class:`RestanceResult`.

        Raises:
            WorkerLost: the worker is already gone (its end of the pipe is closed).
            ExecutiveError: the worker was closed.
        """
        if self._processes.closed:
            raise ExecutiveError("the planning worker is closed")
        self._next_ticket += 1
        ticket = self._next_ticket
        now = self._now
        try:
            now.send_job(ticket, job)
        except (BrokenPipeError, OSError) as exc:
            reason = now.fault(time.monotonic(), self.hang_s, self.job_s) or f"cannot be reached ({exc})"
            raise WorkerLost(reason, self.pid) from exc
        return ticket

    def poll(self, ticket: int) -> PlanningResult | RestanceResult | None:
        """The result of ``ticket`` if it has come (taken out), else None. Never blocks.

        Raises:
            WorkerLost: the worker died or hangs (:meth:`replace` it and submit again).
        """
        result = self._now.inbox.pop(ticket, None)
        if result is not None:
            return result
        reason = self._now.fault(time.monotonic(), self.hang_s, self.job_s)
        if reason is not None:
            raise WorkerLost(reason, self.pid)
        return None

    def forget(self, ticket: int) -> None:
        """Drop ``ticket``: its result, if it still comes, is thrown away (a halted selector's)."""
        self._now.pending.discard(ticket)
        self._now.inbox.pop(ticket, None)

    def replace(self) -> int | None:
        """Kill the worker (if it still runs) and start a fresh one; its pid.

        Tickets not answered are dropped: submit their jobs again.
        """
        old = self._now.process
        if old.exitcode is None:
            old.kill()
        self._processes.retired.append(old)
        self._processes.now = self._start()
        self.replaced += 1
        return self.pid

    def close(self, wait: bool = False) -> None:
        """Stop the worker (it ends its rollout processes; killed if busy); ``wait``: wait for it.

        Without ``wait`` this returns at once (the tick that ends a mission calls it); the
        interpreter waits for the worker at exit.
        """
        self._processes.close(wait)
