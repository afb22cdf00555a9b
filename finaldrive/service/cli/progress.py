"""A progress line on stderr for long local runs: done/total, failed, best so far, ETA.

On a terminal the line is redrawn in place (at most 10 times a second). With
``--progress`` into a pipe or file it prints plain lines instead, at most one every 2 s,
so logs stay readable. Without a terminal and without ``--progress`` it prints nothing.
"""

from __future__ import annotations

import math
import sys
import time
from typing import TextIO

BAR_WIDTH = 24
REDRAW_S = 0.1     # terminal
LINE_EVERY_S = 2.0  # pipe or file


class Progress:
    """Tracks simulations done and failed and the best fitness, and reports them on ``stream``."""

    def __init__(self, total: int, *, enabled: bool | None = None, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty()
        self.enabled = self.live if enabled is None else enabled
        self.total = total
        self.done = 0
        self.failed = 0
        self.best = math.nan
        self._start = time.monotonic()
        self._shown = -math.inf
        self._open = False     # a live line is on screen without its newline

    def update(self, done: int = 0, failed: int = 0, best: float | None = None) -> None:
        """Add ``done`` simulations (``failed`` of them failed); ``best`` replaces the best so far."""
        self.done += done
        self.failed += failed
        if best is not None and math.isfinite(best):
            self.best = best
        now = time.monotonic()
        if self.enabled and now - self._shown >= (REDRAW_S if self.live else LINE_EVERY_S):
            self._show(now)

    def close(self) -> None:
        """Show the final state and end the line."""
        if self.enabled:
            self._show(time.monotonic())
            if self._open:
                self.stream.write("\n")
                self.stream.flush()
                self._open = False

    def line(self, now: float) -> str:
        """The progress text (no control characters)."""
        elapsed = now - self._start
        total = max(self.total, self.done, 1)
        filled = round(BAR_WIDTH * self.done / total)
        eta = elapsed / self.done * (total - self.done) if self.done else math.nan
        best = f"{self.best:.3f} m" if math.isfinite(self.best) else "-"
        return (f"[{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {self.done}/{self.total} "
                f"failed {self.failed}  best {best}  elapsed {_clock(elapsed)}  ETA {_clock(eta)}")

    def _show(self, now: float) -> None:
        self._shown = now
        if self.live:
            self.stream.write("\r\x1b[K" + self.line(now))
            self._open = True
        else:
            self.stream.write(self.line(now) + "\n")
        self.stream.flush()


def _clock(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "--:--"
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes:02d}:{secs:02d}"
