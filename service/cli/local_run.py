"""Running a study in this process and its workers (``optimize``, ``sweep``): no service, no store.

The study's runs (finaldrive.engine.study) say what to simulate; each wave hands every run's
ready requests to the executor as one stream, and results go back to their runs as they
arrive. Progress goes to stderr. The executor is always closed, also on Ctrl-C.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from finaldrive.service.cli.common import UsageError, clean
from finaldrive.service.cli.progress import Progress

if TYPE_CHECKING:
    from finaldrive.engine import BatchResult, Request, Run, SimSettings, StudyPlan, Vehicle
    from finaldrive.workers import Executor

#: What the caller learns of each finished part of a request: the part, its results and fitness.
OnResult = Callable[["Request", "BatchResult", np.ndarray], None]


def default_executor() -> str:
    """``process`` when this machine has more than one core, else ``serial``."""
    return "process" if (os.cpu_count() or 1) > 1 else "serial"


def open_executor(kind: str, workers: int | None) -> Executor:
    from finaldrive.workers import make_executor

    if workers is not None and workers < 1:
        raise UsageError("--workers must be >= 1")
    try:
        return make_executor(kind, num_workers=workers)  # type: ignore[arg-type]
    except ImportError as exc:
        raise UsageError(str(exc)) from None


def run_waves(runs: list[Run], plan: StudyPlan, settings: SimSettings, vehicle: Vehicle, executor: Executor,
              on_result: OnResult) -> None:
    """Evaluate until every run is done: each wave is every run's ready work, in one stream."""
    from finaldrive.engine import fitness_values
    from finaldrive.workers import evaluate_roads_stream

    by_index = {run.index: run for run in runs}
    while requests := [q for run in runs if not run.done for q in run.take()]:
        stream = evaluate_roads_stream(executor, [(plan.roads[q.road].road, q.designs) for q in requests],
                                       settings, vehicle)
        for i, rows, batch in stream:
            part = requests[i].part(rows)
            fitness = fitness_values(batch)
            on_result(part, batch, fitness)
            by_index[part.run].tell(part.road, part.step, part.candidates, fitness)


def design_dict(x: np.ndarray) -> dict[str, float]:
    return {"a2_deg": math.degrees(float(x[0])), "l2": float(x[1]), "rws": float(x[2])}


def result_dict(batch: BatchResult, fitness: np.ndarray, i: int) -> dict[str, Any]:
    """Design and outcome of row ``i`` of a batch (JSON-ready)."""
    return {**design_dict(batch.designs[i]), "fitness_m": clean(fitness[i]),
            "distance_m": clean(batch.distance_m[i]), "squat_ratio": clean(batch.squat_ratio[i]),
            "slack_mm": clean(batch.slack_m[i] * 1000.0)}


@dataclass
class Tally:
    """Every evaluated design's result on every road, each road's best, and the progress line."""

    n_roads: int
    progress: Progress
    results: dict[tuple[float, ...], dict[int, dict[str, Any]]] = field(default_factory=dict)
    road_best: dict[int, tuple[float, dict[str, Any]]] = field(default_factory=dict)

    def __call__(self, part: Request, batch: BatchResult, fitness: np.ndarray) -> None:
        for i in range(len(part)):
            row = result_dict(batch, fitness, i)
            self.results.setdefault(tuple(part.designs[i]), {})[part.road] = row
            best = self.road_best.get(part.road)
            if math.isfinite(fitness[i]) and (best is None or fitness[i] > best[0]):
                self.road_best[part.road] = (float(fitness[i]), row)
        ok = np.isfinite(fitness)
        best_f = max((f for f, _ in self.road_best.values()), default=None) if self.n_roads == 1 else None
        self.progress.update(done=len(part), failed=int((~ok).sum()), best=best_f)

    def on_roads(self, x: np.ndarray) -> list[dict[str, Any] | None]:
        """The results of design ``x`` on each road (None where it was not evaluated)."""
        found = self.results.get(tuple(x), {})
        return [found.get(r) for r in range(self.n_roads)]
