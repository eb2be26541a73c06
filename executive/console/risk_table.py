"""The risk of a task's alternatives as the console shows it: markdown tables from decision rows.

A row is what the audit log's ``plan`` line holds (:func:`executive.decision.selector.risk_row`):
``name``, ``feasible``, ``risk`` (per mode probability, ``combined`` with its bounds,
``weighted_sum``, ``expected_loss``), ``value`` (the ordering quantity), ``physics`` (the dry run
and, when rollouts ran, per mode the analytic probability, the failures, the fused value and
its interval) and ``reason`` (why infeasible). The same rows come from a live selector and from
a run folder, so a run's page and a replay's read alike.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from executive.risk.orderings import ordering as ordering_named
from executive.risk.orderings import ordering_names
from executive.schema.failure_modes import failure_modes, mode_names

__all__ = ["number", "physics_table", "ranked", "risk_table", "verdict_line"]


def number(value: float | None) -> str:
    """A probability or loss for people: 4 significant digits, tiny values in exponent form."""
    if value is None:
        return "-"
    if value != 0 and abs(value) < 1e-6:
        return "≈0"
    if value != 0 and abs(value) < 1e-4:
        return f"{value:.1e}"
    return f"{value:.4g}"


def _short(value: float) -> str:
    """A probability in 2 significant digits (the intervals of a few rollouts are wide)."""
    return "≈0" if abs(value) < 1e-6 else f"{value:.2g}"


def ranked(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Feasible rows lowest value first, then the infeasible ones in their order."""
    feasible = sorted((r for r in rows if r.get("value") is not None), key=lambda r: float(r["value"]))
    return [*feasible, *(r for r in rows if r.get("value") is None)]


def verdict_line(rows: Sequence[Mapping[str, Any]], ordering: str, threshold: float) -> str:
    """What the ranking means: the lowest alternative, and whether it needs approval."""
    order = ranked(rows)
    if not order or order[0].get("value") is None:
        return "**no feasible alternative**"
    best = order[0]
    value = float(best["value"])
    if value > threshold:
        return (
            f"**{best['name']}** is lowest ({ordering} {number(value)}) but **above the threshold "
            f"{threshold:g}: it needs approval**"
        )
    return f"**{best['name']}** is lowest ({ordering} {number(value)}), within the threshold {threshold:g}"


def risk_table(rows: Sequence[Mapping[str, Any]], ordering: str, threshold: float) -> str:
    """Markdown: one line per alternative, ranked, with each failure mode's probability.

    Columns: rank, alternative, each failure mode's (executive.schema.failure_modes), P(any), expected loss,
    and the ordering's own value when it is another (the seed's weighted sum, loss and time;
    :mod:`executive.risk.orderings`); the ordering's column is marked ``!`` where it is above
    the threshold. Infeasible alternatives follow with their reason.
    """
    keys = [*mode_names(), "combined", "expected_loss"]
    heads = [*(m.label for m in failure_modes()), "P(any)", "exp. loss"]
    ranked_key = ordering_named(ordering).key if ordering in ordering_names() else ""
    if ranked_key and ranked_key not in keys:
        keys.append(ranked_key)
        heads.append(ordering_named(ordering).label)
    lines = ["| # | alternative | " + " | ".join(heads) + " |", "|---|---|" + "---|" * len(heads)]
    for i, row in enumerate(ranked(rows), 1):
        risk = row.get("risk")
        if row.get("value") is None or not risk:
            reason = str(row.get("reason") or "infeasible").replace("|", "/")
            lines.append(f"| - | {row['name']} | infeasible: {reason} |" + " |" * (len(heads) - 1))
            continue
        above = float(row["value"]) > threshold
        cells = [number(risk.get(k)) + (" !" if k == ranked_key and above else "") for k in keys]
        lines.append(f"| {i} | **{row['name']}** | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        f"ranked by {ordering}; threshold **{threshold:g}**; {verdict_line(rows, ordering, threshold)}"
    )
    return "\n".join(lines)


def physics_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown: what physics said per alternative: the dry run, and with rollouts the failures
    counted and per mode ``analytic → fused [credible interval]`` (``analytic → dry run → fused``
    for a mode the dry run refines). Empty without a check."""
    checked = [r for r in ranked(rows) if r.get("physics")]
    if not checked:
        return ""
    with_rollouts = any(r["physics"].get("modes") for r in checked)
    head = "| alternative | dry run | rollouts |"
    if with_rollouts:
        head += "".join(f" {m.label} |" for m in failure_modes())
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for row in checked:
        physics = row["physics"]
        dry = physics.get("dry_run", {})
        outcome = str(dry.get("outcome", "-"))
        n = int(physics.get("rollouts", 0))
        failures = {k: v for k, v in physics.get("outcomes", {}).items() if k != "success"}
        rolled = (
            f"{n}: " + (", ".join(f"{v} {k}" for k, v in sorted(failures.items())) or "no failure")
            if n
            else "-"
        )
        line = f"| {row['name']} | {outcome} | {rolled} |"
        if with_rollouts:
            modes = physics.get("modes", {})
            line += "".join(f" {_mode_cell(modes.get(m))} |" for m in mode_names())
        lines.append(line)
    return "\n".join(lines)


def _mode_cell(v: Mapping[str, Any] | None) -> str:
    """One mode's ``analytic → [dry run →] fused [interval]`` (``-``: not checked)."""
    if not v:
        return "-"
    cell = _short(v["analytic"])
    if "measured" in v:
        cell += f" → {_short(v['measured'])}"
    if "fused" in v:
        cell += f" → {_short(v['fused'])} [{_short(v['interval'][0])}, {_short(v['interval'][1])}]"
    return cell
