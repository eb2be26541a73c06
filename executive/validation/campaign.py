"""Monte Carlo validation campaigns: does the predicted risk predict real failures?

:func:`run_campaign` runs N trials (:func:`run_trial`) of every alternative of one task; trial
``i`` of every alternative executes on the same sampled truth (seed ``trials.seed + i``: common
random numbers, so the alternatives are compared on the same worlds). Results stream to
``trials.jsonl`` in the run folder (in trial order whatever the number of jobs, fsync'ed, no
timings: the same seed gives the same file; ``--resume`` completes a cut campaign); at the end
:func:`summarise` scores the predictions against the outcomes into ``summary.json``, ``table.md``
and ``reliability.png``. Backends: ``local`` (this process for one job, else a pool of spawned
processes) and ``ray`` (Ray tasks, ``pip install .[cluster]``; the cluster at ``RAY_ADDRESS``,
else a local one with ``jobs`` CPUs).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import multiprocessing
import os
import pickle
import signal
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.schema.failure_modes import (
    failure_mode,
    failure_modes,
    mode_names,
    mode_of_verdict,
    outcome,
    verdict_names,
)
from executive.schema.types import Scenario, SceneVariation
from executive.world.model import Perturbation

if TYPE_CHECKING:
    from executive.decision.physics_check import RolloutJob

__all__ = [
    "CampaignResult",
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
]


def observed_outcomes() -> tuple[str, ...]:
    """The verdicts a trial can end in, in the order tables show them: each failure mode's
    verdicts, then the outcomes no mode predicts (the failure-mode table; ``error`` apart)."""
    return tuple(v for v in verdict_names() if v != "error")


def _forecasts_by_mode() -> dict[str, str]:
    """Each failure mode's predicted probability (its own key), and ``any``'s: ``combined``."""
    return {**{m: m for m in mode_names()}, "any": "combined"}


Backend = Literal["local", "ray"]
FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
_ByMode = dict[str, float | None]  # a score per failure mode (None: not defined)


@dataclass(frozen=True)
class Prediction:
    """An alternative planned on the estimate: its risk report, or why it does not plan."""

    alternative: str
    feasible: bool
    risk: dict[str, float] | None  # CombinedRisk.as_dict(): each failure mode's, combined, ...
    value: float | None  # the scenario's ordering quantity
    error: str = ""
    plan: Any = field(default=None, repr=False)  # AlternativePlan (None when infeasible)
    assessed: Any = field(default=None, repr=False)  # CombinedRisk (None when infeasible)
    physics: dict[str, Any] | None = None  # the physics check's summary, when it ran
    analytic: dict[str, float] | None = None  # the analytic risk and value, when rollouts fused it


def predict(scenario: Scenario, task_index: int, alternative: str) -> Prediction:
    """Plan ``alternative`` on the estimate and assess its risk (as ``executive plan`` does)."""
    from executive.decision.assessment import assess_plan
    from executive.planning.planner import Planner, PlanningError
    from executive.risk.collision import CollisionModel, breach_summary
    from executive.tasks.steps import plan_alternative
    from executive.world.model import build

    world = build(scenario)
    task = scenario.mission[task_index]
    try:
        plan = plan_alternative(Planner(world), world, task, alternative)
    except PlanningError as exc:
        return Prediction(alternative, False, None, None, str(exc))
    model = CollisionModel(world, scenario.risk, uncertainty=scenario.uncertainty)
    risk = assess_plan(world, plan, model)
    risk_dict = risk.as_dict()
    breach = breach_summary(risk.components["collision"]) if "collision" in risk.components else None
    if breach is not None:  # P(touching a breach obstacle), a part of the collision mode
        risk_dict["breach"] = float(breach["probability"])
    return Prediction(alternative, True, risk_dict, risk.value(scenario.risk.ordering), "", plan, risk)


def check_predictions(
    scenario: Scenario,
    predictions: dict[str, Prediction],
    run_map: Callable[[Sequence[RolloutJob]], list[dict[str, Any]]],
    log: Callable[[str], Any] = print,
) -> dict[str, Prediction]:
    """The predictions after the physics check (:mod:`executive.decision.physics_check`) on the estimate.

    A fused alternative carries the fused risk and value. One whose dry run failed keeps its
    analytic risk but has no value (the executive would never run it); its trials still run,
    so the campaign measures it all the same.
    """
    from executive.decision.physics_check import check_alternatives

    feasible = {n: p for n, p in predictions.items() if p.feasible and p.assessed is not None}
    if not feasible:
        return predictions
    cfg = scenario.risk.rollouts
    rolls = f", then up to {cfg.count} rollouts each" if cfg.count else ""
    log(f"checking {', '.join(feasible)} in physics: a dry run on the estimate{rolls}")
    plans = {n: p.plan for n, p in feasible.items()}
    verdict = check_alternatives(plans, {n: p.assessed for n, p in feasible.items()}, scenario, run_map)
    out = dict(predictions)
    for name, result in verdict.alternatives.items():
        physics = result.as_dict(cfg.confidence)
        if not result.dry_run_ok:
            out[name] = dataclasses.replace(
                out[name], value=None, error=result.dry_run_reason(), physics=physics
            )
            continue
        risk, ordering = result.risk, scenario.risk.ordering
        analytic = None
        if result.fused is not None:
            analytic = {**result.analytic.as_dict(), "value": result.analytic.value(ordering)}
        out[name] = dataclasses.replace(
            out[name], risk=risk.as_dict(), value=risk.value(ordering), physics=physics, analytic=analytic
        )
    if verdict.stopped != "off":
        log(f"  rollouts: {verdict.rollouts} per alternative, stopped by {verdict.stopped}")
    return out


def _prediction_text(p: Prediction, ordering: str) -> str:
    if not p.feasible or p.risk is None:
        return f"infeasible: {p.error}"
    if p.value is None:
        return f"never chosen: {p.error}"
    return f"P(any) {p.risk['combined']:.4f}  {ordering} {p.value:.4f}"


def trial_seed(base_seed: int, index: int) -> int:
    """The seed of trial ``index``: ``trials.seed + index`` (the same for every alternative)."""
    return base_seed + index


def vary_scene(
    scenario: Scenario, variation: SceneVariation, rng: np.random.Generator
) -> tuple[Scenario, dict[str, Any]]:
    """A trial's scene: every object and obstacle of ``scenario`` shifted by a draw of ``variation``.

    Draws in a fixed order (objects: dx, dy, dyaw; then obstacles: dx, dy; then, when
    ``variation.perception_scale`` is a range, the trial's perception factor, log-uniform).
    Returns the shifted scenario (the trial's estimate, its pose sigmas scaled by that
    factor) and the shifts, for the record.
    """
    objects, obstacles = [], []
    shifts: dict[str, Any] = {"object_offsets": {}, "obstacle_offsets": {}}
    for body in scenario.scene.objects:
        dx, dy = rng.normal(0.0, variation.object_position, 2) if variation.object_position else (0.0, 0.0)
        dyaw = float(rng.normal(0.0, variation.object_yaw_rad)) if variation.object_yaw_rad else 0.0
        x, y, z = body.position
        roll, pitch, yaw = body.orientation_rad
        objects.append(
            dataclasses.replace(body, position=(x + dx, y + dy, z), orientation_rad=(roll, pitch, yaw + dyaw))
        )
        shifts["object_offsets"][body.name] = [float(dx), float(dy), dyaw]
    for body in scenario.scene.obstacles:
        dx, dy = (
            rng.normal(0.0, variation.obstacle_position, 2) if variation.obstacle_position else (0.0, 0.0)
        )
        x, y, z = body.position
        obstacles.append(dataclasses.replace(body, position=(x + dx, y + dy, z)))
        shifts["obstacle_offsets"][body.name] = [float(dx), float(dy)]
    scene = dataclasses.replace(scenario.scene, objects=tuple(objects), obstacles=tuple(obstacles))
    uncertainty = scenario.uncertainty
    if variation.varies_perception:
        low, high = variation.perception_scale
        factor = float(np.exp(rng.uniform(np.log(low), np.log(high))))
        uncertainty = dataclasses.replace(
            uncertainty,
            object_position=uncertainty.object_position * factor,
            object_yaw_rad=uncertainty.object_yaw_rad * factor,
            obstacle_position=uncertainty.obstacle_position * factor,
        )
        shifts["perception_scale"] = factor
    return dataclasses.replace(scenario, scene=scene, uncertainty=uncertainty), _perturbation_json(shifts)


def trial_scene(scenario: Scenario, seed: int) -> tuple[Scenario, Perturbation, dict[str, Any] | None]:
    """Trial ``seed``'s estimate (the scenario, or a varied scene), its truth, and the variation.

    One generator per trial: first the scene variation (when the scenario has one), then the
    truth's perturbation from the estimate's uncertainty (:func:`executive.world.model.sample_perturbation`).
    """
    from executive.world.model import sample_perturbation

    rng = np.random.default_rng(seed)
    variation = scenario.trials.scene_variation
    if variation.is_zero():
        return scenario, sample_perturbation(scenario, rng), None
    estimate, shifts = vary_scene(scenario, variation, rng)
    return estimate, sample_perturbation(estimate, rng), shifts


def run_trial(
    scenario: Scenario,
    task_index: int,
    alternative: str,
    index: int,
    seed: int,
    prediction: Prediction | None = None,
) -> dict[str, Any]:
    """Execute one trial; the record written to ``trials.jsonl`` (JSON-safe, no timings).

    The trial takes the alternative's plan and predicted risk on the *estimate*, builds the
    truth world of its perturbation (object and obstacle poses, object mass, friction, the
    robot's CoM offset) and executes the plan in physics with the alternative forced (no
    selection, no approval, no live guards: the question is what the plan does, not whether a
    guard would stop it). Outcome: ``success``, or the detectors' failure mode ``collision``,
    ``fall``, ``drop``, ``unstable``, or a verdict no mode predicts (``tracking``, ``task``,
    ``timeout``: not finished in the time limit; :mod:`executive.schema.failure_modes`);
    ``infeasible`` when the alternative does not plan (nothing is executed) and ``error`` when
    the trial's code raised (a defect; counted, never hidden).

    ``prediction``: the alternative planned on the scenario's fixed estimate, once per
    alternative (planning is deterministic: planning again per trial gives the same plan);
    None: plan it here, on the trial's own scene, as a scenario with a scene variation needs.
    """
    from executive.execution.runner import error_fields, execute_plan, outcome_fields
    from executive.world.model import build

    estimate, perturbation, shifts = trial_scene(scenario, seed)
    if prediction is None or shifts is not None:
        prediction = predict(estimate, task_index, alternative)
    record: dict[str, Any] = {
        "trial": index,
        "alternative": alternative,
        "seed": seed,
        "outcome": "infeasible",
        "failure": None,
        "placement_error_m": None,
        "sim_time_s": 0.0,
        "predicted": _predicted(prediction),
        "scene": shifts,
        "truth": _perturbation_json(asdict(perturbation)),
    }
    if not prediction.feasible:
        record["failure"] = {"mode": "infeasible", "detail": prediction.error}
        return record
    try:
        truth = build(estimate, perturbation, kind="truth")
        result = execute_plan(prediction.plan, truth, estimate.mission[task_index])
    except Exception as exc:  # a defect in a trial must not end the campaign; it is counted
        record.update(error_fields(exc))
        return record
    record.update(outcome_fields(result))
    return record


def _predicted(prediction: Prediction) -> dict[str, Any] | None:
    """A record's prediction: per-mode probabilities and the value ranked by; with rollouts,
    the analytic prediction they were fused with under ``analytic``."""
    if prediction.risk is None:
        return None
    out: dict[str, Any] = {**prediction.risk, "value": prediction.value}
    if prediction.analytic is not None:
        out["analytic"] = prediction.analytic
    return out


def _perturbation_json(p: dict[str, Any]) -> dict[str, Any]:
    def r(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: r(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [r(x) for x in v]
        if isinstance(v, float):
            return round(v, 9)
        return v

    return r(p)


# --- the trials file -------------------------------------------------------------------------


class TrialLog:
    """``trials.jsonl``: one trial per line, appended, flushed and fsync'ed line by line."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: IO[str] = path.open("a", encoding="utf-8")

    def write(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record, allow_nan=False, sort_keys=True) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()


def _current_names(record: dict[str, Any]) -> dict[str, Any]:
    """A trial record with its predictions under the failure modes' current names (an old
    campaign's ``grasp`` is ``drop``)."""
    predicted = record.get("predicted")
    if not isinstance(predicted, dict):
        return record
    old = {alias: m.name for m in failure_modes() for alias in m.aliases}
    record["predicted"] = {old.get(k, k): v for k, v in predicted.items()}
    return record


def read_trials(path: Path, *, repair: bool = False) -> list[dict[str, Any]]:
    """The trials recorded in ``path``.

    A last line cut short (a campaign killed while writing) is dropped, and with
    ``repair`` cut off the file so appending continues cleanly; a bad line before
    the last is an error naming it.
    """
    if not path.is_file():
        return []
    raw = path.read_bytes()
    *complete, tail = raw.split(b"\n")  # tail: what follows the last newline (a cut-short line)
    records: list[dict[str, Any]] = []
    for number, line in enumerate(complete, start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except ValueError as exc:
            raise ExecutiveError(f"{path}:{number}: not valid JSON ({exc})") from None
        if not isinstance(record, dict) or "trial" not in record or "alternative" not in record:
            raise ExecutiveError(f"{path}:{number}: not a trial record (no 'trial' and 'alternative')")
        records.append(_current_names(record))
    good = len(raw) - len(tail)
    if repair and good < len(raw):
        with path.open("r+b") as f:
            f.truncate(good)
    return records


# --- backends ----------------------------------------------------------------------------------

_WORKER: dict[str, Any] = {}


def _init_worker(scenario: Scenario, task_index: int) -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")
    if multiprocessing.parent_process() is not None:  # a pool worker: Ctrl-C is the campaign's to handle
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    _WORKER.clear()
    _WORKER.update(scenario=scenario, task_index=task_index, predictions={}, path=None)


def _predict_in_worker(alternative: str) -> Prediction:
    return predict(_WORKER["scenario"], _WORKER["task_index"], alternative)


def _trial_in_worker(spec: tuple[str | None, int, str, int]) -> dict[str, Any]:
    path, index, alternative, seed = spec
    if path is not None and _WORKER["path"] != path:  # the predictions (with their plans) once
        with open(path, "rb") as f:
            _WORKER["predictions"] = pickle.load(f)
        _WORKER["path"] = path
    prediction = _WORKER["predictions"].get(alternative) if path is not None else None
    return run_trial(_WORKER["scenario"], _WORKER["task_index"], alternative, index, seed, prediction)


def _ray_predict(scenario: Scenario, task_index: int, alternative: str) -> Prediction:
    return predict(scenario, task_index, alternative)


def _ray_trial(
    scenario: Scenario,
    task_index: int,
    predictions: dict[str, Prediction],
    index: int,
    alternative: str,
    seed: int,
) -> dict[str, Any]:
    return run_trial(scenario, task_index, alternative, index, seed, predictions.get(alternative))


class _Runner:
    """Runs predictions and trials on a backend; trials come back in the order asked."""

    def __init__(
        self, scenario: Scenario, task_index: int, jobs: int, backend: Backend, folder: Path
    ) -> None:
        self.scenario = scenario
        self.task_index = task_index
        self.folder = folder
        self._pool: Any = None
        self._ray: Any = None
        self._predictions: dict[str, Prediction] = {}
        self._pickle: Path | None = None
        if backend == "ray":
            try:
                import ray
            except ImportError:
                raise ExecutiveError(
                    "--backend ray needs Ray: pip install 'risk-gated-executive[cluster]' "
                    "(or pip install ray); the default --backend local needs nothing more"
                ) from None
            if not ray.is_initialized():
                if os.environ.get("RAY_ADDRESS"):
                    ray.init(address=os.environ["RAY_ADDRESS"], log_to_driver=False)
                else:
                    ray.init(num_cpus=jobs, include_dashboard=False, log_to_driver=False)
            self._ray = ray
        elif jobs > 1:
            import multiprocessing

            # spawn, not fork: a worker starts clean (no inherited MuJoCo/GL state, no threads).
            ctx = multiprocessing.get_context("spawn")
            self._pool = ctx.Pool(jobs, initializer=_init_worker, initargs=(scenario, task_index))
        else:
            _init_worker(scenario, task_index)

    def predict(self, alternatives: Sequence[str]) -> dict[str, Prediction]:
        if self._ray is not None:
            remote = self._ray.remote(_ray_predict)
            refs = [remote.remote(self.scenario, self.task_index, a) for a in alternatives]
            out = self._ray.get(refs)
        elif self._pool is not None:
            out = self._pool.map(_predict_in_worker, alternatives, chunksize=1)
        else:
            out = [_predict_in_worker(a) for a in alternatives]
        self._predictions = {p.alternative: p for p in out}
        return self._predictions

    def trials(self, specs: Sequence[tuple[int, str, int]]) -> Iterator[dict[str, Any]]:
        if self._ray is not None:
            ray = self._ray
            remote = ray.remote(_ray_trial)
            preds = ray.put(self._predictions)
            refs = [remote.remote(self.scenario, self.task_index, preds, i, a, s) for i, a, s in specs]
            for ref in refs:
                yield ray.get(ref)
            return
        path: str | None = None
        if self._predictions:  # a fixed estimate: the plans go to the workers once, by file
            self._pickle = self.folder / ".predictions.pkl"
            with self._pickle.open("wb") as f:
                pickle.dump(self._predictions, f, protocol=pickle.HIGHEST_PROTOCOL)
            path = str(self._pickle)
        work = [(path, i, a, s) for i, a, s in specs]
        if self._pool is not None:
            yield from self._pool.imap(_trial_in_worker, work, chunksize=1)
        else:
            for spec in work:
                yield _trial_in_worker(spec)

    def use(self, predictions: dict[str, Prediction]) -> dict[str, Prediction]:
        """Trials run these predictions' plans (and records carry their risk) from now on."""
        self._predictions = dict(predictions)
        return self._predictions

    def run_jobs(self, jobs: Sequence[RolloutJob]) -> list[dict[str, Any]]:
        """Physics jobs (dry runs, rollouts) on the campaign's backend, records in order."""
        from executive.decision.physics_check import run_job

        if self._ray is not None:
            remote = self._ray.remote(run_job)
            return list(self._ray.get([remote.remote(job) for job in jobs]))
        if self._pool is not None:
            return list(self._pool.map(run_job, jobs, chunksize=1))
        return [run_job(job) for job in jobs]

    def close(self, *, terminate: bool = False) -> None:
        if self._pool is not None:
            if terminate:
                self._pool.terminate()
            else:
                self._pool.close()
            self._pool.join()
            self._pool = None
        if self._pickle is not None and self._pickle.exists():
            self._pickle.unlink()


# --- statistics --------------------------------------------------------------------------------


def _executed(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The trials that ran in physics (not infeasible, not failed by a defect)."""
    return [r for r in records if r["outcome"] not in ("infeasible", "error")]


def forecasts(executed: Sequence[dict[str, Any]]) -> Iterator[tuple[str, str, FloatArray, BoolArray]]:
    """Per failure mode (and "any"): the predicting key, its probabilities and the 0/1 outcomes."""
    for mode, key in _forecasts_by_mode().items():
        p = np.array([r["predicted"][key] for r in executed], dtype=float)
        verdicts = () if mode == "any" else failure_mode(mode).verdicts
        y = np.array(
            [r["outcome"] != "success" if mode == "any" else r["outcome"] in verdicts for r in executed]
        )
        yield mode, key, p, y.astype(bool)


def _rate(failures: int, trials: int) -> dict[str, Any]:
    from executive.validation.stats import clopper_pearson

    low, high = clopper_pearson(failures, trials)
    return {"value": failures / trials if trials else None, "ci95": [low, high]}


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def summarise(
    scenario: Scenario,
    records: Sequence[dict[str, Any]],
    alternatives: Sequence[str],
    predictions: dict[str, Prediction],
) -> dict[str, Any]:
    """Per alternative: trials, failures by mode, failure rates with 95% Clopper-Pearson
    intervals, mean predicted risk; overall: AUC, Brier and ECE per mode and Spearman."""
    from executive.validation.stats import spearman

    executed = _executed(records)
    ordering = scenario.risk.ordering
    per_alt = [
        _alternative_summary(name, executed, records, predictions.get(name), ordering)
        for name in alternatives
    ]
    breach = sorted(o.name for o in scenario.scene.obstacles if o.category == "breach")
    for a in per_alt if breach else ():
        a["breach"] = _breach_touches([r for r in executed if r["alternative"] == a["name"]], set(breach))
    observed_by, auc, ceiling, brier_by, ece_by = _forecast_scores(executed)
    ran = [a for a in per_alt if a["trials"]]
    rho = {
        q: _finite(spearman([a["predicted"][q] for a in ran], [a["failure_rate"]["value"] for a in ran]))
        for q in ("combined", ordering)
    }
    return {
        "scenario": scenario.name,
        "task": None,
        "ordering": ordering,
        "trials_executed": len(executed),
        "alternatives": per_alt,
        "observed_failures": observed_by,
        "auc": auc,
        "auc_ceiling_per_alternative": ceiling,
        "brier": brier_by,
        "ece": ece_by,
        "spearman": rho[ordering],
        "spearman_by": rho,
        "predictor": _forecasts_by_mode(),
        "breach_obstacles": breach,
    }


def _breach_touches(mine: Sequence[dict[str, Any]], breach: set[str]) -> dict[str, Any]:
    """An alternative's executed trials whose failure touched a breach obstacle (the failure's
    bodies), with the 95% interval, and the mean predicted P(breach)."""
    touches = sum(bool(breach & set((r.get("failure") or {}).get("bodies") or ())) for r in mine)
    predicted = [float((r.get("predicted") or {}).get("breach", 0.0)) for r in mine]
    return {
        "touches": touches,
        "trials": len(mine),
        "rate": _rate(touches, len(mine)),
        "predicted": float(np.mean(predicted)) if predicted else None,
    }


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


def _alternative_summary(
    name: str,
    executed: Sequence[dict[str, Any]],
    records: Sequence[dict[str, Any]],
    prediction: Prediction | None,
    ordering: str,
) -> dict[str, Any]:
    """One alternative's row of the summary: its trials, failures by mode and rates, and its
    mean predicted risk over its executed trials."""
    mine = [r for r in executed if r["alternative"] == name]
    infeasible = [r for r in records if r["alternative"] == name and r["outcome"] == "infeasible"]
    n = len(mine)
    failures = {m: sum(r["outcome"] == m for r in mine) for m in observed_outcomes()}
    failures["any"] = sum(r["outcome"] != "success" for r in mine)
    predicted: dict[str, float | None] = {}
    if mine:
        keys = (*mode_names(), "combined", "weighted_sum", "expected_loss")
        predicted = {k: float(np.mean([r["predicted"][k] for r in mine])) for k in keys}
        # the number the selector ranked by (fused with the rollouts when they ran)
        # (None: the executive would never run it, its dry run failed)
        values = [r["predicted"].get("value", r["predicted"][ordering]) for r in mine]
        predicted["value"] = None if None in values else float(np.mean(values))
    return {
        "name": name,
        "feasible": bool(prediction.feasible) if prediction else None,
        "error": prediction.error
        if prediction and (not prediction.feasible or prediction.value is None)
        else (infeasible[0]["failure"]["detail"] if infeasible else ""),  # planned per trial: the first's why
        "physics": prediction.physics if prediction else None,
        "trials": n,
        "errors": sum(r["outcome"] == "error" for r in records if r["alternative"] == name),
        "infeasible": sum(r["outcome"] == "infeasible" for r in records if r["alternative"] == name),
        "failures": failures,
        "failure_rate": _rate(failures["any"], n),
        "failure_rate_by_mode": {m: _rate(failures[m], n) for m in observed_outcomes()},
        "predicted": predicted,
    }


def _forecast_scores(
    executed: Sequence[dict[str, Any]],
) -> tuple[dict[str, int], _ByMode, _ByMode, _ByMode, _ByMode]:
    """Per failure mode (and "any"): the failures observed, the ROC AUC of its predictor, the
    best AUC of a prediction constant per alternative, the Brier score and the ECE."""
    from executive.validation.stats import brier, expected_calibration_error, roc_auc

    auc: _ByMode = {}
    # The best AUC any prediction that is the same for every trial of an alternative can reach:
    # score each trial by its alternative's observed rate of that mode (an oracle ranking). With
    # one fixed estimate every trial of an alternative has the same prediction, so the AUC of
    # the risk models is bounded by this, however good they are.
    ceiling: _ByMode = {}
    brier_by: _ByMode = {}
    ece_by: _ByMode = {}
    observed_by: dict[str, int] = {}
    for mode, _, p, y in forecasts(executed):
        observed_by[mode] = int(y.sum())
        auc[mode] = _finite(roc_auc(p, y))
        rate = {
            a: float(np.mean([yy for r, yy in zip(executed, y, strict=True) if r["alternative"] == a]))
            for a in {r["alternative"] for r in executed}
        }
        ceiling[mode] = _finite(roc_auc([rate[r["alternative"]] for r in executed], y))
        brier_by[mode] = _finite(brier(p, y))
        ece_by[mode] = _finite(expected_calibration_error(p, y))
    return observed_by, auc, ceiling, brier_by, ece_by


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
    predicted = [f"{p[k]:.4f}" for k in (*mode_names(), "combined", "expected_loss")]
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
    """The seed's Table 1, at scale: predicted risk and observed failures per alternative."""
    lines = [
        "predicted (on the estimate)  vs  observed (detectors, in physics)",
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
    return "\n".join(lines + _breach_lines(summary))


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
    return "\n".join(rows)


def _reliability(records: Sequence[dict[str, Any]], path: Path) -> Path:
    from executive.decision.audit import atomic_replace
    from executive.validation.stats import reliability_diagram

    curves = [(f"{mode} by P({key})", p, y) for mode, key, p, y in forecasts(_executed(records))]
    return atomic_replace(path, lambda tmp: reliability_diagram(curves, tmp))


# --- the campaign ------------------------------------------------------------------------------


@dataclass
class CampaignResult:
    folder: Path
    summary: dict[str, Any]
    records: list[dict[str, Any]]
    new_trials: int
    elapsed_s: float
    interrupted: bool = False

    @property
    def trials_per_s(self) -> float:
        return self.new_trials / self.elapsed_s if self.elapsed_s > 0 else float("nan")


def _fingerprint(scenario: Scenario) -> str:
    """SHA-256 of the scenario as loaded (its YAML file when it has one)."""
    if scenario.source is not None and Path(scenario.source).is_file():
        return hashlib.sha256(Path(scenario.source).read_bytes()).hexdigest()
    return hashlib.sha256(repr(scenario).encode()).hexdigest()


def _check_resume(folder: Path, config: dict[str, Any]) -> None:
    """The campaign in ``folder`` is the one ``config`` asks for (else an ExecutiveError naming the key)."""
    from executive.decision.audit import read_resume_settings

    keys = ("scenario", "scenario_sha256", "seed", "task", "alternatives")
    how = "the same scenario, seed, task and alternatives"
    read_resume_settings(folder, "campaign.json", config, keys, "a campaign", how)


def unique_trials(
    records: Sequence[dict[str, Any]], trials: int, names: Sequence[str]
) -> tuple[list[dict[str, Any]], int, int]:
    """The records that count: the first of each (trial, alternative) with trial < ``trials``.

    Returns them, the number of duplicates dropped (a record written twice, e.g. by two
    resumes racing) and the number beyond ``trials`` (kept on disk, not counted: a campaign
    resumed with a smaller ``--trials``). So a campaign is complete exactly when every
    (trial, alternative) it asks for is there, whatever else the file holds.
    """
    seen: set[tuple[Any, Any]] = set()
    kept: list[dict[str, Any]] = []
    duplicates = beyond = 0
    for record in records:
        key = (record["trial"], record["alternative"])
        if key in seen:
            duplicates += 1
            continue
        seen.add(key)
        if not isinstance(record["trial"], int) or not 0 <= record["trial"] < trials:
            beyond += 1
            continue
        if record["alternative"] in names:
            kept.append(record)
    return kept, duplicates, beyond


class FolderLock:
    """An exclusive ``flock`` on ``<folder>/.campaign.lock`` while a campaign runs there.

    A second campaign on the same folder (two ``--resume`` at once, say) is refused instead
    of interleaving its trials. The kernel drops the lock when the process ends, however it
    ends (a kill -9 leaves no stale lock). Release with :meth:`release` (or let it be collected).
    """

    def __init__(self, folder: Path) -> None:
        import fcntl

        self._file: IO[bytes] | None = (folder / ".campaign.lock").open("ab")
        try:
            fcntl.flock(self._file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.release()
            raise ExecutiveError(
                f"--out {folder}: another campaign is running in this folder; wait for it to end "
                "(then --resume completes it if it was cut), or choose another --out"
            ) from None

    def release(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _write_config(folder: Path, config: dict[str, Any]) -> None:
    from executive.decision.audit import atomic_write_text

    atomic_write_text(folder / "campaign.json", json.dumps(config, indent=2) + "\n")


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
) -> CampaignResult:
    """Run (or complete) a campaign; write trials.jsonl, summary.json, table.md, reliability.png."""
    n = scenario.trials.count if trials is None else trials
    names = _check_request(scenario, n, jobs, backend, task_index, alternatives)
    task = scenario.mission[task_index]
    base_seed = scenario.trials.seed if seed is None else seed
    folder = _campaign_folder(scenario, out, resume)
    trials_path = folder / "trials.jsonl"
    config = _campaign_config(scenario, base_seed, task_index, names, n)
    lock = _claim_folder(folder, trials_path, config, resume)  # held until the summary is written
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
    run = _execute(scenario, task_index, jobs, backend, folder, names, specs, records, log, stream)
    records.sort(
        key=lambda r: (r["trial"], names.index(r["alternative"]) if r["alternative"] in names else 0)
    )
    summary = summarise(scenario, records, names, run.predictions)
    summary.update(
        task=f"{task_index}: {task.label()}",
        seed=base_seed,
        trials_per_alternative=n,
        complete=len(records) == n * len(names),
        jobs=jobs,
        backend=backend,
        elapsed_s=run.elapsed,
        new_trials=run.new,
        trials_per_s=run.new / run.elapsed if run.elapsed > 0 else None,
        trial_phase_s=_finite(run.trial_phase),  # executing trials only (after planning, before statistics)
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
    unknown = [a for a in names if a not in task.alternatives]
    if unknown:
        raise ExecutiveError(
            f"task {task_index} of {scenario.name} has no alternative {', '.join(unknown)}; "
            f"its alternatives are: {', '.join(task.alternatives)}"
        )
    return names


def _campaign_config(
    scenario: Scenario, base_seed: int, task_index: int, names: list[str], n: int
) -> dict[str, Any]:
    """What campaign.json records: the scenario (and its SHA-256), seed, task, alternatives, trials."""
    return {
        "scenario": scenario.name,
        "source": str(scenario.source) if scenario.source else None,
        "scenario_sha256": _fingerprint(scenario),
        "seed": base_seed,
        "task": task_index,
        "alternatives": names,
        "trials": n,
    }


def _campaign_folder(scenario: Scenario, out: Path | str | None, resume: bool) -> Path:
    """The run folder: ``out``, or a new one under runs/ (not when resuming: that needs ``out``)."""
    from executive.decision.audit import run_folder

    if out is not None:
        return Path(out)
    if resume:
        raise ExecutiveError("--resume needs --out DIR: the run folder of the campaign to complete")
    return run_folder(f"{scenario.name}-campaign")


def _claim_folder(folder: Path, trials_path: Path, config: dict[str, Any], resume: bool) -> FolderLock:
    """Check that ``folder`` holds the campaign ``config`` asks for when resuming (else no trials
    yet), create it, lock it and write ``config`` to it. Returns the lock."""
    if resume:
        _check_resume(folder, config)
    elif trials_path.exists() and trials_path.stat().st_size > 0:
        raise ExecutiveError(
            f"{trials_path} already holds trials: add --resume to complete that campaign, "
            "or choose another --out"
        )
    folder.mkdir(parents=True, exist_ok=True)
    lock = FolderLock(folder)
    _write_config(folder, config)
    return lock


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
) -> _Execution:
    """Predict the alternatives (unless the scene varies) and run the trials ``specs``, each
    appended to ``records`` and to trials.jsonl as it ends, with a progress bar. Ctrl-C stops
    the workers; every finished trial is already on disk."""
    from executive.report.progress_bar import ProgressBar

    t0 = time.perf_counter()
    runner = _Runner(scenario, task_index, jobs, backend, folder)
    interrupted = False
    new = 0
    trial_log = TrialLog(folder / "trials.jsonl")
    bar: ProgressBar | None = None
    predictions: dict[str, Prediction] = {}
    trial_phase = float("nan")
    try:
        _predict(predictions, scenario, runner, names, log)
        t_trials = time.perf_counter()
        bar = ProgressBar(len(records) + len(specs), done=len(records), stream=stream)
        bar.draw(force=True)
        failures = sum(r["outcome"] != "success" for r in records)
        for record in runner.trials(specs):
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
    runner: _Runner,
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
        log(f"  {name:<15} {_prediction_text(predictions[name], scenario.risk.ordering)}")


def _write_results(folder: Path, summary: dict[str, Any], records: list[dict[str, Any]]) -> None:
    """summary.json, table.md and (when any trial ran) reliability.png in ``folder``."""
    from executive.decision.audit import atomic_write_text, to_json, write_summary

    write_summary(folder, to_json(summary))
    atomic_write_text(folder / "table.md", table_markdown(summary) + "\n")
    if records:
        _reliability(records, folder / "reliability.png")
