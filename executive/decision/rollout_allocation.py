"""Sequential allocation of a decision's rollouts: which alternatives the next round is for.

Rollouts go where the choice is unclear, not a fixed count to every alternative (the idea of
sequential ranking-and-selection procedures, e.g. Chen et al.'s OCBA, Discrete Event Dynamic
Systems 10(3), 2000; here driven by the stopping rule's posterior). After each round the
stopping rule's joint posterior draws (:func:`executive.risk.fusion.contention`) give,
for every alternative, the chance that it beats the current best by more than the
indifference (:attr:`~executive.risk.fusion.Contention.rivals`). An alternative is rolled out
again while

* it has fewer than ``min_count`` rollouts (the minimum always runs: only ``count`` 0 turns the
  rollouts off);
* it is a *rival*: that chance is at least ``(1 - confidence) / (m - 1)`` of ``m``
  alternatives. When no rival is left, the stopping rule's P(choice clear) is at least
  ``confidence`` (union bound), so an alternative clearly worse than the best stops early;
* it is the best, and a rival is left or its approval is unsure (the chance that its value is
  above ``risk.threshold`` is between ``1 - confidence`` and ``confidence``). A best that is
  clearly within (or clearly over) the threshold with no rival left stops;

and never past ``count`` (the hard cap). Everything here is a function of the counts and of
seeded draws: the same seeds give the same allocation.
"""

from __future__ import annotations

from collections.abc import Mapping

from executive.risk.fusion import Contention
from executive.schema.types import RolloutConfig

__all__ = ["CLEAR", "COUNT", "GOING", "allocate"]

GOING = ""  #: the alternative gets the next round
CLEAR = "clear"  #: more rollouts of it could not change the choice (nor its approval, if best)
COUNT = "count"  #: still unsure, but at ``count``, the cap


def allocate(state: Contention, rollouts: Mapping[str, int], config: RolloutConfig) -> dict[str, str]:
    """Per alternative, whether it gets the next round (:data:`GOING`) or why it stops.

    Args:
        state: the stopping rule's view after the last round, with its rivals and the best's
            chance to need approval (:func:`executive.risk.fusion.contention`).
        rollouts: the rollouts each alternative has had.
        config: ``risk.rollouts`` (``count``, ``min_count``, ``confidence``).

    Returns:
        alternative -> :data:`GOING`, :data:`CLEAR` or :data:`COUNT`.
    """
    share = (1.0 - config.confidence) / max(len(rollouts) - 1, 1)
    choice = state.choice
    rivals = {name for name, p in state.rivals.items() if name != choice.best and p >= share}
    unsure_approval = 1.0 - config.confidence < state.above_threshold < config.confidence
    if choice.confidence >= config.confidence and not unsure_approval:
        rivals = set()  # the stopping rule calls the choice clear
    out = {}
    for name, n in rollouts.items():
        wanted = n < config.min_count or name in rivals
        if name == choice.best:
            wanted = wanted or bool(rivals) or unsure_approval
        out[name] = (COUNT if n >= config.count else GOING) if wanted else CLEAR
    return out
