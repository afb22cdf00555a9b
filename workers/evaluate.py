"""Designs in, results streamed back: batching, the engine call, and reassembly in order.

Every engine stream is a multi-road stream: rows ``(road index, a2, L2, R_WS)`` over a
tuple of roads that is shared once per call, so one pool (and one warm-up) serves a whole
study, and a batch may span two roads.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Generator, Iterator, Sequence
from contextlib import closing
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from finaldrive.engine import BatchResult, Road, SimSettings
from finaldrive.workers.base import Executor
from finaldrive.workers.batching import BatchSizer
from finaldrive.workers.task import Timed, call_timed

if TYPE_CHECKING:
    from finaldrive.engine import Vehicle

#: Design evaluated once per worker process to load the compiled engine (a Table 14 geometry).
WARM_UP_DESIGN = (0.0, 0.0, 0.093)
#: Simulated time of the warm-up simulation [s].
WARM_UP_DURATION_S = 0.01


def run_engine(designs: np.ndarray, road: Road, settings: SimSettings, vehicle: Vehicle | None) -> BatchResult:
    """``engine.evaluate`` on one road (imported in the worker)."""
    from finaldrive.engine import evaluate

    return evaluate(designs, road, settings, vehicle)


def run_engine_on_roads(
    rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings, vehicle: Vehicle | None
) -> list[tuple[int, BatchResult]]:
    """The task body: rows ``(road index, a2, L2, R_WS)``; one ``(road index, results)`` per run of a road."""
    return [(road, run_engine(designs, roads[road], settings, vehicle)) for road, designs in by_road(rows)]


def by_road(rows: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """A task's rows ``(road index, a2, L2, R_WS)`` as runs of one road: ``(road index, design rows)``."""
    index = rows[:, 0].astype(int)
    cuts = np.flatnonzero(np.diff(index)) + 1
    return [(int(index[part[0]]), rows[part, 1:]) for part in np.split(np.arange(len(rows)), cuts) if len(part)]


def warm_up_engine(roads: tuple[Road, ...], settings: SimSettings, vehicle: Vehicle | None) -> None:
    """Simulate one design for ``WARM_UP_DURATION_S`` so Numba's cached code is loaded before timing."""
    settings = settings.with_(duration=WARM_UP_DURATION_S)
    run_engine(np.array([WARM_UP_DESIGN]), roads[0], settings, vehicle)


def stream_rows(
    executor: Executor,
    fn: Callable[..., Any],
    rows: np.ndarray,
    shared: tuple[Any, ...] = (),
    *,
    batch_size: int | None = None,
    warmup: Callable[..., None] | None = None,
) -> Generator[tuple[np.ndarray, Any], None, None]:
    """Cut ``rows`` into batches, run ``fn(batch, *shared)`` on ``executor``, yield as batches finish.

    Yields ``(row indices, result)``. ``batch_size=None`` sizes batches adaptively
    (:mod:`workers.batching`); batches are generated only when the executor has a free slot.
    ``warmup(*shared)`` runs once per worker process before its first batch.
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
            sizer.observe(stop - start, time.perf_counter() - handed_at[index], out.busy_s, out.compute_s, out.idle_s)
            yield np.arange(start, stop), out.result


def evaluate_roads_stream(
    executor: Executor,
    plan: Sequence[tuple[Road, np.ndarray]],
    settings: SimSettings,
    vehicle: Vehicle | None = None,
    *,
    batch_size: int | None = None,
) -> Generator[tuple[int, np.ndarray, BatchResult], None, None]:
    """Evaluate each road's designs (n_r, 3); yield ``(road index, row indices into that road's
    designs, their results)`` as batches complete. Roads, settings and vehicle are sent once."""
    parts = [np.asarray(designs, dtype=float) for _, designs in plan]
    for designs in parts:
        if designs.ndim != 2 or designs.shape[1] != 3:
            raise ValueError(f"designs must have shape (n, 3), got {designs.shape}")
    rows = np.concatenate(
        [np.zeros((0, 4))] + [np.column_stack([np.full(len(d), float(r)), d]) for r, d in enumerate(parts)]
    )
    offsets = np.cumsum([0] + [len(d) for d in parts])
    roads = tuple(road for road, _ in plan)
    stream = stream_rows(
        executor, run_engine_on_roads, rows, (roads, settings, vehicle),
        batch_size=batch_size, warmup=warm_up_engine,
    )
    return _split_by_road(stream, offsets)


def _split_by_road(
    stream: Generator[tuple[np.ndarray, list[tuple[int, BatchResult]]], None, None], offsets: np.ndarray
) -> Generator[tuple[int, np.ndarray, BatchResult], None, None]:
    with closing(stream):
        for flat, runs in stream:
            start = int(flat[0])
            for road, result in runs:
                local = np.arange(start, start + len(result)) - offsets[road]
                start += len(result)
                yield road, local, result


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
    stream = evaluate_roads_stream(executor, [(road, designs)], settings, vehicle, batch_size=batch_size)
    return _drop_road(stream)


def _drop_road(
    stream: Generator[tuple[int, np.ndarray, BatchResult], None, None],
) -> Generator[tuple[np.ndarray, BatchResult], None, None]:
    with closing(stream):
        for _, rows, result in stream:
            yield rows, result


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
