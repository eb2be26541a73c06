"""The risk of a rest re-planned after a walk, checked against what was approved.

When the rest of an alternative is planned again from the measured stance
(:mod:`executive.planning.restance`), the alternative is no longer the one whose risk was
approved. :class:`RiskRecheck` assesses the rest as planned and as re-planned with the same
analytic models (:func:`executive.decision.assessment.assess_plan`); the alternative's value
now is the approved value plus the change, and the re-plan may run only while that stays within
what was approved (:class:`Approval`): the threshold, or the value an operator approved above it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from executive.decision.assessment import assess_plan
from executive.planning.plan import AlternativePlan
from executive.risk.collision import CollisionModel
from executive.world.model import World

__all__ = ["Approval", "RiskRecheck"]


@dataclass(frozen=True)
class Approval:
    """What was approved of an alternative: its ``value`` under ``ordering`` when it started, and
    ``bound``, the most it may reach without asking again (the threshold, or the value an operator
    approved above it: :meth:`of`)."""

    value: float
    bound: float
    ordering: str

    @classmethod
    def of(cls, value: float, threshold: float, ordering: str) -> Approval:
        """The approval of an alternative started at ``value``: within ``threshold`` it was the
        threshold's; above it, an operator approved that value and no more."""
        return cls(float(value), max(float(threshold), float(value)), ordering)


class RiskRecheck:
    """A :class:`executive.planning.restance.RestCheck`: the re-planned rest's risk against the approval.

    Args:
        approval: what was approved of the alternative.
        collision: the collision model of the estimate (None: built on first use).
    """

    def __init__(self, approval: Approval, collision: CollisionModel | None = None) -> None:
        self.approval = approval
        self.collision = collision

    def __call__(
        self, world: World, planned: AlternativePlan, replanned: AlternativePlan
    ) -> tuple[str, dict[str, Any]]:
        """``""`` when the approved value plus the rest's change of value stays within the bound,
        else why not; and the record (both rests' values, the value now, the approval)."""
        if self.collision is None:
            scenario = world.scenario
            self.collision = CollisionModel(world, scenario.risk, uncertainty=scenario.uncertainty)
        ordering = self.approval.ordering
        before = assess_plan(world, planned, self.collision).value(ordering)
        after = assess_plan(world, replanned, self.collision).value(ordering)
        now = self.approval.value + after - before
        record = {
            "ordering": ordering,
            "rest_planned": before,
            "rest_replanned": after,
            "approved": self.approval.value,
            "now": now,
            "bound": self.approval.bound,
        }
        if now <= self.approval.bound:
            return "", record
        reason = (
            f"re-planned from the measured stance, the rest raises the alternative's {ordering} from "
            f"{self.approval.value:.4g} to {now:.4g}, above the {self.approval.bound:.4g} approved"
        )
        return reason, record
