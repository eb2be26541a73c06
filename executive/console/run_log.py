"""A run folder's decisions, read back for the console: per task the last ranking, and the timeline.

``decisions.jsonl`` (:mod:`executive.decision.audit`) is read line by line; a last line cut
short by a killed run is left out (everything before it was written whole). Per task the
rows of its last decision are the ``plan`` lines after its last ``planning`` line; its
``selection``, ``approval`` and ``outcome`` lines say what became of them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from executive.console.server import ConsoleError

__all__ = ["TaskDecision", "read_decisions", "task_decisions", "timeline"]


def read_decisions(folder: Path) -> list[dict[str, Any]]:
    """Every whole line of ``folder/decisions.jsonl``, in order.

    Raises:
        ConsoleError: the folder holds no run (no ``decisions.jsonl``), or a line that is not
            the last is not JSON.
    """
    path = Path(folder) / "decisions.jsonl"
    if not path.is_file():
        raise ConsoleError(f"{folder}: not a run folder (no decisions.jsonl in it)")
    lines = path.read_text(encoding="utf-8").splitlines()
    entries = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            entries.append(json.loads(line))
        except json.JSONDecodeError as exc:
            if i == len(lines) - 1:  # cut short by a kill: the rest was written whole
                break
            raise ConsoleError(f"{path}: line {i + 1} is not JSON ({exc.msg})") from None
    return entries


@dataclass
class TaskDecision:
    """What a run decided for one task (its last planning) and what became of it."""

    task: str
    rows: list[dict[str, Any]] = field(default_factory=list)
    selection: dict[str, Any] | None = None
    approval: dict[str, Any] | None = None
    outcome: dict[str, Any] | None = None

    def note(self) -> str:
        """One markdown paragraph: the selection's reason, the approval (by whom), the outcome."""
        parts = []
        if self.selection is not None:
            parts.append(f"selection: {self.selection.get('reason', '')}")
        if self.approval is not None:
            a = self.approval
            alt = f" {a['alternative']}" if a.get("alternative") else ""
            parts.append(f"approval: **{a.get('decision')}{alt}** by `{a.get('by')}` at {a.get('at')}")
        if self.outcome is not None:
            failure = self.outcome.get("failure") or {}
            detail = f" ({failure.get('mode')}: {failure.get('detail')})" if failure else ""
            parts.append(f"outcome: **{self.outcome.get('outcome')}**{detail}")
        return "  \n".join(parts)


def task_decisions(entries: list[dict[str, Any]]) -> dict[str, TaskDecision]:
    """Per task (``task0``, ...) its last decision, in the order the tasks first appear."""
    out: dict[str, TaskDecision] = {}
    for entry in entries:
        task = entry.get("task")
        if not isinstance(task, str):
            continue
        decision = out.setdefault(task, TaskDecision(task))
        kind = entry.get("kind")
        if kind == "planning":
            decision.rows, decision.selection = [], None
        elif kind == "plan":
            decision.rows.append(entry)
        elif kind == "selection":
            decision.selection = entry
        elif kind == "approval":
            decision.approval = entry
        elif kind == "outcome":
            decision.outcome = entry
    return out


def _summary(entry: dict[str, Any]) -> str:
    kind = entry.get("kind")
    if kind == "plan":
        value = entry.get("value")
        return f"{entry.get('name')}: " + (
            f"value {value:.4g}" if value is not None else f"infeasible: {entry.get('reason')}"
        )
    if kind == "approval":
        return f"{entry.get('decision')} {entry.get('alternative') or ''} by {entry.get('by')}"
    if kind in ("selection", "stop"):
        return str(entry.get("reason", ""))
    if kind == "execute":
        return str(entry.get("alternative"))
    if kind in ("failure", "outcome", "end"):
        return str(entry.get("outcome") or entry.get("mode") or "") + (
            f": {entry['detail']}" if entry.get("detail") else ""
        )
    return ""


def timeline(entries: list[dict[str, Any]]) -> str:
    """Markdown: one line per decision (time, task, kind, what it said)."""
    lines = ["| at | task | kind | |", "|---|---|---|---|"]
    for entry in entries:
        at = str(entry.get("at", ""))[11:23]
        text = _summary(entry).replace("|", "/")
        lines.append(f"| {at} | {entry.get('task') or ''} | {entry.get('kind')} | {text} |")
    return "\n".join(lines)
