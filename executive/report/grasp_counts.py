"""How many one-hand grasp alternatives a task considered, pruned before planning, and planned.

Grasps are a dimension of a transfer's one-hand alternatives (:mod:`executive.tasks.grasp_candidates`);
before planning, each hand's are pruned (the hand cannot make the grasp, it is out of reach, or
it is not among the hand's likeliest). The plan output says how many of each, so that the number
planned stays visibly bounded.

Usage::

    counts = grasp_counts(rows)   # None: the task asked for no grasp but the default
    print(grasp_counts_text(counts))
"""

from __future__ import annotations

from collections.abc import Sequence

from executive.decision.assessment import AlternativeRisk
from executive.tasks.hands import ONE_HAND
from executive.tasks.transfer import GRASPED

__all__ = ["grasp_counts", "grasp_counts_text"]


def grasp_counts(alternatives: Sequence[AlternativeRisk]) -> dict[str, int] | None:
    """``{considered, pruned, planned, feasible}`` over the one-hand rows; None without a grasped row.

    Pruned: refused before planning (no plan time); planned: the planner tried them.
    """
    rows = [a for a in alternatives if a.name in ONE_HAND or a.name in GRASPED]
    if not any(a.name in GRASPED for a in rows):
        return None
    pruned = [a for a in rows if not a.feasible and a.plan_s == 0.0]
    return {
        "considered": len(rows),
        "pruned": len(pruned),
        "planned": len(rows) - len(pruned),
        "feasible": sum(1 for a in rows if a.feasible),
    }


def grasp_counts_text(counts: dict[str, int]) -> str:
    """``grasps: 14 one-hand alternatives considered, 10 pruned before planning, 4 planned (2 feasible)``."""
    return (
        f"grasps: {counts['considered']} one-hand alternatives considered, {counts['pruned']} pruned "
        f"before planning, {counts['planned']} planned ({counts['feasible']} feasible)"
    )
