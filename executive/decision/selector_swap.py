"""Taking a planning result into the selector's tree, a piece a tick.

:class:`ResultSwap` lists the pieces of taking a :class:`~executive.decision.planning_job.PlanningResult`
in (:meth:`ResultSwap.begin`): its physics lines, each feasible alternative's subtree, and per
guarded motion of the lowest-risk one its prepared knot distances handed to the live risk monitor,
then that subtree's guards' allowed contacts. :meth:`ResultSwap.step` runs one piece; a selector
from a worker runs one per tick, one planning in the tick runs them all. :func:`swap_children` then
makes the built subtrees the selector's children.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import py_trees

from behaviours.guard import RiskGuard
from executive.decision.assessment import AlternativeRisk
from executive.decision.audit import AuditLog
from executive.decision.physics_check import PhysicsVerdict
from executive.decision.planning_job import PlanningResult, PreparedKnots, ranked
from executive.tasks.base import TaskKind

if TYPE_CHECKING:
    from executive.planning.plan import AlternativePlan

__all__ = ["ResultSwap", "swap_children"]

Behaviour = py_trees.behaviour.Behaviour


class ResultSwap:
    """One selector's taking in of its planning results.

    Args:
        name: the selector's name (the ``task`` of its log lines).
        kind: the task's kind (builds the subtrees).
        guard: wrap motions in live risk guards.
        log: the audit log.
    """

    def __init__(self, name: str, kind: TaskKind, *, guard: bool, log: AuditLog) -> None:
        self.name = name
        self.kind = kind
        self.guard = guard
        self.log = log
        self.built: dict[str, Behaviour] = {}  # subtrees built from the result so far
        self.pieces: list[Callable[[], str | None]] | None = None  # None: not begun; then what is left

    def reset(self) -> None:
        """Forget the result (a new decision)."""
        self.built, self.pieces = {}, None

    def begin(self, result: PlanningResult, ordering: str, monitor: Any) -> None:
        """List the pieces of taking ``result`` in (see the module docstring).

        Args:
            result: the decision's result.
            ordering: the scenario's ordering quantity (ranks the feasible alternatives).
            monitor: the live risk monitor the guards use (None: guards off, or none installed).
        """
        feasible = ranked(result.results, ordering)
        pieces: list[Callable[[], str | None]] = [lambda: self._log_physics(result.results, result.verdict)]
        pieces += [functools.partial(self._build, alt) for alt in feasible]
        best = feasible[0].plan if feasible else None
        if monitor is not None and best is not None:
            pieces += [functools.partial(self._adopt, monitor, best, knots) for knots in result.knots]
            pieces.append(functools.partial(self._prime_guards, monitor, feasible[0].name))
        self.pieces = pieces

    def step(self) -> str | None:
        """Run the next piece; the selector's feedback message it leaves (None: none)."""
        assert self.pieces
        return self.pieces.pop(0)()

    def _log_physics(self, results: Sequence[AlternativeRisk], verdict: PhysicsVerdict | None) -> None:
        """One ``dry_run`` line per alternative run in physics, and a ``rollouts`` line if any ran."""
        if verdict is None:
            return
        for alt in results:
            if alt.physics is not None:
                dry = alt.physics["dry_run"]
                self.log.record(
                    "dry_run", task=self.name, name=alt.name, ok=alt.feasible, reason=alt.error, **dry
                )
        if verdict.stopped != "off":
            per_alt = {a.name: a.physics for a in results if a.physics is not None and a.feasible}
            self.log.record("rollouts", task=self.name, **verdict.as_dict(), alternatives=per_alt)

    def _build(self, alt: AlternativeRisk) -> str:
        """Build ``alt``'s subtree (kept for the decision)."""
        assert alt.plan is not None
        subtree = self.kind.subtree(alt.plan, guard=self.guard)
        subtree.setup_with_descendants()
        self.built[alt.name] = subtree
        return f"planning {self.name}: {alt.name} ready"

    def _adopt(self, monitor: Any, plan: AlternativePlan, knots: PreparedKnots) -> None:
        """Hand the worker's prepared knot distances of one guarded motion of ``plan`` to ``monitor``."""
        trajectory = plan.trajectories.get(knots.step)
        if trajectory is not None:
            monitor.adopt(
                trajectory.qpos,
                carried=knots.carried,
                allow=knots.allow,
                distances=knots.distances,
                names=knots.names,
            )

    def _prime_guards(self, monitor: Any, name: str) -> None:
        """Have the guards of ``name``'s subtree work out their allowed contacts now (each motion's
        first tick would)."""
        for node in self.built[name].iterate():
            if isinstance(node, RiskGuard):
                node.allow(monitor)


def swap_children(
    composite: py_trees.composites.Composite,
    ranked: Sequence[AlternativeRisk],
    subtrees: dict[str, Behaviour],
) -> dict[str, Behaviour]:
    """Make the built subtrees ``composite``'s children, lowest risk first.

    Returns:
        The new children by alternative name.
    """
    for child in list(composite.children):
        composite.remove_child(child)
    by_name = {}
    for alt in ranked:
        subtree = subtrees[alt.name]
        composite.add_child(subtree)
        by_name[alt.name] = subtree
    return by_name
