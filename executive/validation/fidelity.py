"""Fidelity suites: does the risk ranking hold on scenes nobody tuned for?

``executive fidelity SCENARIO --variants K --trials N`` draws K seeded variants of the
scenario's scene (:mod:`executive.validation.variants`: object yaw, mass, size and friction,
object/obstacle/target positions, table height, within the family's ranges,
:mod:`executive.validation.variation_ranges`), writes each as a YAML file in the
suite folder, runs a validation campaign of one task on each
(:func:`executive.validation.campaign.run_campaign`, N trials per alternative on sampled
truths; ``--task N``, default 0) and reports:

* per variant and alternative: the mean predicted value (the number the selector ranks
  by) and P(any failure), against the observed failure rate with its 95% Clopper-Pearson
  interval; Spearman's rank correlation of the two across the alternatives; and the
  regret of choosing per trial by the predicted value against the best fixed alternative
  on the same truths, cross-fitted, with Newcombe's interval and the exact sign test
  (:mod:`executive.validation.regret`);
* pooled over every variant and trial, per failure mode: ROC AUC, Brier score, ECE, the
  number of events and a reliability diagram; the mean regret over the variants and how
  many are significantly above (or below) zero; the wall time.

Suite folder: ``suite.json`` (the configuration, checked by ``--resume``),
``variant-KK.yaml`` and ``variant-KK/`` (the campaign's run folder, its output in
``campaign.log``) per variant, and ``summary.json`` (written atomically), ``table.md``,
``reliability.png``. ``--resume`` completes an interrupted suite (or extends it to more
variants or trials): every campaign resumes where it stopped.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from executive.decision.audit import atomic_write_text, read_resume_settings
from executive.errors import ExecutiveError
from executive.schema.types import Scenario
from executive.validation.campaign_scoring import (
    analytic_view,
    executed_trials,
    finite,
    pooled_statistics,
    reliability_curves,
)
from executive.validation.variation_ranges import VariationRanges

if TYPE_CHECKING:
    from executive.validation.variants import Variant

__all__ = [
    "FidelityResult",
    "check_folder",
    "pooled_statistics",
    "run_fidelity",
    "table_markdown",
    "table_text",
    "variant_statistics",
]


@dataclass
class FidelityResult:
    """A suite's folder, summary and whether it finished (``interrupted``: stopped by Ctrl-C)."""

    folder: Path
    summary: dict[str, Any]
    interrupted: bool = False


def check_folder(folder: Path) -> None:
    """Create ``folder`` and check a file can be written in it.

    Raises:
        ExecutiveError: it cannot be created or written to.
    """
    probe = folder / ".write-test"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe.write_text("", encoding="utf-8")
        probe.unlink()
    except OSError as exc:
        raise ExecutiveError(f"--out {folder}: cannot write there ({exc.strerror or exc})") from None


def _sha256(path: Path | None) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path is not None and path.is_file() else None


def _prepare(folder: Path, config: dict[str, Any], resume: bool) -> None:
    """Write (or, with ``resume``, check) the suite's ``suite.json``."""
    path = folder / "suite.json"
    if resume:
        keys = (
            "scenario",
            "scenario_sha256",
            "seed",
            "rollouts",
            "task",
            "ranges",
            *(("decide",) if config["decide"] else ()),
        )
        how = "the same scenario, --seed, --rollouts, --task, ranges and --decide"
        read_resume_settings(folder, "suite.json", config, keys, "a fidelity suite", how)
    elif path.is_file():
        raise ExecutiveError(
            f"{folder} already holds a fidelity suite: add --resume to complete it, or choose another --out"
        )
    check_folder(folder)
    atomic_write_text(path, json.dumps(config, indent=2) + "\n")


def run_fidelity(
    scenario: Scenario,
    *,
    variants: int,
    trials: int,
    jobs: int = 1,
    out: Path | str | None = None,
    seed: int | None = None,
    rollouts: int | None = None,
    resume: bool = False,
    stream: IO[str] | None = None,
    decide: bool = False,
    task_index: int = 0,
    ranges: Path | str | None = None,
) -> FidelityResult:
    """Run (or, with ``resume``, complete) a fidelity suite of ``scenario``.

    Args:
        scenario: the scenario to vary (loaded from a YAML file).
        variants: how many variants K (>= 1).
        trials: trials per alternative and variant N (>= 1).
        jobs: worker processes of each campaign.
        out: the suite folder (default ``runs/<stamp>-<scenario>-fidelity``).
        seed: seed of the variants' generators (default: the scenario's ``trials.seed``).
        rollouts: ``risk.rollouts.count`` of every variant (0: off; None: the scenario's when
            deciding, else 0).
        resume: complete the suite in ``out``.
        stream: where progress goes (default stdout).
        decide: every campaign decides per trial as the executive does
            (:func:`executive.validation.campaign.run_campaign`'s ``decide``).
        task_index: the mission's task each campaign runs (alone, from the variant's scene).
        ranges: a variation ranges file (default: the family's beside the scenario,
            :func:`executive.validation.variation_ranges.family_ranges_path`, else the defaults).

    Returns:
        The suite's folder and summary (also in ``summary.json``).

    Raises:
        ExecutiveError: bad arguments, an unwritable or already used folder, a scene
            with no valid variant, a malformed ranges file (naming its key).
    """
    from executive.decision.audit import run_folder
    from executive.validation.variants import base_document
    from executive.validation.variation_ranges import family_ranges_path, load_ranges

    rollouts = _check_arguments(scenario, variants, trials, jobs, rollouts, decide, task_index)
    ranges_path = Path(ranges) if ranges is not None else family_ranges_path(scenario.source)
    drawn_from = load_ranges(ranges_path) if ranges_path is not None else None
    if out is None and resume:
        raise ExecutiveError("--resume needs --out DIR: the folder of the suite to complete")
    folder = Path(out) if out is not None else run_folder(f"{scenario.name}-fidelity")
    base_seed = scenario.trials.seed if seed is None else seed
    config = {
        "scenario": scenario.name,
        "source": str(scenario.source) if scenario.source else None,
        "scenario_sha256": _sha256(scenario.source),
        "seed": base_seed,
        "rollouts": rollouts,
        "decide": decide,
        "variants": variants,
        "trials": trials,
        "task": task_index,
        "ranges_file": str(ranges_path) if ranges_path is not None else None,
        "ranges": (drawn_from or VariationRanges()).as_dict(),
    }
    document = base_document(scenario)
    _prepare(folder, config, resume)
    log = _logger(stream)
    task = scenario.mission[task_index]
    log(
        f"fidelity {scenario.name}, task {task_index} ({task.label()}), ranges "
        f"{ranges_path or 'default'}: {variants} variant(s) x {trials} trial(s) x {len(task.alternatives)} "
        f"alternatives ({', '.join(task.alternatives)}), seed {base_seed}, rollouts "
        f"{rollouts or 'off'}{', each trial decides' if decide else ''}, {jobs} job(s); suite folder {folder}"
    )
    return _run_variants(scenario, document, folder, config, jobs, log, drawn_from)


def _check_arguments(
    scenario: Scenario,
    variants: int,
    trials: int,
    jobs: int,
    rollouts: int | None,
    decide: bool,
    task_index: int,
) -> int:
    """The suite's rollouts count; ExecutiveError naming a bad count or task."""
    for name, value, least in (("--variants", variants, 1), ("--trials", trials, 1), ("--jobs", jobs, 1)):
        if value < least:
            raise ExecutiveError(f"{name} must be at least {least}; got {value}")
    if rollouts is None:
        rollouts = scenario.risk.rollouts.count if decide else 0
    if rollouts < 0:
        raise ExecutiveError(f"--rollouts must be 0 (off) or more; got {rollouts}")
    if not 0 <= task_index < len(scenario.mission):
        raise ExecutiveError(f"--task {task_index}: {scenario.name} has tasks 0-{len(scenario.mission) - 1}")
    return rollouts


def _logger(stream: IO[str] | None) -> Callable[[str], None]:
    import sys

    out = stream if stream is not None else sys.stdout

    def log(text: str) -> None:
        out.write(text + "\n")
        out.flush()

    return log


def _run_variants(
    scenario: Scenario,
    document: dict[str, Any],
    folder: Path,
    config: dict[str, Any],
    jobs: int,
    log: Callable[[str], None],
    ranges: VariationRanges | None,
) -> FidelityResult:
    """Draw, write and run each variant's campaign; then the suite's statistics."""
    from executive.decision.physics_check import with_rollouts
    from executive.report.progress_bar import format_duration
    from executive.validation.campaign import run_campaign
    from executive.validation.variants import make_variant, write_variant

    t0 = time.perf_counter()
    k_total, n = config["variants"], config["trials"]
    task_index = config["task"]
    names = list(scenario.mission[task_index].alternatives)
    done: list[dict[str, Any]] = []
    records: list[dict[str, Any]] = []
    new_trials, campaign_s, interrupted = 0, 0.0, False
    for k in range(k_total):
        variant = make_variant(scenario, document, config["seed"], k, ranges)
        label = f"variant-{k:02d}"
        loaded = with_rollouts(write_variant(variant, folder / f"{label}.yaml"), config["rollouts"])
        sub = folder / label
        with _CampaignLog(sub) as campaign_stream:
            result = run_campaign(
                loaded,
                trials=n,
                jobs=jobs,
                out=sub,
                resume=(sub / "campaign.json").is_file(),
                stream=campaign_stream,
                decide=config["decide"],
                task_index=task_index,
            )
        new_trials += result.new_trials
        campaign_s += result.elapsed_s
        row = variant_statistics(variant, label, result.summary, result.records, names)
        row["object"] = scenario.mission[task_index].object
        done.append(row)
        records.extend({**r, "variant": k} for r in result.records)
        remaining = (k_total - k - 1) * n * len(names)
        rate = new_trials / campaign_s if campaign_s > 0 and new_trials else float("nan")
        log(
            f"{_progress_line(row, k_total)}  [{result.new_trials} new trial(s) in "
            f"{format_duration(result.elapsed_s)}; suite elapsed "
            f"{format_duration(time.perf_counter() - t0)}, "
            f"ETA {format_duration(remaining / rate if remaining else 0.0)}]"
        )
        if result.interrupted:
            interrupted = True
            break
    summary = _suite_summary(scenario, config, done, records, time.perf_counter() - t0, folder)
    summary["complete"] = not interrupted and len(done) == k_total and all(v["complete"] for v in done)
    _write_outputs(folder, summary, records)
    return FidelityResult(folder, summary, interrupted)


class _CampaignLog:
    """The campaign's own output, appended to ``campaign.log`` in its run folder."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / "campaign.log"

    def __enter__(self) -> IO[str]:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("a", encoding="utf-8")
        return self._file

    def __exit__(self, *exc: object) -> None:
        self._file.close()


# --- statistics ---------------------------------------------------------------------------------


def variant_statistics(
    variant: Variant,
    label: str,
    campaign: dict[str, Any],
    records: Sequence[dict[str, Any]],
    names: Sequence[str],
) -> dict[str, Any]:
    """One variant's row: predicted vs observed per alternative, Spearman, regret.

    Args:
        variant: the :class:`executive.validation.variants.Variant` the campaign ran on.
        label: its name in the suite folder (``variant-KK``).
        campaign: the campaign's summary (:func:`executive.validation.campaign.summarise`).
        records: the campaign's trial records.
        names: the task's alternatives.
    """
    from executive.validation.regret import regret, trial_table
    from executive.validation.stats import spearman

    alternatives = []
    for a in campaign["alternatives"]:
        p = a["predicted"] or {}
        alternatives.append(
            {
                "name": a["name"],
                "trials": a["trials"],  # executed in physics
                "infeasible": a["infeasible"],
                "errors": a["errors"],
                "predicted_value": p.get("value"),
                "predicted_combined": p.get("combined"),
                "failures": a["failures"]["any"],
                "failure_rate": a["failure_rate"]["value"],
                "ci95": a["failure_rate"]["ci95"],
                "infeasible_because": _commonest_reason(records, a["name"]),
            }
        )
    ran = [a for a in alternatives if a["trials"]]
    ranked = [a for a in ran if a["predicted_value"] is not None]  # None: its dry run failed
    rho = (
        spearman([a["predicted_value"] for a in ranked], [a["failure_rate"] for a in ranked])
        if ranked
        else math.nan
    )
    result = regret(trial_table(records, names))
    analytic = regret(trial_table(analytic_view(records), names))
    status = "ok" if result.regret is not None else ("all_infeasible" if not ran else "no_comparison")
    return {
        "index": variant.index,
        "name": variant.scenario.name,
        "yaml": f"{label}.yaml",
        "folder": label,
        "redraws": variant.redraws,
        "rejections": variant.rejections,
        "draws": variant.draws,
        "complete": bool(campaign.get("complete")),
        "alternatives": alternatives,
        "spearman": finite(rho),
        "regret": result.as_dict(),
        "regret_analytic": analytic.as_dict(),  # the same trials ranked by the analytic value alone
        "status": status,
    }


def _commonest_reason(records: Sequence[dict[str, Any]], alternative: str) -> str | None:
    """The planner's commonest reason (numbers aside) why ``alternative`` did not plan; an example."""
    import re
    from collections import Counter

    details = [
        r["failure"]["detail"]
        for r in records
        if r["alternative"] == alternative and r["outcome"] == "infeasible" and r.get("failure")
    ]
    if not details:
        return None
    shapes = Counter(re.sub(r"[-+]?\d[\d.e-]*", "#", d) for d in details)
    commonest = shapes.most_common(1)[0][0]
    return next(d for d in details if re.sub(r"[-+]?\d[\d.e-]*", "#", d) == commonest)


def _regret_overall(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean regret over the variants that have one; counts of significant ones; all trials pooled."""
    from executive.validation.regret import sign_test

    scored = [r["regret"] for r in rows if r["regret"]["regret"] is not None]
    plus = sum(r["discordant"][0] for r in scored)
    minus = sum(r["discordant"][1] for r in scored)
    trials = sum(r["trials"] for r in scored)
    return {
        "variants_scored": len(scored),
        "mean": float(np.mean([r["regret"] for r in scored])) if scored else None,
        "mean_naive": float(np.mean([r["naive_regret"] for r in scored])) if scored else None,
        "significant_above_zero": sum(r["significant_above_zero"] for r in scored),
        "significant_below_zero": sum(r["significant_below_zero"] for r in scored),
        "pooled": {
            "trials": trials,
            "regret": (plus - minus) / trials if trials else None,
            "discordant": [plus, minus],
            "p_value": sign_test(plus, minus),
        },
    }


def _suite_summary(
    scenario: Scenario,
    config: dict[str, Any],
    rows: list[dict[str, Any]],
    records: Sequence[dict[str, Any]],
    wall_s: float,
    folder: Path,
) -> dict[str, Any]:
    return {
        **config,
        "alternatives": list(scenario.mission[config["task"]].alternatives),
        "ordering": scenario.risk.ordering,
        "folder": str(folder),
        "variants_run": len(rows),
        "redraws": sum(r["redraws"] for r in rows),
        "all_infeasible_variants": sum(r["status"] == "all_infeasible" for r in rows),
        "trials_executed": sum(r["outcome"] not in ("infeasible", "error") for r in records),
        "pooled": pooled_statistics(records),
        "regret": _regret_overall(rows),
        "analytic": {  # the same trials, ranked and scored by the analytic models alone
            "pooled": pooled_statistics(analytic_view(records)),
            "regret": _regret_overall([{**r, "regret": r["regret_analytic"]} for r in rows]),
        },
        "wall_s": wall_s,
        "regret_method": "cross-fitted on even/odd trials; Newcombe (1998) interval; exact sign test, 5%",
        "per_variant": rows,
    }


def _write_outputs(folder: Path, summary: dict[str, Any], records: Sequence[dict[str, Any]]) -> None:
    from executive.decision.audit import atomic_replace, to_json, write_summary
    from executive.validation.stats import reliability_diagram

    write_summary(folder, to_json(summary))
    atomic_write_text(folder / "table.md", table_markdown(summary) + "\n")
    executed = executed_trials(records)
    if executed:
        curves = reliability_curves(executed)
        title = f"Reliability over {summary['variants_run']} variants of {summary['scenario']}"
        atomic_replace(folder / "reliability.png", lambda tmp: reliability_diagram(curves, tmp, title=title))


# --- tables -------------------------------------------------------------------------------------


def _num(x: float | None, fmt: str = ".2f") -> str:
    return "-" if x is None else format(x, fmt)


def _draws_text(row: dict[str, Any]) -> str:
    d = row["draws"]
    objects = d["objects"]
    if not objects:
        return f"table {100 * d['table_height_change_m']:+.1f} cm"
    o = objects.get(row.get("object") or "", next(iter(objects.values())))  # the task's object
    size = "x".join(f"{100 * s:.0f}" for s in o["size"])
    return (
        f"yaw {o['yaw_change_deg']:+.0f}deg {o['mass_kg']:.2f}kg {size}cm mu {o['friction']:.2f} "
        f"table {100 * d['table_height_change_m']:+.1f}cm"
    )


def _alternative_cell(a: dict[str, Any]) -> str:
    """``value P(any) observed% [95% CI]`` of one alternative on one variant."""
    if not a["trials"]:
        return "infeasible"
    low, high = a["ci95"]
    infeasible = f" ({a['infeasible']} inf.)" if a["infeasible"] else ""
    predicted = f"{_num(a['predicted_value'])} {_num(a['predicted_combined'])}"
    return f"{predicted} {100 * a['failure_rate']:.0f}% [{100 * low:.0f},{100 * high:.0f}]{infeasible}"


def _progress_line(row: dict[str, Any], total: int) -> str:
    """One line per variant as it finishes: its scene, the chosen and best failures, the regret."""
    r = row["regret"]
    if r["regret"] is None:
        verdict = f"no regret ({row['status']})"
    else:
        verdict = (
            f"chosen failed {r['choice_failures']}/{r['trials']}, "
            f"best fixed {r['best_failures']}/{r['trials']}, "
            f"regret {r['regret']:+.2f} (p {r['p_value']:.2f})"
        )
    return (
        f"variant {row['index'] + 1}/{total}: {_draws_text(row)}; {verdict}; Spearman {_num(row['spearman'])}"
    )


def _regret_cells(r: dict[str, Any]) -> list[str]:
    n = r["trials"]
    if r["regret"] is None:
        return [f"{r['choice_failures']}/{n}", "-", "-", "-", "-"]
    low, high = r["ci95"]
    mark = " *" if r["significant_above_zero"] or r["significant_below_zero"] else ""
    return [
        f"{r['choice_failures']}/{n}",
        f"{r['best_failures']}/{n}",
        f"{r['regret']:+.2f}{mark}",
        f"[{low:+.2f}, {high:+.2f}]",
        f"{r['p_value']:.2f}",
    ]


def _rows(summary: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    header = [
        "variant",
        "scene",
        "redraws",
        *[f"{a}: value P(any) observed [95% CI]" for a in summary["alternatives"]],
        "Spearman",
        "chosen failed",
        "best failed",
        "regret",
        "95% CI",
        "p",
    ]
    rows = []
    for v in summary["per_variant"]:
        rows.append(
            [
                str(v["index"]),
                _draws_text(v),
                str(v["redraws"]),
                *[_alternative_cell(a) for a in v["alternatives"]],
                _num(v["spearman"]),
                *_regret_cells(v["regret"]),
            ]
        )
    return header, rows


def _footer(summary: dict[str, Any]) -> list[str]:
    lines = _regret_lines(summary["regret"], "")
    if summary.get("decide"):
        lines.insert(
            0,
            "each trial decided as the executive does, on its own estimate: the choice is the "
            "decision's, the pooled scores those of its numbers (trials whose dry run passed)",
        )
    if summary.get("rollouts"):
        lines += _regret_lines(summary["analytic"]["regret"], "analytic models alone (no rollouts): ")
    return [
        *lines,
        f"{summary['variants_run']} variant(s), {summary['redraws']} invalid scene(s) redrawn, "
        f"{summary['all_infeasible_variants']} with no feasible alternative; "
        f"{summary['trials_executed']} trials in physics; wall time {summary['wall_s']:.0f} s",
        *[
            f"variant {v['index']}, {a['name']} never planned, e.g.: {a['infeasible_because']}"
            for v in summary["per_variant"]
            for a in v["alternatives"]
            if not a["trials"] and a["infeasible_because"]
        ],
    ]


def _regret_lines(r: dict[str, Any], label: str) -> list[str]:
    pooled = r["pooled"]
    return [
        f"{label}regret (cross-fitted, per-trial choice minus best fixed alternative): "
        f"mean {_num(r['mean'], '+.3f')} "
        f"over {r['variants_scored']} variant(s) (in-sample, biased high: {_num(r['mean_naive'], '+.3f')}); "
        f"significantly above zero in {r['significant_above_zero']}, below in {r['significant_below_zero']} "
        "(exact sign test, 5%; marked *)",
        f"{label}all trials pooled: regret {_num(pooled['regret'], '+.3f')} over {pooled['trials']} trials, "
        f"discordant {pooled['discordant'][0]} (only the choice failed) vs {pooled['discordant'][1]} "
        f"(only the best failed), p {pooled['p_value']:.3f}",
    ]


def table_text(summary: dict[str, Any]) -> str:
    """The suite's results as aligned text (what ``executive fidelity`` prints)."""
    header, rows = _rows(summary)
    widths = [max(len(c) for c in column) for column in zip(header, *rows, strict=True)]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip() for line in [header, *rows]
    ]
    for label, pooled in _pooled_tables(summary):
        lines += ["", f"{label:<9}events / trials   ROC AUC (ceiling)   Brier    ECE"]
        for mode, m in pooled.items():
            lines.append(
                f"{mode:<9}{m['events']:>6} / {m['trials']:<9}{_num(m['auc'], '.3f'):>8}"
                f" ({_num(m.get('auc_ceiling'), '.3f'):>5})"
                f"{_num(m['brier'], '.4f'):>9}{_num(m['ece'], '.4f'):>8}   (by P({m['predicted_by']}))"
            )
    return "\n".join([*lines, "", *_footer(summary)])


def _pooled_tables(summary: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """The pooled statistics to show: as ranked, and (with rollouts) the analytic models' alone."""
    tables = [("pooled", summary["pooled"])]
    if summary.get("rollouts"):
        tables.append(("analytic", summary["analytic"]["pooled"]))
    return tables


def table_markdown(summary: dict[str, Any]) -> str:
    """:func:`table_text` as markdown tables."""
    header, rows = _rows(summary)
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    for label, pooled in _pooled_tables(summary):
        out += [
            "",
            f"| failure mode ({label}) | predicted by | events | trials | ROC AUC | AUC ceiling "
            "| Brier | ECE |",
            "|---|---|---:|---:|---:|---:|---:|---:|",
        ]
        for mode, m in pooled.items():
            out.append(
                f"| {mode} | P({m['predicted_by']}) | {m['events']} | {m['trials']} "
                f"| {_num(m['auc'], '.3f')} | {_num(m.get('auc_ceiling'), '.3f')} "
                f"| {_num(m['brier'], '.4f')} | {_num(m['ece'], '.4f')} |"
            )
    return "\n".join([*out, "", *_footer(summary)])
