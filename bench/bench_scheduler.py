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
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from finaldrive.engine import BatchResult, Road, SimSettings, Vehicle
from finaldrive.service.config import Settings
from finaldrive.service.jobs.scheduler import Scheduler, SchedulerConfig
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.machine import describe
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database
from finaldrive.workers import make_executor

PLANS = {"paper": {"kind": "paper-study", "roads": ["paper"]}}


class SleepTask:
    """The stand-in evaluation: ``ms`` of sleep a design, a smooth deterministic fitness, no CPU."""

    def __init__(self, ms: float) -> None:
        self.ms = ms

    def __call__(self, rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
                 vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
        time.sleep(self.ms * 1e-3 * len(rows))
        x = rows[:, 1:]
        n = len(x)
        fitness = 20.0 - np.cos(x[:, 0]) * 0.01 - (x[:, 1] - 0.05) ** 2 - (x[:, 2] - 0.09) ** 2
        ones = np.ones(n)
        return [(int(rows[0, 0]), BatchResult(
            designs=x, distance_m=fitness, squat_ratio=ones, slack_m=0.0 * ones, fitness_m=fitness,
            chain_length_m=ones, wall_s=np.full(n, self.ms * 1e-3), status=("ok",) * n, reason=("",) * n))]


def _warm(executor: Any, cpus: int) -> None:
    """Start every Ray worker: ``cpus`` tasks that each hold a CPU for a moment, together."""
    for _ in range(cpus):
        executor.submit(time.sleep, 0.5)
    pending = cpus
    while pending:
        pending -= len(executor.poll(5.0))


def run(cpus: int, eval_ms: float, plan: str, db_url: str | None) -> dict[str, Any]:
    tmp = tempfile.TemporaryDirectory(prefix="finaldrive-bench-")
    url = db_url or f"sqlite:///{Path(tmp.name) / 'bench.db'}"
    settings = Settings(db_url=url, executor="ray", num_workers=cpus)
    db = open_database(settings)
    executor = make_executor("ray", num_workers=cpus)
    try:
        _warm(executor, cpus)
        scheduler = Scheduler(db, executor, task=SleepTask(eval_ms), warmup=None, executor_kind="ray",
                              config=SchedulerConfig(recordings=False))
        start = time.perf_counter()
        job, _ = submit_job(db, JobSpec.model_validate(PLANS[plan]), idempotency_key=None,
                            max_evaluations=10**9, max_cpu_hours=1e9)
        peak = 0
        stop = threading.Event()
        from finaldrive.service.db.models import Job

        def done() -> bool:
            with db.read() as session:
                state = session.get(Job, job.id).state  # type: ignore[union-attr]
            return state in ("succeeded", "failed", "cancelled")

        next_check = 0.0
        while not stop.is_set():
            scheduler.turn(0.02)
            peak = max(peak, scheduler.dispatcher.in_flight())
            if time.perf_counter() >= next_check:
                next_check = time.perf_counter() + 0.25
                if done():
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
    return {"plan": plan, "cpus": cpus, "eval_ms": eval_ms, "store": url.split(":", 1)[0], "state": state,
            "evaluations": stored, "ideal_s": round(ideal, 3), "wall_s": round(wall, 3),
            "efficiency": round(ideal / wall, 4) if wall else None, "peak_in_flight": peak,
            "evaluations_per_s": round(stored / wall, 1), "machine": describe()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cpus", type=int, required=True, help="logical CPUs of the local Ray")
    parser.add_argument("--eval-ms", type=float, required=True, help="stand-in evaluation time a design [ms]")
    parser.add_argument("--plan", choices=sorted(PLANS), default="paper", help="what to run")
    parser.add_argument("--db", help="SQLAlchemy URL of an empty database (default: a fresh SQLite file)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    out = run(args.cpus, args.eval_ms, args.plan, args.db)
    if args.json:
        print(json.dumps(out))
    else:
        for key, value in out.items():
            print(f"{key:>18}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
