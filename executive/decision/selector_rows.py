"""The selector's rows for the audit log: a task's label, an alternative's risk row, a ranking.

:func:`risk_row` is what the log's ``plan`` line holds, and what the console's risk table reads;
:func:`ranking_rows` is the ``selection`` line's ranking.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from executive.decision.assessment import AlternativeRisk
from executive.risk.collision import breach_summary
from executive.tasks.base import Task

__all__ = ["ranking_rows", "risk_row", "task_label"]


def task_label(task: Task) -> str:
    """One line naming the task (its kind's label)."""
    return task.label()


def risk_row(alt: AlternativeRisk, ordering: str) -> dict[str, Any]:
    """One alternative's line for the log and the approval request.

    Args:
        alt: the assessed alternative.
        ordering: the scenario's ordering quantity (``risk.ordering``), whose value the row gives.

    Returns:
        ``name`` and ``feasible``, ``physics`` if it ran in physics; then either ``reason`` (no
        risk; with ``binding``, the limits that held a stalled move back, when known) or
        ``risk``, ``breach`` (if it touches a breach obstacle), ``value``,
        ``planned_duration_s``, ``plan_s`` and ``assess_s``.
    """
    row: dict[str, Any] = {"name": alt.name, "feasible": alt.feasible}
    if alt.physics is not None:
        row["physics"] = alt.physics
    if alt.risk is None:
        row["reason"] = alt.error
        if alt.binding:
            row["binding"] = list(alt.binding)
        return row
    row["risk"] = alt.risk.as_dict()
    breach = breach_summary(alt.risk.components["collision"]) if "collision" in alt.risk.components else None
    if breach is not None:  # touching a breach obstacle (category breach), apart from any collision
        row["breach"] = breach
    row["value"] = alt.risk.value(ordering)
    row["planned_duration_s"] = alt.plan.duration if alt.plan is not None else None
    row["plan_s"], row["assess_s"] = alt.plan_s, alt.assess_s
    return row


def ranking_rows(feasible: Sequence[AlternativeRisk], ordering: str) -> list[dict[str, Any]]:
    """The ranked alternatives' names and values (``ordering``), lowest first, for a ``selection`` line."""
    return [{"name": a.name, "value": a.risk.value(ordering) if a.risk else None} for a in feasible]
