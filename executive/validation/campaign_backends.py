"""Where a campaign's predictions and trials run: this process, a process pool, or Ray.

:class:`Runner` runs them on a backend (:data:`Backend`): ``local`` is this process for one
job, else a pool of ``jobs`` spawned processes; ``ray`` is Ray tasks (``pip install
.[cluster]``) on the cluster at ``RAY_ADDRESS``, else on a local one with ``jobs`` CPUs.
Trials come back in the order asked, whatever the backend. A campaign that decides per
trial (``decide``) sends each worker a whole trial: its decision
(:func:`~executive.validation.campaign_decisions.decide_trial`) and its alternatives executed.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
from collections.abc import Iterator, Sequence
from itertools import groupby
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from executive.errors import ExecutiveError
from executive.schema.types import Scenario
from executive.validation.campaign_decisions import decide_trial
from executive.validation.campaign_predictions import Prediction, predict
from executive.validation.campaign_trials import run_trial

if TYPE_CHECKING:
    from executive.decision.physics_check import RolloutJob

__all__ = ["Backend", "Runner"]

Backend = Literal["local", "ray"]


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


def _decision_in_worker(spec: tuple[tuple[str, ...], int, int, tuple[str, ...]]) -> list[dict[str, Any]]:
    names, index, seed, run = spec
    return decide_trial(_WORKER["scenario"], _WORKER["task_index"], names, index, seed, run)


def _ray_decision(
    scenario: Scenario, task_index: int, spec: tuple[tuple[str, ...], int, int, tuple[str, ...]]
) -> list[dict[str, Any]]:
    names, index, seed, run = spec
    return decide_trial(scenario, task_index, names, index, seed, run)


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


class Runner:
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

    def decisions(
        self, names: Sequence[str], specs: Sequence[tuple[int, str, int]]
    ) -> Iterator[dict[str, Any]]:
        """Decide each trial of ``specs`` among ``names`` and execute its alternatives of ``specs``
        (a worker per trial); the records in the order of ``specs``."""
        work = [
            (tuple(names), index, seed, tuple(a for _, a, _ in group))
            for (index, seed), group in ((k, list(g)) for k, g in groupby(specs, key=lambda s: (s[0], s[2])))
        ]
        if self._ray is not None:
            remote = self._ray.remote(_ray_decision)
            refs = [remote.remote(self.scenario, self.task_index, spec) for spec in work]
            for ref in refs:
                yield from self._ray.get(ref)
        elif self._pool is not None:
            for records in self._pool.imap(_decision_in_worker, work, chunksize=1):
                yield from records
        else:
            for spec in work:
                yield from _decision_in_worker(spec)

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
