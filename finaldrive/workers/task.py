"""Worker-side wrapper: optional one-off warm-up per process, then ``fn`` timed; and how many CPUs
the running task holds (a wide task's body spreads its designs over that many threads).

Imported in every worker process; it must stay free of engine and Ray imports.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

_warmed_up: set[str] = set()  # warm-ups already run in this process
_last_end: list[float] = []    # when this process's previous task ended (perf_counter)
_cpus = [1]                    # CPUs the running task holds (set by its executor)


def task_cpus() -> int:
    """CPUs the task running in this process holds: 1, unless its executor gave it more (a wide task,
    ``RayExecutor(task_cpus=...)``)."""
    return _cpus[0]


def hold_cpus(cpus: int) -> None:
    """Called by an executor in the worker before a task: the task holds ``cpus`` CPUs."""
    _cpus[0] = max(1, int(cpus))


@dataclass(frozen=True)
class Timed:
    """A batch's result with its in-worker times [s]; ``busy_s`` includes any warm-up; ``idle_s``:
    from the end of the process's previous task to this one's start (None for its first), the
    per-task cost of the executor's round trip while work is queued (batching rule 2)."""

    result: Any
    busy_s: float
    compute_s: float
    idle_s: float | None = None


def call_timed(
    fn: Callable[..., Any], warmup: Callable[..., None] | None, batch: Any, *shared: Any
) -> Timed:
    """Run ``warmup(*shared)`` once per process (e.g. load Numba's disk cache), then ``fn(batch, *shared)``."""
    start = time.perf_counter()
    if warmup is not None:
        name = getattr(warmup, "__qualname__", None)
        key = f"{warmup.__module__}.{name}" if name else repr(warmup)
        if key not in _warmed_up:
            warmup(*shared)
            _warmed_up.add(key)
    begin = time.perf_counter()
    result = fn(batch, *shared)
    end = time.perf_counter()
    idle = start - _last_end[0] if _last_end else None
    _last_end[:] = [end]
    return Timed(result, busy_s=end - start, compute_s=end - begin, idle_s=idle)
