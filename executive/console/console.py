"""The operator's console: one local web page per process showing the scene, the decisions and the tree.

Three ways to fill it:

* :meth:`Console.attach` an :class:`executive.runtime.mission.Executive` (``executive run
  --console``): the scene follows the robot live, each task's decision appears as soon as it
  is made (risk table, planned motions as a ghost with a time slider), an approval request
  submitted to :attr:`Console.channel` waits on the page with its buttons, the behaviour tree
  shows each node's status;
* :meth:`Console.preview` a scenario (``executive console SCENARIO``): every task's
  alternatives planned and checked in physics as ``executive plan`` does, nothing executed;
* :meth:`Console.show_run` a run folder (``executive console RUN_DIR``): its decisions as
  they were logged.

The executive is never waited for: a :class:`executive.console.live.LiveFeed` tick listener
drops a snapshot at most ``rate_hz`` times a second, and the console's own thread draws it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import py_trees

from executive.console import PORT
from executive.console.approval_panel import ApprovalPanel
from executive.console.channel import ConsoleChannel
from executive.console.ghost import GhostView, PlannedMotion
from executive.console.live import LiveFeed
from executive.console.replay_view import ReplayView
from executive.console.run_log import read_decisions, task_decisions, timeline
from executive.console.scene import WorldView, light
from executive.console.server import HOST, start_server, stop_server
from executive.console.task_view import TaskView
from executive.decision.assessment import AlternativeRisk
from executive.decision.selector import risk_row, task_label
from executive.schema.types import Scenario
from executive.world.model import World

if TYPE_CHECKING:
    from executive.runtime.mission import Executive

__all__ = ["Console"]

TEXT_PERIOD_S = 0.5  # s between redraws of the status line and the tree
DRAW_SHARE = 0.02  # most of the wall time the console's thread spends moving the scene
CAMERA_OFFSET = np.array([1.6, 1.0, 1.1])  # m from the point looked at
IDLE_WAIT_S = 0.25


class Console:
    """The console's page and the thread that keeps it current.

    Args:
        port: TCP port on 127.0.0.1 (0: any free one; see :func:`executive.console.server.start_server`).
        title: the panel's title.
        rate_hz: the most scene updates per second.
        user: who answers approvals here (default the account running it).

    Raises:
        ConsoleError: viser is not installed.
    """

    def __init__(
        self, port: int = PORT, *, title: str = "executive", rate_hz: float = 25.0, user: str | None = None
    ) -> None:
        self.server = start_server(port, title=title)
        self.channel = ConsoleChannel(user)
        gui = self.server.gui
        self.status = gui.add_markdown("starting", order=0)
        self.approval = ApprovalPanel(self.server, self.channel, order=1)
        self.tree_folder = gui.add_folder("Behaviour tree", order=1000, expand_by_default=True)
        with self.tree_folder:
            self.tree = gui.add_markdown("(no tree)")
        self.tasks: dict[str, TaskView] = {}
        self.view: WorldView | None = None
        self.ghost: GhostView | None = None
        self.feed = LiveFeed(rate_hz)
        self._period = self.feed.period
        self.errors: list[str] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._shown: dict[str, int] = {}
        self.replay: ReplayView | None = None

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.server.get_port()}/"

    # --- filling the page -----------------------------------------------------------------

    def show_world(self, model: mujoco.MjModel, data: mujoco.MjData, estimate: World) -> None:
        """Draw a world: the scene of ``model`` at ``data`` (the one the page follows), lit, the camera
        on the robot and the table; the ghosts of plans made on ``estimate`` will be drawn on it."""
        light(self.server)
        self.view = WorldView(self.server, model, data)
        self.ghost = GhostView(self.server, estimate)
        # Look at the robot and the table from the front left, the table's height.
        table = estimate.scenario.scene.table
        look = np.array([table.position[0] / 2, table.position[1] / 2, table.height])
        self.server.initial_camera.look_at = look
        self.server.initial_camera.position = look + CAMERA_OFFSET

    def task_view(self, key: str, label: str) -> TaskView:
        """The folder of task ``key`` (made on first use, in order of first use)."""
        if key not in self.tasks:
            self.tasks[key] = TaskView(self.server, self.ghost, label, order=10 + len(self.tasks))
        return self.tasks[key]

    def show_alternatives(
        self,
        key: str,
        label: str,
        estimate: World,
        results: list[AlternativeRisk],
        ordering: str,
        threshold: float,
        note: str = "",
    ) -> None:
        """Show one task's decision: its rows, and a ghost motion per feasible alternative with a plan.

        Args:
            key: the task's key (``task0``); a key shown before is laid out anew.
            label: the task's folder title.
            estimate: the world the alternatives were planned on.
            results: every alternative's assessment (after the physics check, if one ran).
            ordering: the scenario's ``risk.ordering``; ``threshold``: its ``risk.threshold``.
            note: a line above the table (what the numbers are).
        """
        rows = [risk_row(a, ordering) for a in results]
        motions = {
            a.name: PlannedMotion(estimate, a) for a in results if a.plan is not None and a.risk is not None
        }
        self.task_view(key, label).show(rows, ordering, threshold, motions, note)

    def attach(self, executive: Executive) -> None:
        """Follow ``executive`` live; returns at once.

        The console's feed joins ``executive.tick_listeners``, and the console's thread draws the
        scene (the truth world the executive steps, or for a host's robot the estimate at the
        robot's joints), each task's decisions, the approval section and the tree. To take
        approvals on the page, build the executive with ``approval=console.channel``.
        """
        robot_world = executive.truth if executive.truth is not None else executive.estimate
        self.show_world(robot_world.model, executive.robot.data, executive.estimate)
        executive.tick_listeners.append(self.feed)
        self._start(lambda: self._follow(executive))

    def _start(self, target: Callable[[], None]) -> None:
        self._thread = threading.Thread(target=target, name="console", daemon=True)
        self._thread.start()

    # --- the console's thread -------------------------------------------------------------

    def _follow(self, executive: Executive) -> None:
        next_text = 0.0
        while not self._stop.is_set():
            snap = self.feed.take(IDLE_WAIT_S)
            try:
                if snap is not None and self.view is not None:
                    t0 = time.perf_counter()
                    self.view.update(snap.qpos)
                    # Draw less often when drawing is slow (a robot of many meshes): at most
                    # DRAW_SHARE of the time goes to it, so the ticking loop keeps its interpreter.
                    self.feed.period = max(self._period, (time.perf_counter() - t0) / DRAW_SHARE)
                self._decisions(executive)
                self.approval.refresh()
                now = time.perf_counter()
                if now >= next_text or executive.done:  # the words change less often than the pose
                    next_text = now + TEXT_PERIOD_S
                    self._tree(executive.root)
                    self._status(executive)
            except Exception as exc:  # a drawing error must not stop the run; it is shown instead
                self._error(exc)

    def _decisions(self, executive: Executive) -> None:
        """Show every task whose selector has ranked anew since last looked."""
        for selector in executive.selectors:
            results = selector.results
            if not results or self._shown.get(selector.name) == id(results):
                continue
            self._shown[selector.name] = id(results)
            label = f"{selector.name}: {task_label(selector.task)}"
            self.show_alternatives(
                selector.name, label, executive.estimate, list(results), selector.ordering, selector.threshold
            )

    def _tree(self, root: py_trees.behaviour.Behaviour) -> None:
        text = "```\n" + py_trees.display.unicode_tree(root, show_status=True) + "\n```"
        if self.tree.content != text:
            self.tree.content = text

    def _status(self, executive: Executive) -> None:
        scenario = executive.scenario.name
        line = f"**{scenario}** · robot time {executive.robot.time:.1f} s · {executive.describe()}"
        pending = executive.pending_approval
        if pending is not None and executive.channel is not self.channel:
            line += f" · waiting for approval from `{executive.channel.name}`"
        if executive.done:
            line = f"**{scenario}** · run ended: **{executive.outcome}**"
            line += f" at robot time {executive.robot.time:.1f} s"
        if self.errors:
            line += f"  \nconsole error: {self.errors[-1]}"
        if self.status.content != line:
            self.status.content = line

    def _error(self, exc: Exception) -> None:
        text = f"{type(exc).__name__}: {exc}"
        if not self.errors or self.errors[-1] != text:
            self.errors.append(text)

    # --- a scenario, a run folder ---------------------------------------------------------

    def preview(self, scenario: Scenario) -> None:
        """Plan every task of ``scenario`` on its estimate and check the plans in physics, as
        ``executive plan`` does, showing the analytic table at once and the checked one after;
        nothing is executed. Returns at once (the planning runs in the console's thread)."""
        from executive.world.model import build

        world = build(scenario)
        mujoco.mj_forward(world.model, world.data)
        self.show_world(world.model, world.data, world)
        self.status.content = f"**{scenario.name}** · planning (nothing is executed)"
        self._start(lambda: self._plan(scenario, world))

    def _plan(self, scenario: Scenario, world: World) -> None:
        from executive.decision.assessment import assess_task
        from executive.decision.physics_check import PhysicsCheck

        risk = scenario.risk
        physics = PhysicsCheck(risk.rollouts.jobs)
        try:
            for i, task in enumerate(scenario.mission):
                key, label = f"task{i}", f"task{i}: {task.label()}"
                analytic = assess_task(world, task)
                note = "analytic risk; checking the plans in physics ..."
                self.show_alternatives(key, label, world, analytic, risk.ordering, risk.threshold, note)
                checked, _ = physics.check(world, analytic)
                note = "after the physics check (dry runs on the estimate, rollouts on sampled truths)"
                self.show_alternatives(key, label, world, checked, risk.ordering, risk.threshold, note)
            self.status.content = f"**{scenario.name}** · planned and checked; nothing was executed"
        except Exception as exc:
            self._error(exc)
            self.status.content = f"**{scenario.name}** · planning failed: {self.errors[-1]}"
        finally:
            physics.close()

    def show_run(self, folder: Path, *, replay: bool | None = None, scenario: str | None = None) -> None:
        """Show the decisions logged in the run folder ``folder``, and its per-tick record with a
        time slider when it has one (else its scene as the scenario starts).

        Args:
            folder: the run folder.
            replay: True: the record is required (``executive replay --console``); None: shown
                when present; False: not shown.
            scenario: the run's scenario file, if not where the run read it.

        Raises:
            ConsoleError: ``folder`` holds no run.
            RecordError: ``replay`` is True and the record is missing or unreadable.
        """
        entries = read_decisions(folder)
        run = next((e for e in entries if e.get("kind") == "run"), {})
        ordering, threshold = str(run.get("ordering", "expected_loss")), float(run.get("threshold", 0.0))
        if not (replay is not False and self._replay(folder, scenario, required=bool(replay))):
            self._scene_of(run)
        for key, decision in task_decisions(entries).items():
            labels = run.get("tasks") or []
            index = int(key[4:]) if key.startswith("task") and key[4:].isdigit() else -1
            label = f"{key}: {labels[index]}" if 0 <= index < len(labels) else key
            self.task_view(key, label).show(decision.rows, ordering, threshold, None, decision.note())
        end = next((e for e in reversed(entries) if e.get("kind") == "end"), None)
        ended = f"ended **{end.get('outcome')}**" if end else "did not end (killed?)"
        self.status.content = f"**{run.get('scenario', folder)}** · run folder `{folder}` · {ended}"
        with self.server.gui.add_folder("Decisions (decisions.jsonl)", order=500, expand_by_default=False):
            self.server.gui.add_markdown(timeline(entries))

    def _replay(self, folder: Path, scenario: str | None, *, required: bool) -> bool:
        """The record's replay section and the scene of its world; False when there is no record."""
        from executive.errors import ExecutiveError
        from executive.execution.tick_record import load_record
        from executive.report.replay import rebuild_world

        try:
            record = load_record(folder)
            world = rebuild_world(record, scenario)
        except ExecutiveError as exc:
            if required:
                raise
            self._error(exc)
            return False
        data = world.data
        data.qpos[:] = record.qpos[0]
        self.show_world(world.model, data, world)
        assert self.view is not None
        self.replay = ReplayView(self.server, record, self.view, self.tree, order=5)
        return True

    def _scene_of(self, run: dict[str, Any]) -> None:
        """The run's scenario as it starts, when its file can still be loaded (else no scene)."""
        from executive.errors import ExecutiveError
        from executive.scenario import load
        from executive.world.model import build

        source = run.get("source")
        if not source or not Path(source).is_file():
            return
        try:
            world = build(load(str(source)))
        except ExecutiveError as exc:
            self._error(exc)
            return
        mujoco.mj_forward(world.model, world.data)
        self.show_world(world.model, world.data, world)

    # --- end ------------------------------------------------------------------------------

    def wait(self) -> None:
        """Block until Ctrl-C (KeyboardInterrupt, re-raised) or :meth:`close` from another thread."""
        while not self._stop.is_set():
            time.sleep(0.2)  # not Event.wait: Ctrl-C inside its lock handling can raise RuntimeError

    def close(self) -> None:
        """Stop the console's thread and its server (the page shows it disconnected)."""
        self._stop.set()
        self.feed.ready.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        stop_server(self.server)
