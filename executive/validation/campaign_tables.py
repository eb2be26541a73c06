"""A campaign's tables and figure: predicted risk beside observed failures.

:func:`table_text` (what ``executive campaign`` prints) and :func:`table_markdown`
(``table.md``) show, per alternative, each failure mode's predicted probability and each
verdict's observed rate with the failures' 95% interval, then the scores per failure mode,
the fused and the analytic scores side by side for a campaign that decided per trial, and the
regret of the per-trial choice; their columns come from the failure-mode table.
:func:`reliability_figure` draws ``reliability.png``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from executive.schema.failure_modes import failure_mode, failure_modes, mode_names, mode_of_verdict, outcome
from executive.validation.campaign_scoring import observed_outcomes, reliability_curves, scored_trials

__all__ = ["reliability_figure", "table_markdown", "table_text"]


def _breach_lines(summary: dict[str, Any]) -> list[str]:
    """One line per executed alternative: breach touches of N, interval, predicted P(breach)."""
    names = summary.get("breach_obstacles") or []
    if not names:
        return []
    lines = [f"breach touches (category breach: {', '.join(names)}):"]
    for a in summary["alternatives"]:
        b = a.get("breach")
        if b and b["trials"]:
            lines.append(
                f"  {a['name']}: {b['touches']} of {b['trials']}, 95% CI {_ci(b['rate'])}%, "
                f"predicted P(breach) {b['predicted']:.4f}"
            )
    return lines


def _pct(rate: dict[str, Any]) -> str:
    value = rate["value"]
    return "-" if value is None else f"{100 * value:.0f}%"


def _ci(rate: dict[str, Any]) -> str:
    low, high = rate["ci95"]
    return f"[{100 * low:.0f}, {100 * high:.0f}]"


def _num(x: float | None, fmt: str = ".3f") -> str:
    return "-" if x is None else format(x, fmt)


def _columns() -> tuple[tuple[str, str, int], ...]:
    """The per-alternative columns both tables show: (text header, markdown header, text width),
    from the failure-mode table: each mode's prediction, then each verdict's observed rate."""
    modes, outcomes_ = failure_modes(), observed_outcomes()
    return (
        ("alternative", "alternative", -15),
        ("trials", "trials", 7),
        *((f"P({m.abbreviation})", f"P({m.name})", 9) for m in modes),
        ("P(any)", "P(any)", 9),
        ("exp.loss", "expected loss", 9),
        *((_abbreviation(v), v, 6) for v in outcomes_),
        ("any", "any failure", 6),
        ("95% CI", "95% CI", 10),
    )


def _abbreviation(verdict: str) -> str:
    """A verdict's short column header: its mode's (its own if it names the mode), or the outcome's."""
    mode = mode_of_verdict(verdict)
    if mode is None:
        return outcome(verdict).abbreviation
    return failure_mode(mode).abbreviation if verdict == mode else verdict[:4] + "."


def _cells(a: dict[str, Any]) -> list[str]:
    """One alternative's row of :func:`_columns` (an infeasible one: why, in the third cell)."""
    if not a["trials"]:
        return [a["name"], "0", f"infeasible: {a['error'][:80]}"]
    p, f = a["predicted"], a["failure_rate_by_mode"]
    predicted = [f"{p[k]:.4f}" if k in p else "-" for k in (*mode_names(), "combined", "expected_loss")]
    observed = [_pct(f[m]) for m in observed_outcomes()]
    return [
        a["name"],
        str(a["trials"]),
        *predicted,
        *observed,
        _pct(a["failure_rate"]),
        _ci(a["failure_rate"]),
    ]


def _text_row(cells: Sequence[str]) -> str:
    return "".join(
        f" {c:>{w}}" if w > 0 else f"{c:<{-w}}" for c, (_, _, w) in zip(cells, _columns(), strict=False)
    )


def table_text(summary: dict[str, Any]) -> str:
    """Predicted risk and observed failures per alternative, then the scores per failure mode."""
    lines = [
        f"predicted ({summary.get('predictions', 'on the estimate')})  vs  observed (detectors, in physics)",
        _text_row([c[0] for c in _columns()]),
    ]
    lines += [_text_row(_cells(a)) for a in summary["alternatives"]]
    auc, b, e = summary["auc"], summary["brier"], summary["ece"]
    lines.append(
        "AUC    " + "  ".join(f"{m} {_num(auc[m])} ({summary['observed_failures'][m]} observed)" for m in auc)
    )
    ceiling = summary["auc_ceiling_per_alternative"]
    lines.append(
        "       best AUC of any prediction constant per alternative: "
        + "  ".join(f"{m} {_num(ceiling[m])}" for m in ceiling)
    )
    lines.append("Brier  " + "  ".join(f"{m} {_num(b[m], '.4f')}" for m in b))
    lines.append("ECE    " + "  ".join(f"{m} {_num(e[m], '.4f')}" for m in e))
    lines.append(
        f"Spearman (predicted {summary['ordering']} vs observed failure rate, per alternative): "
        f"{_num(summary['spearman'], '.2f')}"
    )
    return "\n".join(lines + _breach_lines(summary) + _decision_lines(summary) + _regret_lines(summary))


def _decision_lines(summary: dict[str, Any]) -> list[str]:
    """A campaign that decides per trial: the fused and the analytic predictions, per failure
    mode, on the same trials (events, ROC AUC, ECE, Brier)."""
    d = summary.get("decision")
    if not d:
        return []
    lines = [
        f"fused vs analytic on the same {d['trials']} trials ({d['decisions']} decisions; "
        f"{d['dry_run_failed']} executed trials left out: their dry run failed; "
        f"{d['above_threshold']} decisions chose above the threshold):",
        f"{'mode':<10}{'events':>7}   AUC fused  analytic   ECE fused  analytic   Brier fused  analytic",
    ]
    for mode, f in d["fused"].items():
        a = d["analytic"][mode]
        lines.append(
            f"{mode:<10}{f['events']:>7}   {_num(f['auc']):>9} {_num(a['auc']):>9}"
            f"   {_num(f['ece'], '.4f'):>9} {_num(a['ece'], '.4f'):>9}"
            f"   {_num(f['brier'], '.4f'):>11} {_num(a['brier'], '.4f'):>9}"
        )
    return lines


def _regret_lines(summary: dict[str, Any]) -> list[str]:
    """The regret of the per-trial choice (and of the analytic models' choice, when rollouts were fused)."""
    regrets = summary.get("regret") or {}
    decided = bool(summary.get("decision"))
    labels = {
        "choice": "the executive's choice per trial"
        if decided
        else "choosing per trial by the predicted value",
        "analytic": "choosing by the analytic value alone",
    }
    lines = []
    for key, label in labels.items():
        r = regrets.get(key)
        if not r:
            continue
        if r["regret"] is None:
            lines.append(f"regret of {label}: none ({r['trials']} comparable trials)")
            continue
        low, high = r["ci95"]
        chosen = ", ".join(f"{a} {n}" for a, n in r["chosen"].items() if n)
        lines.append(
            f"regret of {label}: {r['regret']:+.3f} [{low:+.2f}, {high:+.2f}], p {r['p_value']:.2f} "
            f"(cross-fitted; failed {r['choice_failures']} vs best fixed {r['best_failures']} of "
            f"{r['trials']}; chosen {chosen})"
        )
    return lines


def table_markdown(summary: dict[str, Any]) -> str:
    """:func:`table_text` as markdown tables (for a README or a report)."""
    columns = _columns()
    rows = [
        "| " + " | ".join(c[1] for c in columns) + " |",
        "|---|" + "---:|" * (len(columns) - 1),
    ]
    for a in summary["alternatives"]:
        cells = _cells(a)
        rows.append("| " + " | ".join(cells + [""] * (len(columns) - len(cells))) + " |")
    auc, b, e = summary["auc"], summary["brier"], summary["ece"]
    rows.append("")
    ceiling = summary["auc_ceiling_per_alternative"]
    rows.append(
        "| failure mode | predicted by | observed | ROC AUC | best AUC if constant per alternative "
        "| Brier | ECE |"
    )
    rows.append("|---|---|---:|---:|---:|---:|---:|")
    for m in auc:
        rows.append(
            f"| {m} | P({summary['predictor'][m]}) | {summary['observed_failures'][m]} | {_num(auc[m])} "
            f"| {_num(ceiling[m])} | {_num(b[m], '.4f')} | {_num(e[m], '.4f')} |"
        )
    rows.append("")
    rows.append(
        f"Spearman rank correlation, predicted {summary['ordering']} vs observed failure rate "
        f"across alternatives: {_num(summary['spearman'], '.2f')}"
    )
    breach = _breach_lines(summary)
    if breach:
        rows += ["", breach[0], ""] + [f"- {line.strip()}" for line in breach[1:]]
    rows += ["", f"Predictions: {summary.get('predictions', 'on the estimate')}."]
    rows += _decision_markdown(summary)
    rows += ["", *(f"- {line}" for line in _regret_lines(summary))]
    return "\n".join(rows)


def _decision_markdown(summary: dict[str, Any]) -> list[str]:
    """:func:`_decision_lines` as a markdown table."""
    d = summary.get("decision")
    if not d:
        return []
    rows = [
        "",
        f"Fused vs analytic predictions on the same {d['trials']} trials ({d['decisions']} decisions; "
        f"{d['dry_run_failed']} executed trials left out: their dry run failed; {d['above_threshold']} "
        "decisions chose above the threshold):",
        "",
        "| failure mode | events | ROC AUC fused | ROC AUC analytic | AUC ceiling | ECE fused | ECE analytic "
        "| Brier fused | Brier analytic |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for mode, f in d["fused"].items():
        a = d["analytic"][mode]
        rows.append(
            f"| {mode} | {f['events']} | {_num(f['auc'])} | {_num(a['auc'])} | {_num(f['auc_ceiling'])} "
            f"| {_num(f['ece'], '.4f')} | {_num(a['ece'], '.4f')} | {_num(f['brier'], '.4f')} "
            f"| {_num(a['brier'], '.4f')} |"
        )
    return rows


def reliability_figure(records: Sequence[dict[str, Any]], path: Path) -> Path:
    """The reliability diagram of the trials executed among ``records``, written (atomically)
    to ``path``; returns ``path``."""
    from executive.decision.audit import atomic_replace
    from executive.validation.stats import reliability_diagram

    curves = reliability_curves(scored_trials(records))
    return atomic_replace(path, lambda tmp: reliability_diagram(curves, tmp))
