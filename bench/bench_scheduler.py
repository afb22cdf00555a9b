"""How well the scheduler keeps a cluster busy: the real scheduler, store and Ray executor, a stand-in evaluation.

    python bench/bench_scheduler.py --cpus 64 --eval-ms 50 --plan paper --json
    python bench/bench_scheduler.py --cpus 2 --eval-ms 0 --plan paper --db postgresql+psycopg://...

A local Ray is started with ``--cpus`` logical CPUs; the evaluation is replaced by a stand-in that
sleeps ``--eval-ms`` per design without using the CPU (so a 2-core machine can stand in for a
256-CPU cluster) and returns a deterministic fitness. The plan ``paper`` is the paper's study as one
paper-study job: the Table 9 sweep on the 23 roads and 23 DEs (NP 50, 50 generations), 104,190
evaluations, submitted through the service's own submission path into a fresh store (a SQLite file
unless ``--db``). Before timing, every Ray worker is started (one sleeping task a CPU), so the
figure is the scheduler's, not Ray's start-up.

Printed (JSON with ``--json``): ``ideal_s`` (total sleep / CPUs), ``wall_s`` (submission to the job's
end), ``efficiency`` (ideal_s / wall_s), ``peak_in_flight`` (most tasks in flight at once),
``evaluations_per_s`` (stored), with the machine and the settings.
"""

from __future__ import annotations

import argparse
import dataclasses
import heapq
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from finaldrive.engine import DIAGNOSTICS, BatchResult, Road, SimSettings, Vehicle
from finaldrive.service.config import Settings
from finaldrive.service.db.models import Job
from finaldrive.service.jobs.scheduler import Scheduler, SchedulerConfig
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.machine import describe
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database
from finaldrive.workers import make_executor
from finaldrive.workers.base import Done, ExecutorMixin, Shared
from finaldrive.workers.evaluate import by_road

PLANS = {"paper": {"kind": "paper-study", "roads": ["paper"]}}


class SleepTask:
    """The stand-in evaluation: ``ms`` of sleep a design, a smooth deterministic fitness, no CPU."""

    def __init__(self, ms: float, *, sleep: bool = True) -> None:
        self.ms, self.sleep = ms, sleep

    def __call__(self, rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
                 vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
        if self.sleep:
            time.sleep(self.ms * 1e-3 * len(rows))
        return [(road, self._results(x)) for road, x in by_road(rows)]

    def _results(self, x: np.ndarray) -> BatchResult:
        n = len(x)
        fitness = 20.0 - np.cos(x[:, 0]) * 0.01 - (x[:, 1] - 0.05) ** 2 - (x[:, 2] - 0.09) ** 2
        ones, nan = np.ones(n), np.full(n, np.nan)
        return BatchResult(
            designs=x, distance_m=fitness, squat_ratio=ones, slack_m=0.0 * ones, fitness_m=fitness,
            chain_length_m=ones, wall_s=np.full(n, self.ms * 1e-3), status=("ok",) * n, reason=("",) * n,
            **dict.fromkeys(DIAGNOSTICS, nan))


class VirtualCluster(ExecutorMixin):
    """``cpus`` CPUs on a clock, no processes: a task holds a CPU for ``ms`` a design (queued
    first-in first-out while none is free) and is reported when that time has passed on the wall
    clock. Its result is computed at submission (the stand-in told not to sleep), with the
    in-worker times it would have had. The scheduler and the store
    get the whole machine, so the figure is theirs alone, free of Ray's per-worker cost.
    """

    def __init__(self, cpus: int, ms: float) -> None:
        super().__init__()
        self.num_workers, self.capacity, self.ms = cpus, 2 * cpus, ms
        self._ids = 0
        self._free_at = [0.0] * cpus                      # heap: when each CPU becomes free
        self._pending: list[tuple[float, int, Any]] = []  # heap: (finish time, task, result)

    def share(self, value: Any) -> Shared:
        return Shared.new(value)

    def release(self, shared: Shared) -> None:
        pass

    def submit(self, fn: Any, batch: Any, *shared: Shared) -> int:
        values = [handle.ref for handle in shared]
        held = self.ms * 1e-3 * len(batch)
        result = dataclasses.replace(fn(batch, *values), busy_s=held, compute_s=held)  # as if it had slept
        start = max(time.perf_counter(), heapq.heappop(self._free_at))
        end = start + held
        heapq.heappush(self._free_at, end)
        self._ids += 1
        heapq.heappush(self._pending, (end, self._ids, result))
        return self._ids

    def poll(self, timeout: float) -> list[Done]:
        if not self._pending:
            return []
        wait = min(timeout, self._pending[0][0] - time.perf_counter())
        if wait > 0:
            time.sleep(wait)
        now, out = time.perf_counter(), []
        while self._pending and self._pending[0][0] <= now:
            _, task, result = heapq.heappop(self._pending)
            out.append(Done(task, result=result))
        return out

    def cancel(self, tasks: Any) -> None:
        wanted = set(tasks)
        self._pending = [p for p in self._pending if p[1] not in wanted]
        heapq.heapify(self._pending)

    def in_flight(self) -> int:
        return len(self._pending)

    def close(self) -> None:
        self._pending = []


def _warm(executor: Any, cpus: int) -> None:
    """Start every Ray worker: ``cpus`` tasks that each hold a CPU for a moment, together."""
    for _ in range(cpus):
        executor.submit(time.sleep, 0.5)
    pending = cpus
    while pending:
        pending -= len(executor.poll(5.0))


def _count_submissions(executor: Any) -> list[int]:
    """Count the tasks submitted to ``executor`` from now on (in the returned one-element list)."""
    count = [0]
    submit = executor.submit

    def counted(*args: Any) -> int:
        count[0] += 1
        return submit(*args)

    executor.submit = counted
    return count


def run(cpus: int, eval_ms: float, plan: str, db_url: str | None, executor_kind: str) -> dict[str, Any]:
    tmp = tempfile.TemporaryDirectory(prefix="finaldrive-bench-")
    url = db_url or f"sqlite:///{Path(tmp.name) / 'bench.db'}"
    settings = Settings(db_url=url, executor="ray", num_workers=cpus)
    db = open_database(settings)  # as finaldrive.service.jobs.scheduler.run_scheduler
    executor: Any = (VirtualCluster(cpus, eval_ms) if executor_kind == "virtual"
                     else make_executor("ray", num_workers=cpus))
    try:
        if executor_kind == "ray":
            _warm(executor, cpus)
        task = SleepTask(eval_ms, sleep=executor_kind == "ray")
        tasks = _count_submissions(executor)
        scheduler = Scheduler(db, executor, task=task, warmup=None, executor_kind=executor_kind,
                              config=SchedulerConfig(recordings=False))
        start = time.perf_counter()
        job, _ = submit_job(db, JobSpec.model_validate(PLANS[plan]), idempotency_key=None,
                            max_evaluations=10**9, max_cpu_hours=1e9)
        peak = 0

        def done() -> bool:
            with db.read() as session:
                state = session.get(Job, job.id).state  # type: ignore[union-attr]
            return state in ("succeeded", "failed", "cancelled")

        while True:
            scheduler.turn(0.02)
            peak = max(peak, scheduler.dispatcher.in_flight())
            if not scheduler.jobs and done():  # the scheduler lets a job go once it is finished
                break
        wall = time.perf_counter() - start
        scheduler.shutdown()
        with db.read() as session:
            row = session.get(Job, job.id)
            assert row is not None
            stored, state = row.n_done + row.n_failed, row.state
    finally:
        executor.close()
        db.dispose()
        tmp.cleanup()
    ideal = stored * eval_ms * 1e-3 / cpus
    return {"plan": plan, "executor": executor_kind, "cpus": cpus, "eval_ms": eval_ms,
            "store": url.split(":", 1)[0], "state": state,
            "evaluations": stored, "ideal_s": round(ideal, 3), "wall_s": round(wall, 3),
            "efficiency": round(ideal / wall, 4) if wall else None, "peak_in_flight": peak,
            "tasks": tasks[0], "designs_per_task": round(stored / max(1, tasks[0]), 2),
            "evaluations_per_s": round(stored / wall, 1), "machine": describe()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cpus", type=int, required=True, help="logical CPUs of the local Ray")
    parser.add_argument("--eval-ms", type=float, required=True, help="stand-in evaluation time a design [ms]")
    parser.add_argument("--plan", choices=sorted(PLANS), default="paper", help="what to run")
    parser.add_argument("--db", help="SQLAlchemy URL of an empty database (default: a fresh SQLite file)")
    parser.add_argument("--executor", choices=("ray", "virtual"), default="ray",
                        help="ray: a local Ray with --cpus CPUs; virtual: CPUs on a clock in this process "
                             "(the scheduler and store alone, without Ray's per-worker cost)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    out = run(args.cpus, args.eval_ms, args.plan, args.db, args.executor)
    if args.json:
        print(json.dumps(out))
    else:
        for key, value in out.items():
            print(f"{key:>18}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
