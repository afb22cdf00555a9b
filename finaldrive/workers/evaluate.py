"""The task the workers run: rows ``(road index, a2, L2, R_WS)`` over a tuple of roads shared once
per source of work, so one pool (and one warm-up) serves a whole study, and a task may span roads
(finaldrive.workers.dispatch cuts the tasks and hands the results back).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from finaldrive.engine import BatchResult, Road, SimSettings

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
    """Make sure this machine's cache holds the engine's compiled code (``compile_engine``: on a node
    that never ran finaldrive, one process compiles and the node's other workers wait for it, instead
    of each compiling for itself; the dispatcher meanwhile runs their tasks again elsewhere), then
    simulate one design for ``WARM_UP_DURATION_S`` so Numba's cached code is loaded before timing."""
    from finaldrive.engine import compile_engine

    compile_engine((settings.method,), later=())()
    settings = settings.with_(duration=WARM_UP_DURATION_S)
    run_engine(np.array([WARM_UP_DESIGN]), roads[0], settings, vehicle)
