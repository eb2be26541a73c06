"""A campaign's run folder: its trials file, its configuration and its lock.

``trials.jsonl`` holds one trial record per line (:class:`TrialLog` appends and fsyncs each;
:func:`read_trials` reads them back, dropping a line cut short). ``campaign.json`` records
what the campaign asks for, so that ``--resume`` completes only the same campaign
(:func:`claim_folder`); ``.campaign.lock`` keeps a second campaign out while one runs
(:class:`FolderLock`). :func:`unique_trials` picks the records that count.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

from executive.errors import ExecutiveError
from executive.schema.failure_modes import failure_modes
from executive.schema.types import Scenario

__all__ = [
    "FolderLock",
    "TrialLog",
    "campaign_config",
    "campaign_folder",
    "claim_folder",
    "read_trials",
    "unique_trials",
]


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
    old = json.loads((folder / "campaign.json").read_text(encoding="utf-8"))
    made = bool(old.get("decide", False))
    if made != config["decide"]:
        run, flag = ("decides per trial", "with") if made else ("predicts on the estimate", "without")
        raise ExecutiveError(
            f"--resume: the campaign in {folder} {run}; resume it {flag} --decide, "
            "or start anew with another --out"
        )
    if made and old.get("rollouts") != config["rollouts"]:  # each decision's rollouts
        raise ExecutiveError(
            f"--resume: the campaign in {folder} decided with {old.get('rollouts')} rollouts per "
            f"alternative; this run asks for {config['rollouts']}. Resume with the same, or start anew "
            "with another --out"
        )


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


def campaign_config(
    scenario: Scenario, base_seed: int, task_index: int, names: list[str], n: int, decide: bool = False
) -> dict[str, Any]:
    """What campaign.json records: the scenario (and its SHA-256), seed, task, alternatives,
    trials, and whether each trial decides as the executive does (``decide``)."""
    return {
        "scenario": scenario.name,
        "source": str(scenario.source) if scenario.source else None,
        "scenario_sha256": _fingerprint(scenario),
        "seed": base_seed,
        "task": task_index,
        "alternatives": names,
        "trials": n,
        "decide": decide,
        "rollouts": scenario.risk.rollouts.count,
    }


def campaign_folder(scenario: Scenario, out: Path | str | None, resume: bool) -> Path:
    """The run folder: ``out``, or a new one under runs/ (not when resuming: that needs ``out``)."""
    from executive.decision.audit import run_folder

    if out is not None:
        return Path(out)
    if resume:
        raise ExecutiveError("--resume needs --out DIR: the run folder of the campaign to complete")
    return run_folder(f"{scenario.name}-campaign")


def claim_folder(folder: Path, trials_path: Path, config: dict[str, Any], resume: bool) -> FolderLock:
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
