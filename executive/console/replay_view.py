"""A run's per-tick record on the console's page: a time slider over the whole run.

The record (:mod:`executive.execution.tick_record`) keeps, every tick, the recorded world's
``qpos``, the guard's predicted clearance and CoM margin and the tree's statuses. A
:class:`ReplayView` puts a robot-time slider and a play button on the page; at the chosen time
the scene shows the recorded state (the frame at or before it), the panel that tick's guard
values and phase, and the tree as it stood then. A killed run replays up to its last whole tick.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import py_trees

from executive.console.scene import WorldView
from executive.execution.tick_record import Record, TreeNode

if TYPE_CHECKING:
    import viser

__all__ = ["ReplayView", "tree_text"]

_SYMBOLS = {status.value: py_trees.display.unicode_symbols[status] for status in py_trees.common.Status}


def tree_text(statuses: list[tuple[TreeNode, str]]) -> str:
    """The recorded tree at one frame as py_trees prints it: indented by depth, ``[status]`` after names."""
    depth: list[int] = []
    lines = []
    for node, status in statuses:
        d = depth[node.parent] + 1 if 0 <= node.parent < len(depth) else 0
        depth.append(d)
        lines.append(f"{'    ' * d}{node.name} [{_SYMBOLS.get(status, status)}]")
    return "\n".join(lines)


def _mm(value: float) -> str:
    return "-" if not np.isfinite(value) else f"{value * 1000:.1f} mm"


class ReplayView:
    """The replay section of the page: robot-time slider, play/pause, the frame's facts and tree.

    Args:
        server: the console's viser server.
        record: the run's record.
        view: the scene of the recorded world (its model is the record's).
        tree: the page's tree markdown (shows the recorded tree at the chosen frame).
        order: where the section sits in the panel.
    """

    def __init__(
        self, server: viser.ViserServer, record: Record, view: WorldView, tree: Any, order: float
    ) -> None:
        self.record, self.view, self.tree = record, view, tree
        self.lock = threading.Lock()
        self.frame = -1
        gui = server.gui
        times = record.times
        complete = "complete" if record.complete else "cut short (the run was killed or stopped)"
        with gui.add_folder("Replay (the run's per-tick record)", order=order):
            gui.add_markdown(f"{len(record)} ticks, {record.duration:.1f} s of robot time; {complete}")
            self.facts = gui.add_markdown("")
            step = float(np.median(np.diff(times))) if len(times) > 1 else 0.02
            self.slider: Any = gui.add_slider(
                "robot time [s]",
                min=float(times[0]),
                max=float(max(times[-1], times[0] + step)),
                step=round(step, 4),
                initial_value=float(times[0]),
            )
            self.play = gui.add_button("Play / pause", color="blue")
        self.slider.on_update(lambda _: self.show(float(self.slider.value)))
        self.play.on_click(lambda _: self._toggle())
        self._playing: threading.Event | None = None
        self.show(float(times[0]))

    def show(self, t: float) -> None:
        """The recorded state at robot time ``t`` (the last frame at or before it)."""
        record = self.record
        frame = record.frame_at(t)
        with self.lock:
            if frame == self.frame:
                return
            self.frame = frame
            self.view.update(record.qpos[frame])
            phase = next((p for p in reversed(record.phases) if p["frame"] <= frame), None)
            doing = f"{phase['task']} {phase['phase']} {phase.get('alternative') or ''}" if phase else "-"
            self.facts.content = (
                f"tick {int(record.ticks[frame])} · robot time {record.times[frame]:.2f} s · {doing}  \n"
                f"guard: predicted clearance {_mm(record.clearance[frame])}, "
                f"CoM margin {_mm(record.com_margin[frame])}"
            )
            statuses = record.statuses_at(frame)
            if statuses:
                self.tree.content = "```\n" + tree_text(statuses) + "\n```"

    def _toggle(self) -> None:
        """Play from the slider's time in real time, or pause."""
        if self._playing is not None:
            self._playing.set()
            self._playing = None
            return
        stop = threading.Event()
        self._playing = stop
        threading.Thread(target=self._play, args=(stop,), name="console-replay", daemon=True).start()

    def _play(self, stop: threading.Event) -> None:
        start_wall, start_t = time.perf_counter(), float(self.slider.value)
        end = float(self.record.times[-1])
        while not stop.is_set():
            t = min(end, start_t + time.perf_counter() - start_wall)
            self.slider.value = round(t / self.slider.step) * self.slider.step
            if t >= end:
                break
            stop.wait(0.04)
        if self._playing is stop:
            self._playing = None
