"""A text progress bar for long batch work (campaign trials): done/total, rate, ETA.

On a terminal the bar is redrawn in place at most every ``refresh_s``; otherwise
(a log file, CI) a line is printed every ``step`` fraction of the work, so logs
stay short.
"""

from __future__ import annotations

import sys
import time
from typing import IO

__all__ = ["ProgressBar", "format_duration"]


def format_duration(seconds: float) -> str:
    """``1h02m``, ``4m05s`` or ``12s``; ``?`` when unknown."""
    if seconds != seconds or seconds < 0 or seconds == float("inf"):
        return "?"
    s = round(seconds)
    if s >= 3600:
        return f"{s // 3600}h{(s % 3600) // 60:02d}m"
    if s >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s}s"


class ProgressBar:
    """``label  37/300 [#####.....]  2.31 trials/s  ETA 1m54s``.

    ``done`` counts work finished before this bar started (a resumed campaign): it
    shows in the count but not in the rate.
    """

    def __init__(
        self,
        total: int,
        *,
        done: int = 0,
        label: str = "trials",
        unit: str = "trials",
        stream: IO[str] | None = None,
        width: int = 30,
        refresh_s: float = 0.2,
        step: float = 0.1,
    ) -> None:
        self.total = total
        self.done = done
        self.label = label
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.refresh_s = refresh_s
        self.step = step
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._start_done = done
        self._t0 = time.monotonic()
        self._last_draw = -1.0
        self._last_printed_fraction = -1.0
        self.extra = ""

    @property
    def rate(self) -> float:
        """Finished per second since the bar started (0 before the first)."""
        elapsed = time.monotonic() - self._t0
        new = self.done - self._start_done
        return new / elapsed if elapsed > 0 and new > 0 else 0.0

    @property
    def eta_s(self) -> float:
        rate = self.rate
        return (self.total - self.done) / rate if rate > 0 else float("nan")

    def line(self) -> str:
        fraction = self.done / self.total if self.total else 1.0
        filled = round(self.width * fraction)
        bar = "#" * filled + "." * (self.width - filled)
        rate = f"{self.rate:.2f} {self.unit}/s" if self.rate > 0 else f"- {self.unit}/s"
        tail = f"  {self.extra}" if self.extra else ""
        return (
            f"{self.label} {self.done}/{self.total} [{bar}] {rate}  "
            f"ETA {format_duration(self.eta_s)}  elapsed {format_duration(time.monotonic() - self._t0)}{tail}"
        )

    def advance(self, n: int = 1, extra: str | None = None) -> None:
        self.done += n
        if extra is not None:
            self.extra = extra
        self.draw()

    def draw(self, force: bool = False) -> None:
        now = time.monotonic()
        if self.tty:
            if force or now - self._last_draw >= self.refresh_s or self.done >= self.total:
                self._last_draw = now
                self.stream.write("\r\x1b[2K" + self.line())
                self.stream.flush()
            return
        fraction = self.done / self.total if self.total else 1.0
        if force or fraction - self._last_printed_fraction >= self.step or self.done >= self.total:
            if fraction == self._last_printed_fraction and not force:
                return
            self._last_printed_fraction = fraction
            self.stream.write(self.line() + "\n")
            self.stream.flush()

    def close(self) -> None:
        """End the bar's line on a terminal."""
        if self.tty:
            self.draw(force=True)
            self.stream.write("\n")
            self.stream.flush()
