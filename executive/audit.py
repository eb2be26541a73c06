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
* ``summary.json``: written at the end (see :func:`write_summary`).
* the plots of ``executive plan --plot``.
"""

from __future__ import annotations

import json
import math
import os
import re
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = ["AuditLog", "now_iso", "run_folder", "to_json", "write_summary"]


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


def run_folder(scenario_name: str, base: Path | str = "runs") -> Path:
    """A new folder ``<base>/<YYYYmmdd-HHMMSS>-<scenario>`` (a ``-2``, ``-3``... suffix if taken)."""
    stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", scenario_name) or "scenario"
    root = Path(base)
    folder = root / f"{stamp}-{safe}"
    n = 2
    while folder.exists():
        folder = root / f"{stamp}-{safe}-{n}"
        n += 1
    return folder


class AuditLog:
    """Append-only JSON-lines log of a run's decisions; also kept in memory (``entries``).

    ``folder`` None keeps the log in memory only (an embedding host that logs elsewhere).
    """

    def __init__(self, folder: Path | str | None, *, fsync: bool = True) -> None:
        self.folder = Path(folder) if folder is not None else None
        self.entries: list[dict[str, Any]] = []
        self._fsync = fsync
        self._file: IO[str] | None = None
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._file = (self.folder / "decisions.jsonl").open("a", encoding="utf-8")

    @property
    def path(self) -> Path | None:
        return self.folder / "decisions.jsonl" if self.folder is not None else None

    def record(self, kind: str, **fields: Any) -> dict[str, Any]:
        """Write one decision line (and flush it to disk) before returning it."""
        entry = {"seq": len(self.entries), "at": now_iso(), "kind": kind, **to_json(fields)}
        line = json.dumps(entry, allow_nan=False)
        self.entries.append(entry)
        if self._file is not None and not self._file.closed:
            self._file.write(line + "\n")
            self._file.flush()
            if self._fsync:
                os.fsync(self._file.fileno())
        return entry

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.entries if e["kind"] == kind]

    def close(self) -> None:
        if self._file is not None and not self._file.closed:
            self._file.close()

    def __enter__(self) -> AuditLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_summary(folder: Path | str, summary: dict[str, Any]) -> Path:
    """Write ``summary.json`` atomically (a temporary file renamed over it)."""
    path = Path(folder) / "summary.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(to_json(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path
