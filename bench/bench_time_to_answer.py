"""Time to the answer on a cluster: when every road's optimiser is within 1 mm of that road's optimum.

    python bench/bench_time_to_answer.py --cpus 16,64,256 --settings default --json

One ``de`` job on the paper's 23 roads (``--roads``; run i on road i, seed i), through the real scheduler and store
(SQLite) on bench_scheduler's virtual cluster, which charges Ray's measured per-task costs. Each
design costs its own real wall time and returns its real result: every run is first simulated
here, in this process's order (a seeded optimiser asks the same rows however the work is spread,
a tested guarantee; designs equal to 1e-12 simulated once, as the store's result cache does), and
the virtual cluster's task looks the results up. So the clock is the
scheduler's and the cluster's, and the answers are the engine's.

``--settings``: ``default`` (the optimiser's default preset) or ``paper`` (Table 10); ``--np`` sets
the population (a wider round for a wider cluster: fewer rounds, more work). A road's
reference is the best fitness known for it: docs/paper-study.json's (the paper study's sweep and DE
of 4,530 evaluations a road) or a better one found here. Printed (JSON with ``--json``) for each
CPU count: ``time_to_1mm_s`` (from the job's start, when a scheduler claimed it, until the last road
that gets there has its first stored evaluation within 1 mm of its reference; ``claim_s`` is the
time from submission to that start), the median over those roads, ``roads_missed`` (the roads
whose run stopped short of 1 mm: the time does not count them), ``wall_s`` (the job's
start to its end) and the evaluations.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from bench_scheduler import RAY_GAP_MS, RAY_POLL, RAY_TASK_US, RayCosts, SleepTask, VirtualCluster, _count_submissions
from sqlalchemy import select

from finaldrive.engine import BatchResult, Road, SimSettings, Vehicle, evaluate, fitness_values
from finaldrive.service.config import Settings
from finaldrive.service.db.models import Evaluation, Job
from finaldrive.service.jobs.cache import DESIGN_DECIMALS
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.jobs.scheduler import Scheduler, SchedulerConfig
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.machine import describe
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database
from finaldrive.workers.evaluate import by_road

PAPER_STUDY = Path(__file__).resolve().parent.parent / "docs" / "paper-study.json"
TOL_M = 1e-3
#: The warm-up job's sweep on the job's roads (8 designs a road, the stand-in's results).
WARM_GRID = "a2_deg=0:315:45,l2_m=0.1,rws_m=0.09"


def spec_of(settings: str, roads: str, np_: int | None) -> dict[str, Any]:
    return {"kind": "de", "roads": [roads], "seed": 0, "de": {"preset": settings, **({"np": np_} if np_ else {})}}


def _simulate_run(job: tuple[dict[str, Any], int]) -> tuple[int, dict[bytes, BatchResult]]:
    """Run ``index`` of the job's plan in this process; every row asked, with its result."""
    spec, index = job
    plan = build_plan(JobSpec.model_validate(spec).normalised())
    run = plan.study.runs()[index]
    evaluate(np.array([[0.0, 0.0, 0.093]]), plan.study.roads[0].road, plan.settings)  # the engine loaded: the
    results: dict[bytes, BatchResult] = {}  # designs' times are the simulations', not numba's start-up
    first: dict[tuple[float, ...], BatchResult] = {}  # as the store's result cache: designs equal to 1e-12 once
    while not run.done:
        for request in run.take():
            keys = [tuple((np.round(row, DESIGN_DECIMALS) + 0.0).tolist()) for row in request.designs]
            new = [k for k, key in enumerate(keys) if key not in first and key not in keys[:k]]
            batch = evaluate(request.designs[new], plan.study.roads[request.road].road, plan.settings)
            for j, k in enumerate(new):
                first[keys[k]] = batch.rows(slice(j, j + 1))
            told = BatchResult.concat([first[key] for key in keys])
            for row, key in zip(request.designs, keys, strict=True):
                results[row.tobytes()] = first[key]
            run.tell(request.road, request.step, request.candidates, fitness_values(told))
    return index, results


class CachedTask:
    """The virtual cluster's task: each design's result and wall time as simulated ahead (designs not
    simulated ahead, the warm-up job's, get the stand-in's results at the median time of those)."""

    def __init__(self, cache: dict[int, dict[bytes, BatchResult]]) -> None:
        self.cache = cache
        median_s = float(np.median([float(r.wall_s[0]) for c in cache.values() for r in c.values()]))
        self.others = SleepTask(median_s * 1e3, sleep=False)

    def __call__(self, rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
                 vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
        out = []
        for road, x in by_road(rows):
            known = self.cache[road]
            if all(row.tobytes() in known for row in x):
                out.append((road, BatchResult.concat([known[row.tobytes()] for row in x])))
            else:
                out.append((road, self.others.results(x)))
        return out


def references(cache: dict[int, dict[bytes, BatchResult]], specs: list[str]) -> dict[int, float]:
    """Each road's best known fitness: the paper study's (for a road of it), or better here."""
    known = {road["spec"]: road for road in json.loads(PAPER_STUDY.read_text())["roads"]}
    out = {}
    for road, results in cache.items():
        here = max((float(r.fitness_m[0]) for r in results.values() if np.isfinite(r.fitness_m[0])), default=-np.inf)
        paper = known.get(specs[road])
        best = [paper["de_best"]["fitness_m"], paper["sweep_best"]["fitness_m"]] if paper else []
        out[road] = max([*best, here])
    return out


def _until_done(db: Any, scheduler: Scheduler, spec: dict[str, Any]) -> int:
    """Submit ``spec`` and turn the scheduler until the job has ended; its id."""
    job_id = submit_job(db, JobSpec.model_validate(spec), idempotency_key=None, max_evaluations=10**9,
                        max_cpu_hours=1e9)[0].id
    while True:
        scheduler.turn(0.02)
        if scheduler.jobs:  # the loop reads the store only when a real scheduler's would idle too
            continue
        with db.read() as session:
            job = session.get(Job, job_id)
            assert job is not None
            if job.state in ("succeeded", "failed", "cancelled"):
                return job_id


def _watch_tells(scheduler: Scheduler, refs: dict[int, float]) -> dict[Any, float]:
    """When the scheduler opened the next job ("open") and first told each road's optimiser a result
    within 1 mm (road -> perf_counter), recorded by wrapping the scheduler's own methods."""
    told: dict[Any, float] = {}
    open_, tell = scheduler._open, scheduler._tell

    def opened(job_id: int) -> None:
        told.setdefault("open", time.perf_counter())
        open_(job_id)

    def telling(job: Any, part: Any, fitness: np.ndarray) -> None:
        if part.road not in told and np.any(np.nan_to_num(fitness, nan=-np.inf) >= refs[part.road] - TOL_M):
            told[part.road] = time.perf_counter()
        tell(job, part, fitness)

    scheduler._open, scheduler._tell = opened, telling  # type: ignore[method-assign]
    return told


def run(cpus: int, spec: dict[str, Any], cache: dict[int, dict[bytes, BatchResult]], refs: dict[int, float],
        costs: RayCosts, tmp: Path, warm: bool, task_cpus: int | None = None) -> dict[str, Any]:
    url = f"sqlite:///{tmp / f'tta-{cpus}-{time.monotonic_ns()}.db'}"
    db = open_database(Settings(db_url=url, executor="ray", num_workers=cpus))
    cluster = VirtualCluster(cpus, costs, task_cpus=task_cpus)
    try:
        scheduler = Scheduler(db, cluster, task=CachedTask(cache), warmup=None, executor_kind="virtual",
                              config=SchedulerConfig(recordings=False))
        if warm:  # a service that has run a job: its dispatcher has measured the cluster
            _until_done(db, scheduler, {"kind": "sweep", "roads": [spec["roads"][0]], "grid": WARM_GRID})
        tasks = _count_submissions(cluster)
        told = _watch_tells(scheduler, refs)
        job_id = _until_done(db, scheduler, spec)
        scheduler.shutdown()
        with db.read() as session:
            job = session.get(Job, job_id)
            assert job is not None
            submitted, start, end, state = job.created_at, job.started_at or job.created_at, job.finished_at, job.state
            rows = session.execute(select(Evaluation.road_index, Evaluation.fitness_m, Evaluation.created_at)
                                   .where(Evaluation.job_id == job_id)).all()
    finally:
        cluster.close()
        db.dispose()
    first: dict[int, datetime] = {}
    for road, fitness, created in rows:
        if fitness is not None and fitness >= refs[road] - TOL_M and (road not in first or created < first[road]):
            first[road] = created
    times = {road: (first[road] - start).total_seconds() for road in first}
    missed = sorted(set(refs) - set(first))
    told_s = [told[road] - told["open"] for road in first if road in told]
    return {"cpus": cpus, "task_cpus": cluster.task_cpus, "warm": warm, "state": state, "evaluations": len(rows),
            "tasks": tasks[0],
            "time_to_1mm_s": round(max(times.values()), 3) if times else None,
            "told_1mm_s": round(max(told_s), 3) if told_s else None,
            "time_to_1mm_median_s": round(float(np.median(list(times.values()))), 3) if times else None,
            "roads_missed": missed, "wall_s": round((end - start).total_seconds(), 3) if end else None,
            "claim_s": round((start - submitted).total_seconds(), 3),
            "compute_s": round(sum(float(r.wall_s[0]) for c in cache.values() for r in c.values()), 3)}


def main() -> int:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cpus", default="16,64,256", help="CPU counts of the virtual cluster")
    parser.add_argument("--roads", default="paper", help="the job's roads (default: the paper's 23)")
    parser.add_argument("--settings", choices=("default", "paper"), default="default")
    parser.add_argument("--np", type=int, help="the optimiser's population (default: the preset's)")
    parser.add_argument("--repeat", type=int, default=3, help="runs at each CPU count (medians printed)")
    parser.add_argument("--workers", type=int, default=2, help="processes simulating the runs ahead")
    parser.add_argument("--cold", action="store_true",
                        help="the job is the scheduler's first (by default a small sweep runs before it)")
    parser.add_argument("--task-cpus", type=int,
                        help="CPUs a task holds (default: the executor's rule, workers.base.task_width)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    spec = spec_of(args.settings, args.roads, args.np)
    study = build_plan(JobSpec.model_validate(spec).normalised()).study
    start = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        cache = dict(pool.map(_simulate_run, [(spec, i) for i in range(len(study.runs()))], chunksize=1))
    refs = references(cache, [r.road.spec for r in study.roads])
    costs = RayCosts.parse(RAY_TASK_US, RAY_GAP_MS, RAY_POLL)
    out: dict[str, Any] = {"settings": args.settings, "roads": args.roads, "np": study.de.np if study.de else None,
                           "simulated_ahead_s": round(time.perf_counter() - start, 1), "ray_costs": costs.as_dict(),
                           "machine": describe(), "by_cpus": {}}
    with tempfile.TemporaryDirectory(prefix="finaldrive-tta-") as tmp:
        for cpus in (int(c) for c in args.cpus.split(",")):
            runs = [run(cpus, spec, cache, refs, costs, Path(tmp), not args.cold, args.task_cpus)
                    for _ in range(args.repeat)]
            runs.sort(key=lambda r: r["time_to_1mm_s"] if r["time_to_1mm_s"] is not None else float("inf"))
            out["by_cpus"][cpus] = {"median": runs[len(runs) // 2], "runs": runs}
            if not args.json:
                print(json.dumps(out["by_cpus"][cpus]["median"]), flush=True)
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
