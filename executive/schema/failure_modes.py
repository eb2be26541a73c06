"""The failure modes: one table that everything listing a mode reads.

A failure mode is a way an alternative can fail that a risk model predicts and a
detector or behaviour observes: ``collision``, ``fall`` (its verdicts: ``fall``,
``unstable``, ``slip``), ``drop`` and ``tracking``. Each :class:`FailureMode` says which
detector and behaviour verdicts count as it, its severity and seed weight defaults (the
scenario's ``risk.severity`` and ``risk.weights`` keys are the mode's name), whether it ends
a task at once, and its labels in tables. Verdicts that are no risk mode (a timeout, a task's
own goal not met, a guard's stop, a defect) are :class:`Outcome` rows of the same table, so
every verdict lands somewhere explicit.

Adding a mode is one :func:`register_mode` call plus its risk model
(:func:`executive.decision.risk_models.register_model`) and, if physics can observe it,
a detector check that returns its verdict::

    register_mode(FailureMode("spill", "spill", "spill", verdicts=("spill",), severity=5.0))
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from executive.errors import ExecutiveError

__all__ = [
    "FailureMode",
    "Outcome",
    "ScenarioDeprecationWarning",
    "canonical_mode",
    "failure_mode",
    "failure_modes",
    "mode_names",
    "mode_of_verdict",
    "outcome",
    "outcomes",
    "register_mode",
    "unregister_mode",
    "verdict_names",
]


class ScenarioDeprecationWarning(FutureWarning):
    """A scenario key that still reads but has a new name (shown to users by default)."""


@dataclass(frozen=True)
class FailureMode:
    """One predicted failure mode.

    name: the one name in reports, YAML keys (``risk.severity``, ``risk.weights``) and logs.
    label: a column heading (at most 10 characters); abbreviation: at most 6, for wide tables.
    verdicts: the detector and behaviour verdicts that count as this mode.
    severity, weight: defaults of ``risk.severity.<name>`` and ``risk.weights.<name>``.
    seed_max: the largest seed score of the mode's model (for the weighted sum's range);
        None: the collision metric's, which depends on its peak and exposure weights.
    per_body: the severity depends on the bodies involved (an obstacle's own severity, the
        factor of the robot's body part: ``risk.severity.body_parts``).
    terminal: a failure of this mode ends the task at once (nothing is re-tried).
    aliases: old names, still read from YAML with a :class:`ScenarioDeprecationWarning`.
    """

    name: str
    label: str
    abbreviation: str
    verdicts: tuple[str, ...]
    severity: float
    weight: float = 1.0
    seed_max: float | None = 1.0
    per_body: bool = False
    terminal: bool = False
    aliases: tuple[str, ...] = ()
    description: str = ""


@dataclass(frozen=True)
class Outcome:
    """A verdict that is no risk mode: reported and counted, predicted by no model."""

    name: str
    abbreviation: str
    description: str


_MODES: dict[str, FailureMode] = {}
_OUTCOMES: dict[str, Outcome] = {}


def register_mode(mode: FailureMode) -> None:
    """Add ``mode`` to the table (after the modes already there).

    Raises:
        ExecutiveError: the name, an alias or a verdict is taken already.
    """
    taken = {v for m in _MODES.values() for v in (m.name, *m.aliases, *m.verdicts)} | set(_OUTCOMES)
    clash = sorted(taken & {mode.name, *mode.aliases, *mode.verdicts})
    if clash:
        raise ExecutiveError(f"failure mode '{mode.name}': {', '.join(clash)} already named in the table")
    _MODES[mode.name] = mode


def unregister_mode(name: str) -> None:
    """Remove a mode added by :func:`register_mode` (tests, plug-ins unloading)."""
    failure_mode(name)
    del _MODES[name]


def _register_outcome(o: Outcome) -> None:
    _OUTCOMES[o.name] = o


def failure_modes() -> tuple[FailureMode, ...]:
    """Every failure mode, in table order."""
    return tuple(_MODES.values())


def mode_names() -> tuple[str, ...]:
    """The modes' names, in table order."""
    return tuple(_MODES)


def failure_mode(name: str) -> FailureMode:
    """The mode called ``name``.

    Raises:
        ExecutiveError: no such mode (the message lists the valid names).
    """
    try:
        return _MODES[name]
    except KeyError:
        raise ExecutiveError(f"unknown failure mode '{name}'; valid: {', '.join(_MODES)}") from None


def canonical_mode(name: str, where: str = "") -> str | None:
    """The mode's name for ``name`` or one of its old names (warning for an old one); None if neither."""
    if name in _MODES:
        return name
    for mode in _MODES.values():
        if name in mode.aliases:
            at = f"{where}: " if where else ""
            warnings.warn(
                f"{at}'{name}' is the old name of the failure mode '{mode.name}'; write '{mode.name}'",
                ScenarioDeprecationWarning,
                stacklevel=2,
            )
            return mode.name
    return None


def outcomes() -> tuple[Outcome, ...]:
    """Every verdict that is no risk mode, in table order."""
    return tuple(_OUTCOMES.values())


def outcome(name: str) -> Outcome:
    """The non-risk outcome called ``name`` (raises :class:`ExecutiveError` listing the valid ones)."""
    try:
        return _OUTCOMES[name]
    except KeyError:
        raise ExecutiveError(f"unknown outcome '{name}'; valid: {', '.join(_OUTCOMES)}") from None


def verdict_names() -> tuple[str, ...]:
    """Every verdict a detector or behaviour may return: the modes' verdicts, then the outcomes."""
    return (*(v for m in _MODES.values() for v in m.verdicts), *_OUTCOMES)


def mode_of_verdict(verdict: str) -> str | None:
    """The mode ``verdict`` counts as, or None for a non-risk outcome.

    Raises:
        ExecutiveError: ``verdict`` is in neither the modes nor the outcomes.
    """
    for mode in _MODES.values():
        if verdict in mode.verdicts:
            return mode.name
    if verdict in _OUTCOMES:
        return None
    raise ExecutiveError(f"unknown verdict '{verdict}'; valid: {', '.join(verdict_names())}")


register_mode(
    FailureMode(
        "collision",
        "collision",
        "coll.",
        verdicts=("collision",),
        severity=3.0,
        weight=1.0,
        seed_max=None,
        per_body=True,
        description="a robot or carried body touches something it should not",
    )
)
register_mode(
    FailureMode(
        "fall",
        "fall",
        "fall",
        verdicts=("fall", "unstable", "slip"),
        severity=10.0,
        weight=2.0,
        terminal=True,
        description=(
            "the robot falls, a foot it stands on slips, or its simulation blows up "
            "(unstable: no longer controlled)"
        ),
    )
)
register_mode(
    FailureMode(
        "drop",
        "drop",
        "drop",
        verdicts=("drop",),
        severity=2.0,
        weight=1.0,
        aliases=("grasp",),
        description="the object is not grasped, slips from the hand, falls, or is set down off its target",
    )
)
register_mode(
    FailureMode(
        "tracking",
        "tracking",
        "track",
        verdicts=("tracking",),
        severity=1.0,
        weight=1.0,
        description="a hand ends a move (or a foot a step) farther from its planned end than the move allows",
    )
)
_register_outcome(
    Outcome("guard", "guard", "a live guard stopped the motion before a limit was crossed (the robot holds)")
)
_register_outcome(Outcome("task", "task", "the task's own goal was not met (e.g. a press's force)"))
_register_outcome(Outcome("timeout", "t/o", "not finished in the time limit"))
_register_outcome(Outcome("error", "error", "the physics run's code raised (a defect)"))
