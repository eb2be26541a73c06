"""Fusing the analytic risk with what physics rollouts observed, and when to stop rolling out.

Per failure mode, the analytic probability ``p_a`` is a Beta prior of weight ``w``
(``Beta(w p_a, w (1 - p_a))``: it counts as ``w`` pseudo-trials) and ``k`` failures of that
mode in ``n`` rollouts update it to ``Beta(w p_a + k, w (1 - p_a) + n - k)``, whose mean
``(w p_a + k) / (w + n)`` is the fused probability (conjugate Beta-binomial update; Gelman
et al., *Bayesian Data Analysis*, 3rd ed., section 2.4). The combined risk is then made from
the fused modes exactly as from analytic ones (:func:`executive.risk.combine.combine`).

The stopping rule (:func:`choice_confidence`) is a Bayesian indifference-zone rule: rolling
out stops when the posterior probability that the alternative with the lowest posterior mean
value is within ``indifference`` of the truly lowest reaches ``confidence``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from executive.risk.combine import CombinedRisk, combine
from executive.risk.orderings import ordering as ordering_named
from executive.schema.failure_modes import failure_mode, mode_names
from executive.schema.types import RiskConfig

__all__ = [
    "Choice",
    "Contention",
    "ModePosterior",
    "choice_confidence",
    "contention",
    "fuse",
    "observed_as",
    "posteriors",
]


def observed_as(mode: str) -> tuple[str, ...]:
    """The rollout outcomes that count as failures of ``mode``: its verdicts in the failure-mode
    table (:mod:`executive.schema.failure_modes`; a fall's include ``unstable``). Outcomes that are
    no risk mode (``timeout``, ``task``, ``tracking``, ``guard``) count in none."""
    return failure_mode(mode).verdicts if mode in mode_names() else ()


@dataclass(frozen=True)
class ModePosterior:
    """The Beta posterior of one failure mode's probability: ``Beta(a, b)``, and its cost."""

    mode: str
    a: float
    b: float
    severity: float  # expected loss per unit of probability (the analytic report's)
    failures: int = 0  # rollouts that failed in this mode
    rollouts: int = 0  # rollouts counted for this mode (0 for a mode physics does not observe)

    @property
    def mean(self) -> float:
        return self.a / (self.a + self.b)

    def interval(self, confidence: float) -> tuple[float, float]:
        """Equal-tailed credible interval at ``confidence``."""
        from scipy import stats  # here: 0.3 s to import, and rollout processes never need it

        tail = (1.0 - confidence) / 2.0
        a, b = max(self.a, 1e-12), max(self.b, 1e-12)
        return float(stats.beta.ppf(tail, a, b)), float(stats.beta.ppf(1.0 - tail, a, b))


def posteriors(
    analytic: CombinedRisk, counts: Mapping[str, int], n: int, prior_weight: float
) -> list[ModePosterior]:
    """Per analytic mode, the posterior after ``counts`` (outcome -> rollouts) of ``n`` rollouts.

    Modes with no observed counterpart (no verdicts: :func:`observed_as`) keep the analytic value
    (``n`` counts as 0 for them).
    """
    out = []
    for mode, report in analytic.components.items():
        p = report.probability
        observed = observed_as(mode)
        k = sum(counts.get(o, 0) for o in observed) if observed else 0
        trials = n if observed else 0
        if prior_weight + trials == 0:  # no prior and no data: the analytic value as a point mass
            a, b = (p, 1.0 - p)
        else:
            a, b = prior_weight * p + k, prior_weight * (1.0 - p) + trials - k
        out.append(ModePosterior(mode, a, b, report.severity, k, trials))
    return out


def fuse(
    analytic: CombinedRisk,
    counts: Mapping[str, int],
    n: int,
    prior_weight: float,
    confidence: float,
    config: RiskConfig,
) -> CombinedRisk:
    """The combined risk made of the fused (posterior mean) probability of every mode.

    Each report keeps its severity and traces; its bounds become the posterior's credible
    interval and its details say what was fused (``analytic``, ``rollouts``, ``failures``).
    """
    reports = []
    for post in posteriors(analytic, counts, n, prior_weight):
        report = analytic.components[post.mode]
        details = {
            **report.details,
            "analytic": report.probability,
            "rollouts": post.rollouts,
            "failures": post.failures,
        }
        reports.append(
            dataclasses.replace(
                report,
                probability=post.mean,
                probability_bounds=post.interval(confidence),
                details=details,
            )
        )
    return combine(reports, config, analytic.duration_s)


def _values(
    post: Sequence[ModePosterior], ordering: str, draws: int, rng: np.random.Generator, offset: float
) -> np.ndarray:
    """``draws`` samples of the ordering value from independent mode posteriors (the ordering's
    :attr:`~executive.risk.orderings.Ordering.sample`; ``offset``: the alternative's time loss)."""
    p = np.stack([rng.beta(max(m.a, 1e-12), max(m.b, 1e-12), draws) for m in post])
    return np.asarray(ordering_named(ordering).sample(p, np.array([m.severity for m in post]), offset))


class Choice(NamedTuple):
    """The stopping rule's view of a decision under the posterior."""

    best: str  # the alternative with the lowest posterior mean value
    confidence: float  # P(best is within the indifference of the truly lowest)
    opportunity_cost: float  # E[value(best) - min over alternatives]: what choosing it costs on average


class Contention(NamedTuple):
    """The stopping rule's view of a decision and what keeps it open, per alternative."""

    choice: Choice
    rivals: Mapping[str, float]  # P(its value is below best's by more than the indifference); best: 0
    above_threshold: float  # P(best's value is above the threshold: its approval is asked)


def choice_confidence(
    candidates: Mapping[str, Sequence[ModePosterior]],
    ordering: str,
    indifference: float,
    *,
    draws: int = 4000,
    seed: int = 0,
    offsets: Mapping[str, float] | None = None,
) -> Choice:
    """The current choice under the posterior: its confidence and expected opportunity cost.

    The expected opportunity cost is Chick & Inoue's (Operations Research 49(5), 2001): the
    loss expected from choosing ``best`` instead of the alternative that is truly lowest. Both
    are estimated from ``draws`` joint posterior samples (seeded). The seed's weighted sum is
    no probability; with ``ordering == "weighted_sum"`` the rule judges the probability of any
    failure instead. ``offsets``: per alternative, a known part of its value (its time loss).

    Raises:
        ValueError: no candidates.
    """
    names, samples = _joint_draws(candidates, ordering, draws, seed, offsets)
    return _choice_of(names, samples, indifference)


def contention(
    candidates: Mapping[str, Sequence[ModePosterior]],
    ordering: str,
    indifference: float,
    threshold: float,
    *,
    draws: int = 4000,
    seed: int = 0,
    offsets: Mapping[str, float] | None = None,
) -> Contention:
    """:func:`choice_confidence` (the same draws, the same numbers) with, per alternative, its
    chance of beating the best by more than ``indifference``, and the chance that the best's
    value is above ``threshold``: what a sequential allocation of rollouts spends them on
    (:mod:`executive.decision.rollout_allocation`). With ``ordering == "weighted_sum"`` the
    value sampled is the probability of any failure, as for the stopping rule.

    Raises:
        ValueError: no candidates.
    """
    names, samples = _joint_draws(candidates, ordering, draws, seed, offsets)
    choice = _choice_of(names, samples, indifference)
    best = samples[names.index(choice.best)]
    rivals = {name: float((samples[i] < best - indifference).mean()) for i, name in enumerate(names)}
    return Contention(choice, rivals, float((best > threshold).mean()))


def _joint_draws(
    candidates: Mapping[str, Sequence[ModePosterior]],
    ordering: str,
    draws: int,
    seed: int,
    offsets: Mapping[str, float] | None,
) -> tuple[list[str], np.ndarray]:
    """The alternatives' names and ``draws`` seeded samples of each one's value (rows)."""
    if not candidates:
        raise ValueError("choice_confidence needs at least one alternative")
    rng = np.random.default_rng(seed)
    names = list(candidates)
    off = offsets or {}
    samples = np.stack(
        [_values(candidates[name], ordering, draws, rng, off.get(name, 0.0)) for name in names]
    )
    return names, samples


def _choice_of(names: Sequence[str], samples: np.ndarray, indifference: float) -> Choice:
    best = int(np.argmin(samples.mean(axis=1)))
    shortfall = samples[best] - samples.min(axis=0)
    return Choice(names[best], float((shortfall <= indifference).mean()), float(shortfall.mean()))
