"""Running a study in this process and its workers (``optimize``, ``sweep``): no service, no store.

The study's runs (finaldrive.engine.study) say what to simulate; the dispatcher the service's
schedulers use (finaldrive.workers.dispatch) keeps all their ready work in flight, and results go
back to their runs as they arrive. Progress goes to stderr. The executor is always closed, also
on Ctrl-C.
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


def run_study(runs: list[Run], plan: StudyPlan, settings: SimSettings, vehicle: Vehicle, executor: Executor,
              on_result: OnResult) -> None:
    """Evaluate until every run is done, all ready work in flight (the service's dispatcher, no store).

    A part whose worker was lost comes back as failed designs with that reason, as in the service.
    """
    from finaldrive.engine import BatchResult, fitness_values
    from finaldrive.workers.dispatch import Dispatcher, Work
    from finaldrive.workers.evaluate import run_engine_on_roads, warm_up_engine

    by_index = {run.index: run for run in runs}

    def delivered(part: Request, batch: BatchResult) -> None:
        fitness = fitness_values(batch)
        on_result(part, batch, fitness)
        by_index[part.run].tell(part.road, part.step, part.candidates, fitness)

    dispatcher = Dispatcher(executor, run_engine_on_roads, warmup=warm_up_engine)
    work = Work(key="local", shared=(tuple(r.road for r in plan.roads), settings, vehicle), on_result=delivered,
                on_failure=lambda part, reason: delivered(part, BatchResult.failed(part.designs, reason)))
    dispatcher.add(work)
    try:
        while True:
            for run in runs:
                if not run.done:
                    work.queue.extend(run.take())
            if not work.queue and not dispatcher.in_flight():
                return
            dispatcher.step(0.1)
    finally:
        dispatcher.close()


def design_dict(x: np.ndarray) -> dict[str, float]:
    return {"a2_deg": math.degrees(float(x[0])), "l2_m": float(x[1]), "rws_m": float(x[2])}


def result_dict(batch: BatchResult, fitness: np.ndarray, i: int) -> dict[str, Any]:
    """Design and outcome of row ``i`` of a batch (JSON-ready)."""
    return {**design_dict(batch.designs[i]), "fitness_m": clean(fitness[i]),
            "distance_m": clean(batch.distance_m[i]), "squat_ratio": clean(batch.squat_ratio[i]),
            "slack_m": clean(batch.slack_m[i])}


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

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every evaluated design (n, 3) with its fitness and distance on each road (roads x n; NaN:
        failed or not evaluated there)."""
        keys = list(self.results)
        designs = np.array(keys, dtype=float).reshape(-1, 3)
        fitness = np.full((self.n_roads, len(keys)), np.nan)
        distance = np.full((self.n_roads, len(keys)), np.nan)
        for j, key in enumerate(keys):
            for r, row in self.results[key].items():
                fitness[r, j] = math.nan if row["fitness_m"] is None else row["fitness_m"]
                distance[r, j] = math.nan if row["distance_m"] is None else row["distance_m"]
        return designs, fitness, distance
