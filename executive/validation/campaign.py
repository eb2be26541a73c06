"""Monte Carlo validation campaigns: does the predicted risk predict real failures?

:func:`run_campaign` runs N trials of every alternative of one task on sampled truths
(trial ``i`` of every alternative on the same one), streams them to ``trials.jsonl`` in the
run folder, and scores the predictions against the outcomes into ``summary.json``,
``table.md`` and ``reliability.png``. ``resume`` completes a cut campaign. With ``decide``
each trial first decides as the executive does, on its own estimate (planning, analytic risk,
dry runs, rollouts, fusion: :mod:`~executive.validation.campaign_decisions`), and the records
carry the numbers it decided with and its choice. The parts:
predictions (:mod:`~executive.validation.campaign_predictions`), trials
(:mod:`~executive.validation.campaign_trials`), backends
(:mod:`~executive.validation.campaign_backends`), the run folder
(:mod:`~executive.validation.campaign_folder`), scoring
(:mod:`~executive.validation.campaign_scoring`) and tables
(:mod:`~executive.validation.campaign_tables`); this module re-exports their public names.
How a campaign works: docs/campaigns.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, NamedTuple

from executive.errors import ExecutiveError
from executive.schema.types import Scenario
from executive.validation.campaign_backends import Backend, Runner
from executive.validation.campaign_folder import (
    FolderLock,
    TrialLog,
    campaign_config,
    campaign_folder,
    claim_folder,
    read_trials,
    unique_trials,
)
from executive.validation.campaign_predictions import (
    Prediction,
    check_predictions,
    predict,
    prediction_text,
)
from executive.validation.campaign_scoring import finite, forecasts, observed_outcomes, summarise
from executive.validation.campaign_tables import reliability_figure, table_markdown, table_text
from executive.validation.campaign_trials import run_trial, trial_scene, trial_seed, vary_scene

__all__ = [
    "Backend",
    "CampaignResult",
    "FolderLock",
    "Prediction",
    "TrialLog",
    "check_predictions",
    "forecasts",
    "observed_outcomes",
    "predict",
    "read_trials",
    "run_campaign",
    "run_trial",
    "summarise",
    "table_markdown",
    "table_text",
    "trial_scene",
    "trial_seed",
    "unique_trials",
    "vary_scene",
]


@dataclass
class CampaignResult:
    """A campaign's run folder, summary and trial records; the trials it ran this time and in
    how many seconds; whether Ctrl-C cut it."""

    folder: Path
    summary: dict[str, Any]
    records: list[dict[str, Any]]
    new_trials: int
    elapsed_s: float
    interrupted: bool = False

    @property
    def trials_per_s(self) -> float:
        return self.new_trials / self.elapsed_s if self.elapsed_s > 0 else float("nan")


def run_campaign(
    scenario: Scenario,
    *,
    trials: int | None = None,
    jobs: int = 1,
    out: Path | str | None = None,
    resume: bool = False,
    backend: Backend = "local",
    seed: int | None = None,
    task_index: int = 0,
    alternatives: Sequence[str] | None = None,
    stream: IO[str] | None = None,
    decide: bool = False,
) -> CampaignResult:
    """Run (or complete) a campaign; write trials.jsonl, summary.json, table.md, reliability.png.

    Args:
        scenario: the scenario whose task is run.
        trials: trials per alternative (default: the scenario's ``trials.count``).
        jobs: worker processes (or Ray CPUs).
        out: the run folder (default ``runs/<stamp>-<scenario>-campaign``).
        resume: complete the campaign in ``out`` (the same scenario, seed, task, alternatives).
        backend: ``local`` or ``ray``.
        seed: the first trial's seed (default: the scenario's ``trials.seed``).
        task_index, alternatives: the task, and which of its alternatives (default: all).
        stream: where progress goes (default stdout).
        decide: each trial decides among the alternatives as the executive does, on its own
            estimate (``risk.rollouts`` rollouts per alternative), before they are executed.

    Returns:
        The run folder, summary and records.

    Raises:
        ExecutiveError: a bad argument, a folder already used or busy, Ray missing.
    """
    n = scenario.trials.count if trials is None else trials
    names = _check_request(scenario, n, jobs, backend, task_index, alternatives)
    task = scenario.mission[task_index]
    base_seed = scenario.trials.seed if seed is None else seed
    folder = campaign_folder(scenario, out, resume)
    trials_path = folder / "trials.jsonl"
    config = campaign_config(scenario, base_seed, task_index, names, n, decide)
    lock = claim_folder(folder, trials_path, config, resume)  # held until the summary is written
    records, duplicates, beyond = unique_trials(read_trials(trials_path, repair=True), n, names)
    done = {(r["trial"], r["alternative"]) for r in records}
    specs = [(i, a, trial_seed(base_seed, i)) for i in range(n) for a in names if (i, a) not in done]
    log = print if stream is None else (lambda text: (stream.write(text + "\n"), stream.flush()))
    log(
        f"campaign {scenario.name}: task {task_index} ({task.object}), "
        f"{n} trials x {len(names)} alternatives "
        f"({', '.join(names)}), seed {base_seed}, {jobs} job(s) on {backend}; run folder {folder}"
    )
    _log_resumed(log, trials_path, len(records), len(specs), duplicates, beyond, n)
    _log_alone(log, scenario, task_index)
    run = _execute(scenario, task_index, jobs, backend, folder, names, specs, records, log, stream, decide)
    records.sort(
        key=lambda r: (r["trial"], names.index(r["alternative"]) if r["alternative"] in names else 0)
    )
    summary = summarise(scenario, records, names, run.predictions)
    summary.update(
        task=f"{task_index}: {task.label()}",
        predictions=_predictions_text(scenario, decide),
        seed=base_seed,
        trials_per_alternative=n,
        complete=len(records) == n * len(names),
        jobs=jobs,
        backend=backend,
        elapsed_s=run.elapsed,
        new_trials=run.new,
        trials_per_s=run.new / run.elapsed if run.elapsed > 0 else None,
        trial_phase_s=finite(run.trial_phase),  # executing trials only (after planning, before statistics)
        duplicates_ignored=duplicates,
        records_beyond_trials=beyond,
    )
    _write_results(folder, summary, records)
    lock.release()
    return CampaignResult(folder, summary, records, run.new, run.elapsed, run.interrupted)


def _check_request(
    scenario: Scenario,
    n: int,
    jobs: int,
    backend: str,
    task_index: int,
    alternatives: Sequence[str] | None,
) -> list[str]:
    """The alternatives a campaign runs; ExecutiveError naming a bad trials, jobs, backend, task
    or alternative."""
    if n < 1:
        raise ExecutiveError(f"--trials must be at least 1; got {n}")
    if jobs < 1:
        raise ExecutiveError(f"--jobs must be at least 1; got {jobs}")
    if backend not in ("local", "ray"):
        raise ExecutiveError(f"unknown backend '{backend}'; valid: local, ray")
    if not 0 <= task_index < len(scenario.mission):
        raise ExecutiveError(f"{scenario.name} has {len(scenario.mission)} task(s); no task {task_index}")
    task = scenario.mission[task_index]
    names = list(alternatives) if alternatives else list(task.alternatives)
    if not names:
        raise ExecutiveError(
            f"task {task_index} of {scenario.name} ({task.label()}) names no alternative to run"
        )
    unknown = [a for a in names if a not in task.alternatives]
    if unknown:
        raise ExecutiveError(
            f"task {task_index} of {scenario.name} has no alternative {', '.join(unknown)}; "
            f"its alternatives are: {', '.join(task.alternatives)}"
        )
    return names


def _log_alone(log: Callable[[str], Any], scenario: Scenario, task_index: int) -> None:
    """Say that a later task of a mission runs alone, from the scenario's scene."""
    if task_index:
        before = "; ".join(f"{i}: {t.label()}" for i, t in enumerate(scenario.mission[:task_index]))
        log(
            f"task {task_index} runs alone, from the scenario's scene: the tasks before it ({before}) "
            "do not run first, so what they would have moved or left in hand is where the scene has it"
        )


def _log_resumed(
    log: Callable[[str], Any], trials_path: Path, kept: int, to_run: int, duplicates: int, beyond: int, n: int
) -> None:
    """Say what a resumed campaign found in its trials file."""
    if kept:
        log(f"resuming: {kept} trial(s) already in {trials_path.name}, {to_run} to run")
    if duplicates:
        log(
            f"  {duplicates} duplicated record(s) in {trials_path.name} "
            "(same trial and alternative): counted once"
        )
    if beyond:
        log(f"  {beyond} record(s) beyond --trials {n} in {trials_path.name}: kept there, not counted")


class _Execution(NamedTuple):
    """What :func:`_execute` did: the trials it ran, whether Ctrl-C cut it, the alternatives'
    predictions, the seconds of the trial phase (nan if cut) and in all."""

    new: int
    interrupted: bool
    predictions: dict[str, Prediction]
    trial_phase: float
    elapsed: float


def _execute(
    scenario: Scenario,
    task_index: int,
    jobs: int,
    backend: Backend,
    folder: Path,
    names: list[str],
    specs: list[tuple[int, str, int]],
    records: list[dict[str, Any]],
    log: Callable[[str], Any],
    stream: IO[str] | None,
    decide: bool = False,
) -> _Execution:
    """Predict the alternatives (unless the scene varies or each trial decides) and run the
    trials ``specs``, each appended to ``records`` and to trials.jsonl as it ends, with a
    progress bar. Ctrl-C stops the workers; every finished trial is already on disk."""
    from executive.report.progress_bar import ProgressBar

    t0 = time.perf_counter()
    runner = Runner(scenario, task_index, jobs, backend, folder)
    interrupted = False
    new = 0
    trial_log = TrialLog(folder / "trials.jsonl")
    bar: ProgressBar | None = None
    predictions: dict[str, Prediction] = {}
    trial_phase = float("nan")
    try:
        if decide:
            log(_predictions_text(scenario, True))
        else:
            _predict(predictions, scenario, runner, names, log)
        t_trials = time.perf_counter()
        bar = ProgressBar(len(records) + len(specs), done=len(records), stream=stream)
        bar.draw(force=True)
        failures = sum(r["outcome"] != "success" for r in records)
        for record in runner.decisions(names, specs) if decide else runner.trials(specs):
            trial_log.write(record)
            records.append(record)
            new += 1
            failures += record["outcome"] != "success"
            bar.advance(extra=f"{failures} failed")
        bar.close()
        trial_phase = time.perf_counter() - t_trials
        runner.close()
    except KeyboardInterrupt:  # stop the workers; every finished trial is already on disk
        interrupted = True
        runner.close(terminate=True)
        if bar is not None:
            bar.close()
    finally:
        trial_log.close()
        runner.close(terminate=True)
    return _Execution(new, interrupted, predictions, trial_phase, time.perf_counter() - t0)


def _predict(
    predictions: dict[str, Prediction],
    scenario: Scenario,
    runner: Runner,
    names: list[str],
    log: Callable[[str], Any],
) -> None:
    """Fill ``predictions`` with the alternatives planned and then checked on the estimate (in
    place, so that a Ctrl-C between the two keeps the plans), and log them; none when the scene
    varies from trial to trial (each trial then plans on its own)."""
    variation = scenario.trials.scene_variation
    if not variation.is_zero():
        log("the scene varies from trial to trial (trials.scene_variation): each trial plans on its own")
        log("  (its predictions are analytic: dry runs and rollouts check one fixed estimate)")
        if variation.varies_perception:
            low, high = variation.perception_scale
            log(f"  and so does the perception: pose sigmas x {low:g} to x {high:g} (log-uniform)")
    else:
        log(f"planning {', '.join(names)} on the estimate")
        predictions.update(runner.predict(names))
        checked = runner.use(check_predictions(scenario, dict(predictions), runner.run_jobs, log))
        predictions.clear()
        predictions.update(checked)
    for name in predictions:
        log(f"  {name:<15} {prediction_text(predictions[name], scenario.risk.ordering)}")


def _predictions_text(scenario: Scenario, decide: bool) -> str:
    """Which predictions the campaign scores (the summary's ``predictions``, the table's title)."""
    n = scenario.risk.rollouts.count
    if decide:
        fused = (
            f"fused with up to {n} rollouts per alternative"
            if n
            else "analytic, after the dry runs (no rollouts)"
        )
        return (
            "each trial's decision, on its own estimate as the executive makes it: planned, assessed, "
            f"dry-run, {fused}"
        )
    if not scenario.trials.scene_variation.is_zero():
        return "analytic, per trial on its own estimate"
    fused = f", fused with up to {n} rollouts per alternative" if n else " (analytic, after the dry runs)"
    return f"on the scenario's estimate, once per alternative{fused}"


def _write_results(folder: Path, summary: dict[str, Any], records: list[dict[str, Any]]) -> None:
    """summary.json, table.md and (when any trial ran) reliability.png in ``folder``."""
    from executive.decision.audit import atomic_write_text, to_json, write_summary

    write_summary(folder, to_json(summary))
    atomic_write_text(folder / "table.md", table_markdown(summary) + "\n")
    if records:
        reliability_figure(records, folder / "reliability.png")
