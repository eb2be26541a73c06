"""The orderings the selector ranks alternatives by: a registry of :class:`Ordering`.

Built in: ``expected_loss`` (risk = probability x severity, the seed's equation 1),
``probability`` (of any failure), ``weighted_sum`` (the seed's weighted sum of the
per-mode scores, Long et al. 2018) and ``loss_and_time`` (the expected loss plus what the
alternative's planned time costs at ``risk.loss_per_second``: the study's risk against payoff).
A scenario names one in ``risk.ordering``; a new one is a :func:`register_ordering` call::

    register_ordering(Ordering("fall_first", lambda t: t.components["fall"].probability,
                               lambda risk, scene: (1.0, "a probability is at most 1")))
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.schema.failure_modes import failure_modes
from executive.schema.types import RiskConfig, SceneConfig

__all__ = ["Ordering", "Totals", "ordering", "ordering_names", "register_ordering", "unregister_ordering"]


class Totals(Protocol):
    """What an ordering reads of an alternative's combined risk (executive.risk.combine.CombinedRisk)."""

    @property
    def components(self) -> Mapping[str, object]: ...
    @property
    def weighted_sum(self) -> float: ...
    @property
    def probability(self) -> float: ...
    @property
    def expected_loss(self) -> float: ...
    @property
    def time_loss(self) -> float: ...


@dataclass(frozen=True)
class Ordering:
    """One way of ranking alternatives.

    value: the quantity ranked by (lower is better) of an alternative's combined risk.
    max_value: the largest value it can take for a scenario's risk settings and scene, and
        how that is made up (a threshold at or above it would never ask for approval).
    sample: the value from samples of the modes' probabilities ``p`` (modes x draws), their
        severities and the alternative's time loss (the stopping rule's posterior draws); the
        default is the probability of any failure.
    key: the key of the value in a risk row (``CombinedRisk.as_dict``), label: its column heading.
    """

    name: str
    value: Callable[[Totals], float]
    max_value: Callable[[RiskConfig, SceneConfig | None], tuple[float, str]]
    description: str = ""
    sample: Callable[[FloatArray, FloatArray, float], FloatArray] = lambda p, sev, t: _any(p)
    key: str = ""
    label: str = ""


FloatArray = NDArray[np.float64]
_ORDERINGS: dict[str, Ordering] = {}


def _any(p: FloatArray) -> FloatArray:
    """The probability of any failure per draw, the modes independent."""
    return np.asarray(1.0 - np.prod(1.0 - p, axis=0))


def register_ordering(o: Ordering) -> None:
    """Add ``o`` to the registry (raises :class:`ExecutiveError` if its name is taken)."""
    if o.name in _ORDERINGS:
        raise ExecutiveError(f"ordering '{o.name}' is registered already")
    _ORDERINGS[o.name] = o


def unregister_ordering(name: str) -> None:
    """Remove an ordering added by :func:`register_ordering`."""
    ordering(name)
    del _ORDERINGS[name]


def ordering_names() -> tuple[str, ...]:
    """The registered orderings' names."""
    return tuple(_ORDERINGS)


def ordering(name: str) -> Ordering:
    """The ordering called ``name``.

    Raises:
        ExecutiveError: no such ordering (the message lists the valid names).
    """
    try:
        return _ORDERINGS[name]
    except KeyError:
        raise ExecutiveError(f"unknown ordering '{name}'; valid: {', '.join(_ORDERINGS)}") from None


def _max_probability(risk: RiskConfig, scene: SceneConfig | None) -> tuple[float, str]:
    return 1.0, "a probability is at most 1"


def _max_weighted_sum(risk: RiskConfig, scene: SceneConfig | None) -> tuple[float, str]:
    """Each mode's weight times its seed score's largest value (collision: peak + exposure weights)."""
    w = dict(risk.weights)
    peak = risk.collision.peak_weight + risk.collision.exposure_weight
    terms, parts = [], []
    for m in failure_modes():
        top = peak if m.seed_max is None else m.seed_max
        terms.append(w.get(m.name, 0.0) * top)
        scale = " x (peak_weight + exposure_weight) " + f"{peak:g}" if m.seed_max is None else ""
        scale += f" x {m.seed_max:g}" if m.seed_max not in (None, 1.0) else ""
        parts.append(f"{m.name} {w.get(m.name, 0.0):g}{scale}")
    return sum(terms), "weights " + " + ".join(parts)


def _max_expected_loss(risk: RiskConfig, scene: SceneConfig | None) -> tuple[float, str]:
    """Each mode's severity; a per-body mode's largest (obstacles' own too) x the largest body-part factor."""
    sev = risk.severity
    factor = max([1.0, *(f for _, f in sev.body_parts)])
    own = [b.severity for b in scene.obstacles if b.severity is not None] if scene is not None else []
    total, parts = 0.0, []
    for m in failure_modes():
        if m.per_body:
            top = max([sev.of(m.name), *own])
            total += top * factor
            parts.append(f"{m.name} {top:g} x largest body-part factor {factor:g}")
        else:
            total += sev.of(m.name)
            parts.append(f"{m.name} {sev.of(m.name):g}")
    return total, "severity " + " + ".join(parts)


def _max_loss_and_time(risk: RiskConfig, scene: SceneConfig | None) -> tuple[float, str]:
    top, how = _max_expected_loss(risk, scene)
    if risk.loss_per_second > 0.0:
        return math.inf, f"{how}, plus loss_per_second x the planned duration, which has no bound"
    return top, how


register_ordering(
    Ordering(
        "weighted_sum",
        lambda t: t.weighted_sum,
        _max_weighted_sum,
        "the seed's weighted sum of the per-mode scores",
        key="weighted_sum",
        label="seed sum",
    )
)
register_ordering(
    Ordering(
        "probability",
        lambda t: t.probability,
        _max_probability,
        "the probability of any failure",
        key="combined",
        label="P(any)",
    )
)
register_ordering(
    Ordering(
        "expected_loss",
        lambda t: t.expected_loss,
        _max_expected_loss,
        "the sum over modes of probability x severity",
        lambda p, sev, t: np.asarray(sev @ p),
        key="expected_loss",
        label="exp. loss",
    )
)
register_ordering(
    Ordering(
        "loss_and_time",
        lambda t: t.expected_loss + t.time_loss,
        _max_loss_and_time,
        "the expected loss plus risk.loss_per_second x the planned duration",
        lambda p, sev, t: np.asarray(sev @ p + t),
        key="loss_and_time",
        label="loss+time",
    )
)
