"""The task the workers run: rows ``(road index, a2, L2, R_WS)`` over a tuple of roads shared once
per source of work, so one pool (and one warm-up) serves a whole study, and a task may span roads
(finaldrive.workers.dispatch cuts the tasks and hands the results back).

A wide task (one that holds several CPUs, :func:`~finaldrive.workers.task.task_cpus`) runs its
designs on as many threads of its process, each taking the next design not yet begun: the engine's
compiled loops release the GIL (``nogil``), and its Python around them is about a tenth of a design
(docs/workers.md, "Wide tasks").
"""

from __future__ import annotations

import itertools
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np

from finaldrive.engine import BatchResult, Road, SimSettings
from finaldrive.workers.task import task_cpus

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
    """The task body: rows ``(road index, a2, L2, R_WS)``; one ``(road index, results)`` per run of a road
    (on :func:`task_cpus` threads, results in the rows' order)."""
    runs = by_road(rows)
    threads = min(task_cpus(), len(rows))
    if threads <= 1:
        return [(road, run_engine(designs, roads[road], settings, vehicle)) for road, designs in runs]
    singles = [(road, designs[i:i + 1]) for road, designs in runs for i in range(len(designs))]
    results: list[BatchResult | None] = [None] * len(singles)
    taken = itertools.count()   # next() of a count is atomic under the GIL
    failed = threading.Event()

    def work() -> None:
        for i in iter(taken.__next__, None):
            if i >= len(singles) or failed.is_set():
                return
            road, design = singles[i]
            try:
                results[i] = run_engine(design, roads[road], settings, vehicle)
            except BaseException:
                failed.set()      # the others stop; the task raises (the dispatcher retries its designs alone)
                raise

    for future in [_pool(threads).submit(work) for _ in range(threads)]:
        future.result()
    done = iter(results)
    return [(road, BatchResult.concat([next(done) for _ in range(len(designs))]))  # type: ignore[misc]
            for road, designs in runs]


_pools: dict[int, ThreadPoolExecutor] = {}


def _pool(threads: int) -> ThreadPoolExecutor:
    """This process's threads for wide tasks of ``threads`` CPUs (kept for the next task)."""
    if threads not in _pools:
        _pools[threads] = ThreadPoolExecutor(threads, thread_name_prefix="finaldrive-design")
    return _pools[threads]


def by_road(rows: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """A task's rows ``(road index, a2, L2, R_WS)`` as runs of one road: ``(road index, design rows)``."""
    index = rows[:, 0].astype(int)
    cuts = np.flatnonzero(np.diff(index)) + 1
    return [(int(index[part[0]]), rows[part, 1:]) for part in np.split(np.arange(len(rows)), cuts) if len(part)]


def warm_up_engine(roads: tuple[Road, ...], settings: SimSettings, vehicle: Vehicle | None) -> None:
    """Make sure this machine's cache holds the engine's compiled code (``compile_engine``: on a node
    that never ran finaldrive, one process compiles and the node's other workers wait for it, instead
    of each compiling for itself; the dispatcher meanwhile runs their tasks again elsewhere), then
    simulate one design for ``WARM_UP_DURATION_S`` so Numba's cached code is loaded before timing."""
    from finaldrive.engine import compile_engine

    compile_engine((settings.method,), later=())()
    settings = settings.with_(duration=WARM_UP_DURATION_S)
    run_engine(np.array([WARM_UP_DESIGN]), roads[0], settings, vehicle)
