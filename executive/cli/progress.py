"""What ``executive run`` shows while the mission runs, and the final table.

Decisions are printed as they reach the audit log (the risk table when a task has
been planned, the selection, approvals, failures, outcomes). Between them, on a
terminal, one status line is redrawn in place (robot time, task, phase, the
running behaviour); without a terminal a line is printed whenever the running
behaviour changes. Nothing is drawn while an approval prompt waits for the
operator: the status line (``\r\x1b[2K`` + text) would erase the prompt line the
operator types on; with a terminal prompt the display prints what precedes the
request (the risk table, the selection) and then lets the prompt draw
(:meth:`executive.decision.approval.TerminalChannel.screen_free`).
"""

from __future__ import annotations

import math
import time
from typing import IO, Any

from executive.decision.approval import TerminalChannel
from executive.report.plots import risk_table
from executive.runtime.mission import Executive

__all__ = ["MissionDisplay", "final_table", "observed"]


def final_table(summary: dict[str, Any]) -> str:
    """Chosen alternative, predicted risk and outcome per task."""
    ordering = summary.get("ordering", "value")
    width = max([34, *(len(t["task"]) + 2 for t in summary["tasks"])])  # a long label widens the column
    head = f"{'task':<{width}}{'chosen':<15}{ordering:>14}{'P(any)':>9}{'approval':>22}  outcome"
    lines = [head]
    for task in summary["tasks"]:
        risk = task.get("risk") or {}
        value = task.get("value")
        approval = task.get("approval")
        by = f"{approval['decision']} ({approval['by']})" if approval else "not needed"
        if approval is None and task.get("chosen") is None:
            by = "-"
        outcome = task.get("outcome") or "not run"
        failure = task.get("failure")
        if failure and outcome != "success":
            outcome += f": {failure.get('detail', '')}"
        value_text = f"{value:.4f}" if value is not None else "-"
        combined = risk.get("combined")
        combined_text = f"{combined:.4f}" if combined is not None else "-"
        lines.append(
            f"{task['task']:<{width}}{task.get('chosen') or '-':<15}"
            f"{value_text:>14}{combined_text:>9}{by:>22}  {outcome}"
        )
    return "\n".join(lines)


class MissionDisplay:
    """Progress of an :class:`Executive` on a text stream."""

    def __init__(self, executive: Executive, stream: IO[str], refresh_s: float = 0.2) -> None:
        self.executive = executive
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.refresh_s = refresh_s
        self._seen = 0
        self._last_draw = 0.0
        self._last_line = ""
        self._drawn = False
        if isinstance(executive.channel, TerminalChannel):
            executive.channel.wait_for_display = True

    def start(self) -> None:
        ex = self.executive
        self._print(
            f"run {ex.scenario.name}: {len(ex.scenario.mission)} task(s); truth {ex.truth_label}; "
            f"approval {ex.channel.name}; risk ranked by {ex.scenario.risk.ordering}, "
            f"threshold {ex.scenario.risk.threshold:g}"
        )
        if ex.folder is not None:
            self._print(f"run folder {ex.folder}")

    def _print(self, text: str) -> None:
        if self._drawn:
            self.stream.write("\r\x1b[2K")
            self._drawn = False
        self.stream.write(text + "\n")
        self.stream.flush()

    def _events(self) -> None:
        entries = self.executive.log.entries
        while self._seen < len(entries):
            entry = entries[self._seen]
            self._seen += 1
            text = self._describe(entry)
            if text:
                self._print(text)

    def _describe(self, e: dict[str, Any]) -> str:
        kind = e["kind"]
        if kind == "planning":
            what = "re-planning" if e.get("replan") else "planning"
            return f"{e['task']}: {what} {', '.join(e['alternatives'])} on the estimate"
        if kind == "selection":
            selector = next(s for s in self.executive.selectors if s.name == e["task"])
            ex = self.executive
            table = risk_table(ex.scenario, selector.name, selector.results, approval=ex.channel.name)
            return f"{table}\n{e['task']}: {e['reason']}"
        if kind == "approval_request":
            return f"{e['task']}: approval requested from {e['channel']}"
        if kind == "approval":
            alt = f" {e['alternative']}" if e.get("alternative") else ""
            return f"{e['task']}: {e['decision']}{alt} by {e['by']} at {e['at']}"
        if kind == "execute":
            return f"{e['task']}: executing {e['alternative']}"
        if kind == "failure":
            return f"{e['task']}: {e['alternative']} failed: {e['detail']}"
        if kind == "outcome":
            return f"{e['task']}: {e['outcome']}"
        if kind == "stop":
            return f"stopped: {e['reason']}"
        if kind == "observation":
            return observed(e)
        return ""

    def update(self) -> None:
        self._events()
        ex = self.executive
        pending = ex.pending_approval
        if pending is not None:  # the prompt owns the terminal until it is answered
            if isinstance(ex.channel, TerminalChannel):
                ex.channel.screen_free(pending)
            return
        if ex.done:
            return
        line = f"t={ex.robot.time:6.2f} s  {ex.describe()}"
        if self.tty:
            now = time.monotonic()
            if now - self._last_draw >= self.refresh_s:
                self._last_draw = now
                self.stream.write("\r\x1b[2K" + line[:150])
                self.stream.flush()
                self._drawn = True
            return
        # Not a terminal: a line per behaviour, not per tick.
        key = line.split(":", 1)[0] if ":" in line else line
        key = " ".join(key.split()[2:])
        if key != self._last_line:
            self._last_line = key
            self._print(line)

    def finish(self) -> None:
        self._events()
        summary = self.executive.summary()
        self._print("")
        self._print(final_table(summary))
        for placed in summary.get("placement", []):
            if placed.get("error_m") is None:  # nothing was executed: the object was not moved
                self._print(f"{placed['object']} not moved: no alternative was executed")
            else:
                self._print(f"{placed['object']} rests {placed['error_m'] * 1000:.1f} mm from its target")
        wall = summary.get("wall_s") or 0.0
        self._print(
            f"outcome   {summary['outcome']}; {summary['sim_time_s']:.1f} s simulated in {wall:.1f} s wall, "
            f"{summary['ticks']} ticks, longest tick {summary['max_tick_s'] * 1000:.1f} ms"
        )
        if summary.get("folder"):
            self._print(f"run folder {summary['folder']} (decisions.jsonl, summary.json, plots)")


def observed(e: dict[str, Any]) -> str:
    """One line of an ``observation`` log line: why, from what, where each object is and who holds it."""
    source = e["source"]
    how = source["source"]
    if "sigma_position_m" in source:
        sigma_yaw = math.degrees(source["sigma_yaw_rad"])
        how += f", sigma {1000 * source['sigma_position_m']:.0f} mm {sigma_yaw:.1f} deg"
    where = "; ".join(
        f"{o['name']} at ({o['position'][0]:.3f}, {o['position'][1]:.3f}, {o['position'][2]:.3f})"
        + (f" in the {o['held_by']} hand" if o["held_by"] else "")
        for o in e["objects"]
    )
    return f"{e['task'] or 'start'}: observed ({e['reason'].replace('_', ' ')}; {how}): {where}"
