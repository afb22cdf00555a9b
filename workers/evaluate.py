"""Designs in, results streamed back: batching, the engine call, and reassembly in order."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import closing
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from engine.api import BatchResult, SimSettings
from engine.model.road import Road
from workers.base import Executor
from workers.batching import BatchSizer
from workers.task import Timed, call_timed

if TYPE_CHECKING:
    from engine.vehicle import Vehicle


def run_engine(designs: np.ndarray, road: Road, settings: SimSettings, vehicle: Vehicle | None) -> BatchResult:
    """The task body: ``engine.evaluate`` on one batch (imported in the worker)."""
    from engine import evaluate

    return evaluate(designs, road, settings, vehicle)


def warm_up_engine() -> None:
    """Call ``engine.warmup()`` if the engine provides one (loads compiled code once per process)."""
    import engine

    warmup = getattr(engine, "warmup", None)
    if callable(warmup):
        warmup()


def stream_rows(
    executor: Executor,
    fn: Callable[..., Any],
    rows: np.ndarray,
    shared: tuple[Any, ...] = (),
    *,
    batch_size: int | None = None,
    warmup: Callable[[], None] | None = None,
) -> Iterator[tuple[np.ndarray, Any]]:
    """Cut ``rows`` into batches, run ``fn(batch, *shared)`` on ``executor``, yield as batches finish.

    Yields ``(row indices, result)``. ``batch_size=None`` sizes batches adaptively
    (:mod:`workers.batching`); batches are generated only when the executor has a free slot.
    """
    if batch_size is not None and batch_size < 1:
        raise ValueError("batch_size must be >= 1")
    n = len(rows)
    sizer = BatchSizer(executor.num_workers)
    spans: list[tuple[int, int]] = []
    handed_at: list[float] = []

    def batches() -> Iterator[np.ndarray]:
        start = 0
        while start < n:
            stop = min(n, start + (batch_size or sizer.next_size(n - start)))
            spans.append((start, stop))
            handed_at.append(time.perf_counter())
            yield rows[start:stop]
            start = stop

    out: Timed
    with closing(executor.map_batches(partial(call_timed, fn, warmup), batches(), shared)) as stream:
        for index, out in stream:
            start, stop = spans[index]
            sizer.observe(stop - start, time.perf_counter() - handed_at[index], out.busy_s, out.compute_s)
            yield np.arange(start, stop), out.result


def evaluate_stream(
    executor: Executor,
    designs: np.ndarray,
    road: Road,
    settings: SimSettings,
    vehicle: Vehicle | None = None,
    *,
    batch_size: int | None = None,
) -> Iterator[tuple[np.ndarray, BatchResult]]:
    """Evaluate ``designs`` (n, 3) on ``road``; yield ``(row indices into designs, their results)``
    as batches complete. ``road``, ``settings`` and ``vehicle`` are sent once per call."""
    designs = np.asarray(designs, dtype=float)
    if designs.ndim != 2 or designs.shape[1] != 3:
        raise ValueError(f"designs must have shape (n, 3), got {designs.shape}")
    return stream_rows(
        executor, run_engine, designs, (road, settings, vehicle),
        batch_size=batch_size, warmup=warm_up_engine,
    )


def evaluate_all(
    executor: Executor,
    designs: np.ndarray,
    road: Road,
    settings: SimSettings,
    vehicle: Vehicle | None = None,
    *,
    on_progress: Callable[[int, int], None] | None = None,
) -> BatchResult:
    """Evaluate every design and return the results in input order.

    ``on_progress(done, total)`` is called after each batch completes.
    """
    total = len(designs)
    parts: dict[int, BatchResult] = {}
    done = 0
    for rows, result in evaluate_stream(executor, designs, road, settings, vehicle):
        parts[int(rows[0])] = result
        done += len(rows)
        if on_progress is not None:
            on_progress(done, total)
    return BatchResult.concat([parts[start] for start in sorted(parts)])
