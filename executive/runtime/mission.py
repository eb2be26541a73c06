"""The executive as an object a host embeds: ``Executive(scenario, approval=...)``, then ``tick()``.

The tree is a Sequence of one :class:`executive.decision.selector.RiskSelector` per task of the
mission. Each ``tick()`` ticks the tree once and never blocks (planning runs in a
worker process, :mod:`executive.decision.planning_worker`; approvals are answered
asynchronously); when the executive owns the
physics (the default: a truth world sampled from the scenario's uncertainty, or
equal to the estimate with ``truth="exact"``) it then steps the simulation one
control period. A host that drives its own robot passes ``robot=`` (an object with
the :class:`executive.execution.robot_interface.RobotInterface` methods) and steps it itself;
the MuJoCo estimate is then used for prediction only.

Inspect ``status`` (py_trees status of the mission), ``pending_approval`` (the request
waiting for an answer, if any), ``log`` (the :class:`executive.decision.audit.AuditLog`) and
``summary()``. ``stop()`` halts the tree, holds the robot and closes the log.

A host that ticks in real time should call :func:`freeze_startup_heap` once it has built
the executive (``executive run`` does): CPython's full garbage collection otherwise
stops every thread now and then, in the middle of a motion (measured: ``docs/workers.md``).
"""

from __future__ import annotations

import contextlib
import gc
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import py_trees

from behaviours.guard import install_monitor
from behaviours.robot_access import install
from executive.decision.approval import ApprovalChannel, ApprovalDecision, PendingApproval, make_channel
from executive.decision.audit import AuditLog, now_iso, write_summary
from executive.decision.physics_check import PhysicsCheck
from executive.decision.planning_worker import PlanningWorker
from executive.decision.selector import RiskSelector, task_label
from executive.execution.simulated import SimulatedRobot
from executive.execution.tick_record import TickRecorder
from executive.monitoring.detectors import FailureDetector
from executive.monitoring.live_risk import LiveRiskMonitor
from executive.schema.types import Scenario, Task
from executive.world.model import World, build, sample_perturbation
from executive.world.observation import SimulatedSensor, refresh

__all__ = ["Executive", "freeze_startup_heap"]

Status = py_trees.common.Status


def freeze_startup_heap() -> int:
    """Take everything alive now out of the cyclic garbage collector's reach; once per process.

    A full (generation 2) collection walks every tracked object and stops every thread while
    it does. After ``gc.collect(); gc.freeze()`` the libraries, the worlds and the tree are in
    the permanent generation and later full collections walk only what was made since (Python
    docs, ``gc.freeze``). Frozen objects are never collected as cycles, so this is done once
    per process (later calls do nothing) and meant for a process that builds its executive
    once. Measurements: ``docs/workers.md``.

    Returns:
        The number of objects frozen.
    """
    if gc.get_freeze_count() == 0:
        gc.collect()
        gc.freeze()
    return gc.get_freeze_count()


#: Signals a host may turn into ``KeyboardInterrupt`` (``executive run`` turns SIGTERM and SIGHUP
#: into it, :mod:`executive.cli.signals`): held off while a stop is written.
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextlib.contextmanager
def _stop_signals_deferred() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT), and SIGTERM and SIGHUP where a handler of the host's catches them,
    off while the run's last records are written.

    A second Ctrl-C (or SIGTERM) during :meth:`Executive.stop` would otherwise cut the ``end``
    line or ``summary.json``; it is noted on stderr and otherwise ignored (the run is ending
    anyway). A signal left at its default action (it ends the process) or ignored is left so.
    Only the main thread can set signal handlers; elsewhere this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def note(signum: int, frame: object) -> None:
        again = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        sys.stderr.write(
            f"\n({again} again: the run is already stopping; its log and summary are being written)\n"
        )

    previous: dict[signal.Signals, Any] = {}
    try:
        for signum in _STOP_SIGNALS:
            handler = signal.getsignal(signum)
            if handler is not None and (signum == signal.SIGINT or callable(handler)):
                previous[signum] = signal.signal(signum, note)
    except ValueError:  # no signals here (an embedded interpreter)
        pass
    try:
        yield
    finally:
        for held, handler in previous.items():
            signal.signal(held, handler)


def _load(scenario: Scenario | str | Path) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    from executive.scenario import load

    return load(str(scenario))


class Executive:
    """Plan, gate and run a scenario's mission, one non-blocking tick at a time.

    Args:
        scenario: a :class:`Scenario`, a scenario file, or a bundled scenario's name.
        approval: an approval channel, or a mode ``prompt|auto|deny`` (default: the
            scenario's ``approval.mode``; ``prompt`` only on a terminal, else ``deny``).
        robot: the host's robot (see :mod:`executive.execution.robot_interface`); None: the executive
            simulates the truth world itself and steps it in :meth:`tick`.
        truth: ``"exact"`` (truth = estimate) or a seed for the sampled truth (default
            ``trials.seed``); only without ``robot``. The seed (``trials.seed`` for ``"exact"``)
            also seeds the noise of what the simulated robot sees
            (:class:`executive.world.observation.SimulatedSensor`).
        out: run folder for ``decisions.jsonl``/``summary.json``/plots; None keeps the log in
            memory only. A folder another run has used is refused
            (:class:`executive.decision.audit.RunFolderError`) unless ``resume``.
        control_dt: control period (s) of a tick.
        guard: live risk guards around every motion.
        background: plan in a warm worker process (False: inside the tick, blocking).
        pace_waiting: while the robot only holds (planning, awaiting approval), step the
            bundled physics in real time instead of as fast as possible.
    """

    def __init__(
        self,
        scenario: Scenario | str | Path,
        *,
        approval: ApprovalChannel | str | None = None,
        robot: Any = None,
        truth: str | int | None = None,
        out: Path | str | None = None,
        control_dt: float = 0.02,
        guard: bool = True,
        background: bool = True,
        pace_waiting: bool = True,
        resume: bool = False,
    ) -> None:
        self.scenario = _load(scenario)
        self.folder = Path(out) if out is not None else None
        # Claim the run folder first: a second run on it is refused before anything is built.
        self.log = AuditLog(self.folder, resume=resume)
        try:
            self._build(approval, robot, truth, control_dt, guard, background, pace_waiting)
            if self.folder is not None:  # the run folder's per-tick record (its module's docstring)
                self.tick_listeners.append(TickRecorder(self.folder, self, truth=truth))
        except BaseException:
            self.log.abandon()  # nothing was decided: the folder is free again
            raise

    def _build(
        self,
        approval: ApprovalChannel | str | None,
        robot: Any,
        truth: str | int | None,
        control_dt: float,
        guard: bool,
        background: bool,
        pace_waiting: bool,
    ) -> None:
        sc = self.scenario
        if isinstance(approval, str) or approval is None:
            mode = approval or sc.approval.mode
            fallback = sc.approval.mode if sc.approval.mode != "prompt" else "deny"
            approval = make_channel(mode, fallback=fallback)
        self.channel: ApprovalChannel = approval
        self.estimate: World = build(sc)
        self.truth: World | None = None
        if robot is None:
            seed = sc.trials.seed if truth in (None, "exact") else int(truth)
            if truth == "exact":
                self.truth, self.truth_label = build(sc), "exact (truth = estimate)"
            else:
                rng = np.random.default_rng(seed)
                self.truth = build(sc, sample_perturbation(sc, rng), kind="truth")
                self.truth_label = f"sampled from the scenario's uncertainty, seed {seed}"
            # The robot sees the objects with the scenario's uncertainty, seeded by the run's seed.
            sensor = SimulatedSensor(self.truth, seed)
            detector = FailureDetector(self.truth)
            robot = SimulatedRobot(self.truth, control_dt=control_dt, detector=detector, sensor=sensor)
            self.owns_physics = True
        else:
            self.truth_label = "the host's robot"
            self.owns_physics = False
        self.robot = robot
        # Every decision is checked in physics (dry runs, rollouts) in warm worker processes:
        # the planning worker's own (it plans, assesses and checks), or these when planning in the tick.
        self.physics = PhysicsCheck(sc.risk.rollouts.jobs)
        self.planning = PlanningWorker(sc, sc.risk.rollouts.jobs) if background else None
        if self.planning is None:
            self.physics.pool.warm()  # the workers start while the world and the tree are built
        self.selectors = [self._selector(i, task, guard, background) for i, task in enumerate(sc.mission)]
        self.root = py_trees.composites.Sequence(name=sc.name, memory=True, children=list(self.selectors))
        self.tree = py_trees.trees.BehaviourTree(self.root)
        self.monitor = LiveRiskMonitor(self.estimate, sc.risk.guard) if guard else None
        if self.monitor is not None:  # every pair's distance functor now, not in the ticks of a swap
            self.monitor.collision.warm()
        self.pace_waiting = pace_waiting
        self.ticks = 0
        self.max_tick_s = 0.0  # longest tree tick (physics excluded), s
        self.tick_s = 0.0  # all tree ticks (physics excluded), s
        self.started_wall = time.perf_counter()
        self.wall_s = 0.0
        self.outcome: str | None = None  # success | failed | aborted
        self._summary: dict[str, Any] | None = None
        #: Called with the executive after every tick (and its physics step): recorders, consoles.
        self.tick_listeners: list[Callable[[Executive], None]] = []
        self._install()
        self.tree.setup()
        self.log.record(
            "run",
            scenario=sc.name,
            source=str(sc.source),
            robot=sc.robot.name,
            truth=self.truth_label,
            approval=self.channel.name,
            ordering=sc.risk.ordering,
            threshold=sc.risk.threshold,
            tasks=[task_label(t) for t in sc.mission],
            folder=str(self.folder) if self.folder else None,
        )
        if not self.owns_physics:  # a host's robot: the estimate starts from what it sees
            self.log.record("observation", task=None, **refresh(self.estimate, robot, {}, "at_start"))

    def _selector(self, i: int, task: Task, guard: bool, background: bool) -> RiskSelector:
        """The selector of the mission's task ``i``."""
        return RiskSelector(
            f"task{i}",
            task,
            estimate=self.estimate,
            channel=self.channel,
            log=self.log,
            timeout_s=self.scenario.approval.timeout_s,
            guard=guard,
            physics=self.physics,
            background=background,
            worker=self.planning,
        )

    def _install(self) -> None:
        install(self.robot)
        install_monitor(self.monitor)

    # --- state ----------------------------------------------------------------------------

    @property
    def status(self) -> Status:
        return self.root.status

    @property
    def done(self) -> bool:
        return self.outcome is not None

    @property
    def pending_approval(self) -> PendingApproval | None:
        for selector in self.selectors:
            pending = selector.pending
            if selector.phase == "awaiting_approval" and pending is not None and pending.decision is None:
                return pending
        return None

    @property
    def current_task(self) -> RiskSelector | None:
        return next((s for s in self.selectors if s.status == Status.RUNNING), None)

    def describe(self) -> str:
        """One line: what the executive is doing now."""
        task = self.current_task
        if task is None:
            return self.outcome or "idle"
        return f"{task.name} [{task.phase}] {task.feedback_message}"

    # --- running --------------------------------------------------------------------------

    def tick(self) -> Status:
        """Tick the tree once (never blocks); step the bundled physics one control period."""
        if self.done:
            return self.status
        t0 = time.perf_counter()
        self._tick_tree()
        tick_s = time.perf_counter() - t0
        self.max_tick_s = max(self.max_tick_s, tick_s)
        self.tick_s += tick_s
        self.ticks += 1
        if self.owns_physics and self.status == Status.RUNNING:
            self.robot.advance()
            if self.pace_waiting and self._waiting():
                # While the robot only holds (planning in the worker thread, or an operator to
                # answer), simulated time follows the wall clock, as a real robot's would,
                # and the planner gets the processor instead of a physics loop racing ahead.
                spare = self.robot.control_dt - (time.perf_counter() - t0)
                if spare > 0:
                    time.sleep(spare)
        for listener in self.tick_listeners:
            listener(self)
        if self.status != Status.RUNNING:
            self._finish("success" if self.status == Status.SUCCESS else self._failed_outcome())
        return self.status

    def _tick_tree(self) -> None:
        """``BehaviourTree.tick()``, without its walk over every node when nobody looks.

        py_trees' tick runs the tree, then iterates over *all* nodes (every alternative's
        subtree) to offer them to the "full" visitors, building a list per node even when
        there are none. With no visitors and no tick handlers that walk does nothing; it is
        skipped, and the tree is ticked exactly as ``BehaviourTree.tick`` ticks it.
        """
        tree = self.tree
        if tree.visitors or tree.pre_tick_handlers or tree.post_tick_handlers:
            tree.tick()
            return
        for _ in tree.root.tick():
            pass
        tree.count += 1

    def _waiting(self) -> bool:
        task = self.current_task
        return task is not None and task.phase in ("planning", "awaiting_approval")

    def _failed_outcome(self) -> str:
        return "aborted" if any(s.outcome == "aborted" for s in self.selectors) else "failed"

    def run(
        self, *, time_limit_s: float | None = None, on_tick: Callable[[Executive], None] | None = None
    ) -> dict[str, Any]:
        """Tick until the mission ends (or ``time_limit_s`` of robot time); return the summary."""
        while not self.done:
            self.tick()
            if on_tick is not None:
                on_tick(self)
            if time_limit_s is not None and self.robot.time > time_limit_s and not self.done:
                self.stop(f"time limit {time_limit_s:.0f} s reached")
        return self.summary()

    def stop(self, reason: str, *, by: str | None = None) -> None:
        """Halt the tree, hold the robot, answer nothing more, close the log (outcome aborted).

        Safe to call from the main thread at any moment, a ``KeyboardInterrupt`` handler
        included (what a host does on Ctrl-C or SIGTERM: docs/embedding.md); a second call
        does nothing. The planning worker and its rollout processes are ended.

        Args:
            reason: why, in words (the ``stop`` line and ``summary.json``'s ``reason``).
            by: who answers ``abort`` to a request still waiting for approval (logged before
                the ``stop`` line). Default: ``operator:interrupt`` when called while a
                ``KeyboardInterrupt`` is being handled (Ctrl-C), else ``halt``.

        A second Ctrl-C (or a SIGTERM or SIGHUP the host turns into one) meanwhile is held off
        until the summary and the ``end`` line are written.
        """
        if self.done:
            return
        if by is None:
            by = "operator:interrupt" if isinstance(sys.exc_info()[1], KeyboardInterrupt) else "halt"
        with _stop_signals_deferred():
            self._answer_pending(by, reason)
            self.tree.interrupt()
            self.robot.hold()
            self.log.record("stop", reason=reason, time=self.robot.time)
            self._finish("aborted", reason=reason)

    def _answer_pending(self, by: str, reason: str) -> None:
        """Log the answer of every request awaiting approval (abort now, or one given not yet acted on)."""
        for selector in self.selectors:
            pending = selector.pending
            if selector.phase != "awaiting_approval" or pending is None:
                continue
            pending.answer(ApprovalDecision("abort", None, by=by, at=now_iso(), note=reason))
            decision = pending.decision
            if decision is not None and selector.approval is not decision:
                selector.approval = decision
                self.log.record("approval", task=selector.name, **decision.as_dict())

    def close(self) -> None:
        for selector in self.selectors:
            selector.shutdown()
        self.physics.close()
        if self.planning is not None:
            self.planning.close()
        self.tree.shutdown()
        self.log.close()

    # --- report ---------------------------------------------------------------------------

    def _finish(self, outcome: str, reason: str = "") -> None:
        """Write ``summary.json`` (atomically), then the ``end`` line, then the plots; close.

        The summary comes first, so a run killed just after its ``end`` line has it whole.
        """
        with _stop_signals_deferred():
            self.outcome = outcome
            self.wall_s = time.perf_counter() - self.started_wall
            summary = self.summary()
            if reason:
                summary["reason"] = reason
            self._summary = summary
            if self.folder is not None:
                write_summary(self.folder, summary)
            self.log.record(
                "end", outcome=outcome, time=self.robot.time, ticks=self.ticks, wall_s=self.wall_s
            )
            try:
                if self.folder is not None:
                    self._plots()
            finally:
                self.close()

    def _plots(self) -> None:
        """The pictures of ``executive plan --plot``, for the alternatives each task last ranked."""
        from executive.report.plots import plot_alternatives
        from executive.risk.fall import support_polygon

        assert self.folder is not None
        world = self.estimate
        mujoco.mj_forward(world.model, world.data)
        try:
            polygon = support_polygon(world, world.data, from_contacts=False)
        except ValueError:
            return
        for i, selector in enumerate(self.selectors):
            if selector.ranking:
                plot_alternatives(self.scenario, selector.ranking, polygon, self.folder / f"task{i}")

    def summary(self) -> dict[str, Any]:
        if self._summary is not None:
            return self._summary
        tasks = []
        for selector in self.selectors:
            tasks.append(
                {
                    "task": task_label(selector.task),
                    "chosen": selector.chosen,
                    "risk": selector.chosen_risk["risk"] if selector.chosen_risk else None,
                    "value": selector.chosen_risk["value"] if selector.chosen_risk else None,
                    "approval": selector.approval.as_dict() if selector.approval else None,
                    "outcome": selector.outcome,
                    "failure": selector.failure,
                    "tried": list(selector.tried),
                }
            )
        placement = self._placement()
        return {
            "scenario": self.scenario.name,
            "run_id": self.log.run_id,
            "outcome": self.outcome,
            "truth": self.truth_label,
            "approval_channel": self.channel.name,
            "ordering": self.scenario.risk.ordering,
            "threshold": self.scenario.risk.threshold,
            "tasks": tasks,
            "placement": placement,
            "sim_time_s": self.robot.time,
            "wall_s": self.wall_s or time.perf_counter() - self.started_wall,
            "ticks": self.ticks,
            "max_tick_s": self.max_tick_s,
            "folder": str(self.folder) if self.folder else None,
        }

    def _placement(self) -> list[dict[str, Any]]:
        """Where each task's object is now (in the truth world, when the executive owns it).

        ``executed`` is False for a task that never started an alternative (planning failed,
        the approval was refused): its object was not moved and its ``error_m`` is None.
        """
        if self.truth is None:
            return []
        out = []
        for task, selector in zip(self.scenario.mission, self.selectors, strict=True):
            to = getattr(task, "to", None)
            if not task.object or to is None:
                continue
            pos, _ = self.truth.object_pose(task.object)
            executed = bool(selector.tried)
            err = float(np.hypot(pos[0] - to[0], pos[1] - to[1])) if executed else None
            out.append({"object": task.object, "position": pos, "executed": executed, "error_m": err})
        return out

    def __enter__(self) -> Executive:
        return self

    def __exit__(self, *exc: object) -> None:
        if not self.done:
            self.stop("the host left the executive's context")
        self.close()
