"""The audit log of a run: every decision, one JSON line each, flushed as it is made.

A run folder (default ``runs/<UTC timestamp>-<scenario>/``) holds:

* ``decisions.jsonl``: one JSON object per line, in order: ``{"seq", "at", "kind", ...}``
  where ``kind`` is one of ``run`` (start: scenario, truth, approval channel),
  ``plan`` (an alternative planned or found infeasible, with its risk report),
  ``selection`` (the ranking and the alternative chosen), ``approval_request``,
  ``approval`` (decision, by whom, when), ``execute`` (an alternative starts),
  ``guard`` (a live guard tripped), ``behaviour`` (a behaviour finished, its status
  and message), ``failure`` (a failure detector's verdict), ``outcome`` (a task
  ends) and ``end`` (the run ends). Each line is written, flushed and fsync'ed
  before the executive acts on the decision, so a crash or a kill loses
  nothing already decided.
  Every line carries the run's ``run_id`` (a UUID4 made when the log opens, also in
  ``summary.json``), so lines of two runs can never pass for one.
* ``summary.json``: written at the end, atomically, before the ``end`` line (see
  :func:`write_summary`).
* the plots of ``executive plan --plot``.

A folder holds one run: opening the log claims it by creating ``decisions.jsonl``
with ``O_CREAT | O_EXCL`` (atomic, so of two runs started on one folder one is
refused), and a folder that already holds a run's files is refused with a
:class:`RunFolderError` unless the log is opened with ``resume=True``.
"""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
import uuid
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from executive.errors import ExecutiveError

__all__ = [
    "AuditLog",
    "RunFolderError",
    "atomic_replace",
    "atomic_write_text",
    "claim_folder",
    "now_iso",
    "read_resume_settings",
    "run_folder",
    "to_json",
    "write_summary",
]

#: Files that make a folder a run's (or a campaign's, a suite's): another run may not use it.
RUN_FILES = ("decisions.jsonl", "summary.json", "trials.jsonl", "campaign.json", "suite.json")


class RunFolderError(ExecutiveError):
    """A run folder cannot be used: another run's already, or not writable."""


def now_iso() -> str:
    """The current UTC time, ISO 8601 with milliseconds and the zone."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def to_json(value: Any) -> Any:
    """``value`` with numpy scalars/arrays, tuples, paths and non-finite floats made JSON-safe."""
    if isinstance(value, dict):
        return {str(k): to_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_json(value.tolist())
    if isinstance(value, np.generic):
        return to_json(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, Path):
        return str(value)
    return value


def atomic_write_text(path: Path | str, text: str) -> Path:
    """Write ``text`` to ``path`` whole or not at all: a temporary file in the same folder,
    flushed to disk, then renamed over ``path`` (``os.replace``), so a reader (or a run
    killed meanwhile) sees the old file or the new one, never a cut one."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_replace(path: Path | str, write: Callable[[Path], object]) -> Path:
    """``write(tmp)`` writes a file (a picture, say) to a temporary path in ``path``'s folder,
    which is then renamed over ``path``: readers see the old file or the new one."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def read_resume_settings(
    folder: Path, name: str, config: dict[str, Any], keys: Sequence[str], what: str, how: str
) -> None:
    """Check that the settings file ``folder/name`` (JSON) is the one ``config`` asks to resume.

    Args:
        folder: the campaign's or suite's folder.
        name: its settings file (``campaign.json``, ``suite.json``).
        config: the settings of this run.
        keys: the settings that must match.
        what: what the folder holds, for messages ("a campaign", "a fidelity suite").
        how: what to resume with, for messages ("the same scenario, seed, task and alternatives").

    Raises:
        ExecutiveError: the file is missing, cut, not a JSON object, or made with other settings.
    """
    from executive.errors import ExecutiveError

    path = folder / name
    if not path.is_file():
        raise ExecutiveError(f"--resume: {folder} holds no {name} (is it {what}'s folder?)")
    try:
        old = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ExecutiveError(
            f"--resume: {path} cannot be read as JSON ({exc}); it was cut or edited: "
            "start anew with another --out"
        ) from None
    if not isinstance(old, dict):
        raise ExecutiveError(f"--resume: {path} is not {what}'s settings (a JSON object expected)")
    for key in keys:
        if old.get(key) != config[key]:
            raise ExecutiveError(
                f"--resume: {what} in {folder} was made with {key} = {old.get(key)!r}; this run asks "
                f"for {config[key]!r}. Resume with {how}, or start anew with another --out"
            )


def run_folder(scenario_name: str, base: Path | str = "runs") -> Path:
    """A new folder ``<base>/<YYYYmmdd-HHMMSS>-<scenario>`` (a ``-2``, ``-3``... suffix if taken).

    The folder is created here (``mkdir`` fails on a name taken meanwhile), so two runs
    started in the same second get two folders.
    """
    stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", scenario_name) or "scenario"
    root = Path(base)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunFolderError(f"run folder {root}: cannot create it ({exc.strerror or exc})") from None
    n = 1
    while True:
        folder = root / (f"{stamp}-{safe}" if n == 1 else f"{stamp}-{safe}-{n}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            n += 1
        except OSError as exc:
            raise RunFolderError(f"run folder {folder}: cannot create it ({exc.strerror or exc})") from None


def claim_folder(folder: Path, *, resume: bool = False) -> int:
    """Create ``folder`` and open its ``decisions.jsonl`` for appending; the descriptor.

    Without ``resume`` the file is created with ``O_EXCL``: of two runs given one folder
    only the first gets it; a folder holding a run's files (:data:`RUN_FILES`) is refused.

    Raises:
        RunFolderError: the folder is another run's, or cannot be created or written.
    """
    used = [name for name in RUN_FILES if (folder / name).exists()]
    if used and not resume:
        raise RunFolderError(
            f"run folder {folder} is already used by another run (it holds {', '.join(used)}); "
            "choose another --out, or leave --out out for a new folder under runs/"
        )
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | (0 if resume else os.O_EXCL)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return os.open(folder / "decisions.jsonl", flags, 0o644)
    except FileExistsError:
        raise RunFolderError(
            f"run folder {folder} is already used by another run (decisions.jsonl appeared while "
            "this run started); choose another --out"
        ) from None
    except OSError as exc:
        raise RunFolderError(f"run folder {folder}: cannot write there ({exc.strerror or exc})") from None


class AuditLog:
    """Append-only JSON-lines log of a run's decisions; also kept in memory (``entries``).

    ``folder`` None keeps the log in memory only (an embedding host that logs elsewhere).
    Opening a folder claims it (:func:`claim_folder`); ``resume`` appends to a run folder
    already used. Each line is one ``write`` to a file opened ``O_APPEND``, then fsync'ed:
    a kill leaves whole lines only. ``run_id`` (UUID4) is in every line.
    """

    def __init__(self, folder: Path | str | None, *, fsync: bool = True, resume: bool = False) -> None:
        self.folder = Path(folder) if folder is not None else None
        self.run_id = str(uuid.uuid4())
        self.entries: list[dict[str, Any]] = []
        self._fsync = fsync
        self._fd: int | None = None
        if self.folder is not None:
            self._fd = claim_folder(self.folder, resume=resume)

    @property
    def path(self) -> Path | None:
        return self.folder / "decisions.jsonl" if self.folder is not None else None

    def record(self, kind: str, **fields: Any) -> dict[str, Any]:
        """Write one decision line (and flush it to disk) before returning it."""
        entry = {
            "seq": len(self.entries),
            "at": now_iso(),
            "run_id": self.run_id,
            "kind": kind,
            **to_json(fields),
        }
        data = (json.dumps(entry, allow_nan=False) + "\n").encode("utf-8")
        self.entries.append(entry)
        if self._fd is not None:
            view = memoryview(data)
            while view:
                view = view[os.write(self._fd, view) :]
            if self._fsync:
                os.fsync(self._fd)
        return entry

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.entries if e["kind"] == kind]

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)

    def abandon(self) -> None:
        """Close the log and give the folder back if nothing was written (a run that never started)."""
        self.close()
        path = self.path
        if path is not None and not self.entries and path.is_file() and path.stat().st_size == 0:
            path.unlink(missing_ok=True)

    def __enter__(self) -> AuditLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_summary(folder: Path | str, summary: dict[str, Any]) -> Path:
    """Write ``summary.json`` atomically (:func:`atomic_write_text`): whole or the old one."""
    text = json.dumps(to_json(summary), indent=2, allow_nan=False) + "\n"
    return atomic_write_text(Path(folder) / "summary.json", text)
