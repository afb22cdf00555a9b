"""Fixed batches through an executor, for the executors' tests (the service's way in is
finaldrive.workers.dispatch.Dispatcher)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import Any

from finaldrive.workers import Done, Executor


def run_batches(executor: Executor, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = (),
                timeout: float = 120.0, arrivals: list[float] | None = None) -> dict[int, Done]:
    """Submit ``fn(batch, *shared)`` for every batch (``shared`` shared once, released at the end) and
    wait for each: batch index -> its ``Done`` (``arrivals``: each one's time since the submission [s])."""
    handles = [executor.share(value) for value in shared]
    try:
        start = time.perf_counter()
        ids = {executor.submit(fn, batch, *handles): i for i, batch in enumerate(batches)}
        out: dict[int, Done] = {}
        deadline = time.monotonic() + timeout
        while len(out) < len(ids):
            assert time.monotonic() < deadline, f"{len(ids) - len(out)} batches did not come back in {timeout} s"
            for done in executor.poll(1.0):
                if done.task in ids:
                    out[ids[done.task]] = done
                    if arrivals is not None:
                        arrivals.append(time.perf_counter() - start)
        return out
    finally:
        for handle in handles:
            executor.release(handle)


def results(executor: Executor, fn: Callable[..., Any], batches: Iterable[Any],
            shared: tuple[Any, ...] = ()) -> dict[int, Any]:
    """Each batch's result (batch index -> result); a task's error is raised, a lost or cancelled
    task fails the test."""
    out = {}
    for index, done in sorted(run_batches(executor, fn, batches, shared).items()):
        if done.error is not None:
            raise done.error
        assert done.ok, f"batch {index}: {done}"
        out[index] = done.result
    return out
