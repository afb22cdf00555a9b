"""How well the scheduler keeps a cluster busy: the real scheduler, store and Ray executor, a stand-in evaluation.

    python bench/bench_scheduler.py --cpus 64 --eval-ms 50 --plan paper --json
    python bench/bench_scheduler.py --cpus 2 --eval-ms 0 --plan paper --db postgresql+psycopg://...

A local Ray is started with ``--cpus`` logical CPUs; the evaluation is replaced by a stand-in that
sleeps ``--eval-ms`` per design without using the CPU (so a 2-core machine can stand in for a
256-CPU cluster) and returns a deterministic fitness. The plan ``paper`` is the paper's study as one
paper-study job: the Table 9 sweep on the 23 roads and 23 DEs (NP 50, 50 generations), 104,190
evaluations, submitted through the service's own submission path into a fresh store (a SQLite file
unless ``--db``). Before timing, every Ray worker is started (one sleeping task a CPU, which also
loads the stand-in) and a small job (``WARM_UP``) runs through the scheduler, so the figure is a
running service's scheduler, not Ray's start-up nor the scheduler's (its writer process, forked from
the fork server, imports this module again before it serves: ~0.35 s, where the service's own main
module takes 8 ms; docs/performance-log.md). The scheduler is driven as ``finaldrive serve`` drives it
(``Scheduler.cycle``: idle turns wait rather than spin).

The plan ``big`` is two jobs submitted together: a dense sweep of 1,018,080 evaluations over 4 roads
(a2 every 2 deg, L2 every 2 mm, 14 R_WS) and the paper's 23 DEs (Table 10 on the 23 roads).

``--executor virtual`` charges Ray's own costs, measured with the real RayExecutor (``--measure-ray``
prints them): the driver's CPU a task (a busy loop in the submitting thread, so it takes the GIL from
the scheduler as Ray's does), each worker's idle gap between tasks, and a ``RayExecutor.poll``'s own
cost as a function of the tasks in flight (a busy loop at each poll). ``--executor virtual-free`` is
the cost-free clock; ``--compare`` runs both and prints the ratio. ``--eval-dist engine`` draws each
design's time (seeded, from the design) out of the wall times of ``--eval-designs`` random designs
simulated by the engine at start-up (sine:0.04:3, the Table 8 box, compilation excluded);
``--eval-ms`` is then ignored.

Printed (JSON with ``--json``): ``ideal_s`` (total evaluation time / CPUs), ``wall_s`` (submission to
the jobs' end, on the store's clock), ``efficiency`` (ideal_s / wall_s), ``peak_in_flight`` (most tasks in
flight at once),
``evaluations_per_s`` (stored), ``cpu_s`` (the CPU seconds each role used while the clock ran:
:data:`CPU_ROLES`, from Linux's /proc) and ``cpu_us_per_evaluation`` (the same a stored evaluation),
with the machine and the settings (``ray_costs``, ``eval_dist``).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import heapq
import itertools
import json
import os
import sys
import tempfile
import threading
import time
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from finaldrive.engine import DIAGNOSTICS, BatchResult, Bounds, Design, Road, SimSettings, Vehicle, simulate
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import Job
from finaldrive.service.jobs.scheduler import GC_THRESHOLDS, Scheduler, SchedulerConfig
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.machine import describe
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database
from finaldrive.workers import make_executor, task as worker_task
from finaldrive.workers.base import Done, ExecutorMixin, Shared, task_width
from finaldrive.workers.evaluate import by_road

#: The jobs of each plan, submitted together.
PLANS: dict[str, list[dict[str, Any]]] = {
    "paper": [{"kind": "paper-study", "roads": ["paper"]}],
    "big": [{"kind": "sweep", "roads": ["sine:0.04:3", "sine:0.04:2", "bump:0.04:0.2", "flat"],
             "grid": "a2_deg=0:358:2,l2_m=0:0.2:0.002,rws_m=0.08:0.106:0.002"},
            {"kind": "de", "roads": ["paper"], "de": {"preset": "paper"}}],
}

# Ray's per-task costs: medians of 3 runs of ``--measure-ray`` (RayExecutor, make_executor("ray",
# num_workers=2), Ray 2.60.0, Python 3.11.7) on the 2-core "AMD EPYC" (lscpu) of this project's
# sessions, Linux 6.18, 2026-12-04 23:10 UTC, load average 1.3-1.8 (runs: 625-687 us, 0.86-1.02 ms,
# polls 2-3 us at every count), with poll taking what Ray's completion callbacks queued. The issue
# measured 1.6-1.9 ms and 8-10 ms on the same kind of machine under load: pass those to bracket.
#: The driver's CPU a task, submission to result (the process's CPU time / tasks, 4 in flight) [us].
RAY_TASK_US = 649.0
#: A worker's idle time between the end of one task and the start of the next, 4 in flight [ms].
RAY_GAP_MS = 0.902
#: The engine's Python a design, holding the GIL, in a wide task (workers/evaluate.py) [us]: an upper
#: bound, a design's whole wall time at 2 ms of simulated time (400 random designs on sine:0.04:3,
#: 100-103 us; the same machine, 2026-12-06). Two threads ran 1.68-1.90x one (two processes: 1.62-1.75x).
GIL_US = 100.0
#: CPUs of a node of the virtual cluster (a task holds at most one node's).
NODE_CPUS = 64
#: One ``RayExecutor.poll(0)``'s cost by the tasks in flight, nothing ready: "n:ms,..." (interpolated,
#: extrapolated linearly).
RAY_POLL = "4:0.002,256:0.002,2048:0.002"


def _spin(seconds: float) -> None:
    """Hold this thread (and the GIL) for ``seconds`` of wall time, as Ray's Python-side work does."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


@dataclasses.dataclass(frozen=True)
class RayCosts:
    """Ray's per-task costs: driver CPU a task [s], worker gap [s], a poll [s] by in-flight count."""

    task_s: float
    gap_s: float
    poll_points: tuple[tuple[int, float], ...]

    @classmethod
    def parse(cls, task_us: float, gap_ms: float, poll: str) -> RayCosts:
        try:
            points = sorted((int(n), float(ms) * 1e-3) for n, ms in (item.split(":") for item in poll.split(",")))
        except ValueError:
            raise SystemExit(f"--ray-poll: expected n:ms,n:ms,... not {poll!r}") from None
        if not points or task_us < 0 or gap_ms < 0 or any(n < 0 or t < 0 for n, t in points):
            raise SystemExit("--ray-task-us, --ray-gap-ms, --ray-poll: expected values >= 0")
        return cls(task_us * 1e-6, gap_ms * 1e-3, tuple(points))

    def poll_s(self, in_flight: int) -> float:
        """One poll: interpolated between the measured points, linear beyond the last two."""
        ns, ts = [n for n, _ in self.poll_points], [t for _, t in self.poll_points]
        if in_flight > ns[-1] and len(ns) > 1:
            return ts[-1] + (ts[-1] - ts[-2]) / (ns[-1] - ns[-2]) * (in_flight - ns[-1])
        return float(np.interp(in_flight, ns, ts))

    def as_dict(self) -> dict[str, Any]:
        return {"task_us": round(self.task_s * 1e6, 1), "gap_ms": round(self.gap_s * 1e3, 3),
                "poll_ms": {n: round(t * 1e3, 3) for n, t in self.poll_points}}


def engine_times(n: int, seed: int = 1, road: str = "sine:0.04:3") -> np.ndarray:
    """The engine's wall time [s] of ``n`` random designs in the Table 8 box on ``road`` (fast method,
    one design simulated first so that compilation is not counted)."""
    box, rng, r, settings = Bounds(), np.random.default_rng(seed), Road.parse(road), SimSettings()
    designs = [Design.from_deg(rng.uniform(*box.a2_deg), rng.uniform(*box.l2_m), rng.uniform(*box.rws_m))
               for _ in range(n)]
    simulate(designs[0], r, settings)
    return np.array([simulate(d, r, settings).wall_s for d in designs])


def describe_times(times: np.ndarray) -> dict[str, float]:
    return {"n": len(times), "median_ms": round(float(np.median(times)) * 1e3, 3),
            "p90_ms": round(float(np.percentile(times, 90)) * 1e3, 3),
            "max_ms": round(float(times.max()) * 1e3, 3), "mean_ms": round(float(times.mean()) * 1e3, 3)}


class SleepTask:
    """The stand-in evaluation: ``ms`` of sleep a design (or, with ``times``, a time drawn for each design
    from them, seeded by the design's bytes; a wide task sleeps :func:`wide_task_s` of them), a smooth
    deterministic fitness, no CPU. Each design's
    time is its ``wall_s``. Its records are the engine's shape: every value finite, as a successful
    run's are (a NULL costs the store other bytes and time than a number)."""

    def __init__(self, ms: float, *, sleep: bool = True, times: np.ndarray | None = None, seed: int = 0) -> None:
        self.ms, self.sleep, self.times, self.seed = ms, sleep, times, seed

    def __call__(self, rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
                 vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
        out = [(road, self.results(x)) for road, x in by_road(rows)]
        if self.sleep:  # as long as its designs on the task's threads
            time.sleep(wide_task_s(np.concatenate([result.wall_s for _, result in out]), worker_task.task_cpus()))
        return out

    def _wall_s(self, x: np.ndarray) -> np.ndarray:
        if self.times is None:
            return np.full(len(x), self.ms * 1e-3)
        return np.array([self.times[zlib.crc32(row.tobytes(), self.seed) % len(self.times)] for row in x])

    def results(self, x: np.ndarray) -> BatchResult:
        n = len(x)
        fitness = 20.0 - np.cos(x[:, 0]) * 0.01 - (x[:, 1] - 0.05) ** 2 - (x[:, 2] - 0.09) ** 2
        diagnostics = np.outer(fitness, np.arange(1.0, len(DIAGNOSTICS) + 1)) + x[:, :1]
        return BatchResult.of(x, ("ok",) * n, ("",) * n, distance_m=fitness, squat_ratio=1.0 + x[:, 1],
                              slack_m=x[:, 2] * 1e-3, fitness_m=fitness, chain_length_m=1.0 + x[:, 2],
                              wall_s=self._wall_s(x), **dict(zip(DIAGNOSTICS, diagnostics.T, strict=True)))


def wide_task_s(times: np.ndarray, threads: int, gil_s: float = GIL_US * 1e-6) -> float:
    """How long a task of designs taking ``times`` [s] runs on ``threads`` threads of one process, each
    taking the next design (workers/evaluate.py): the list schedule's end, but no less than the
    designs' Python, which holds the GIL (``gil_s`` a design, or the whole of a shorter one)."""
    if threads <= 1 or len(times) <= 1:
        return float(np.sum(times))
    free = [0.0] * threads
    for t in times:
        heapq.heapreplace(free, free[0] + float(t))
    return max(max(free), float(np.minimum(times, gil_s).sum()))


def virtual_nodes(cpus: int, node_cpus: int) -> list[int]:
    """A cluster of ``cpus`` CPUs as nodes of ``node_cpus`` (the last one smaller if they do not divide)."""
    return [node_cpus] * (cpus // node_cpus) + ([cpus % node_cpus] if cpus % node_cpus else [])


class VirtualCluster(ExecutorMixin):
    """``cpus`` CPUs on a clock, no processes: a task holds ``task_cpus`` CPUs (``base.task_width`` of
    nodes of ``node_cpus``, unless given) for its designs' times (their ``wall_s``, spread over that
    many threads: :func:`wide_task_s`; queued first-in first-out while no slot is free) and is
    reported when that time has passed on the wall clock. Its result is computed at submission (the
    stand-in told not to sleep), with the in-worker times it would have had. With ``costs`` the driver
    pays Ray's: ``task_s`` at each submit (the stand-in's own time making the result, then a busy loop
    for the rest), ``poll_s(in flight)`` at each poll, and a slot is idle ``gap_s`` after each task
    (reported to the scheduler as the task's ``idle_s``).
    Without, the scheduler and the store get the whole machine, so the figure is theirs alone.
    """

    def __init__(self, cpus: int, costs: RayCosts | None = None, *, task_cpus: int | None = None,
                 node_cpus: int = NODE_CPUS) -> None:
        super().__init__()
        self.task_cpus, slots = task_width(virtual_nodes(cpus, node_cpus), task_cpus)
        self.num_workers, self.capacity, self.costs = slots, 2 * slots, costs
        self.held_s = 0.0                                 # the designs' time of every task submitted
        self._ids = 0
        self._free_at = [0.0] * slots                     # heap: when each slot becomes free
        self._pending: list[tuple[float, int, Any]] = []  # heap: (finish time, task, result)

    def share(self, value: Any) -> Shared:
        return Shared.new(value)

    def release(self, shared: Shared) -> None:
        pass

    def submit(self, fn: Any, batch: Any, *shared: Shared, again: int = 0) -> int:
        values = [handle.ref for handle in shared]
        begun = time.perf_counter()
        timed = fn(batch, *values)
        times = np.concatenate([result.wall_s for _, result in timed.result])
        self.held_s += float(times.sum())
        held = wide_task_s(times, self.task_cpus)
        if self.costs is None:
            result = dataclasses.replace(timed, busy_s=held, compute_s=held)  # as if it had slept
            start = max(time.perf_counter(), heapq.heappop(self._free_at))
        else:  # the stand-in made its result here, in the driver: that time is part of Ray's, not on top
            _spin(self.costs.task_s - (time.perf_counter() - begun))
            free = heapq.heappop(self._free_at)            # the previous task's end + the gap
            start = max(time.perf_counter(), free)
            result = dataclasses.replace(timed, busy_s=held, compute_s=held,
                                         idle_s=start - free + self.costs.gap_s)
        end = start + held
        heapq.heappush(self._free_at, end + (self.costs.gap_s if self.costs else 0.0))
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
        if self.costs is not None:
            _spin(self.costs.poll_s(len(self._pending)))
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


def _warm(executor: Any, slots: int, task: SleepTask | None = None) -> None:
    """Start every Ray worker: ``slots`` tasks that each hold a task's CPUs for a moment, together; with
    ``task``, each worker also loads the stand-in (this module and what it imports, ~0.7 s a worker:
    the service's workers load the engine in its warm-up, before its first job)."""
    for _ in range(slots):
        executor.submit(_hold, task)
    pending = slots
    while pending:
        pending -= len(executor.poll(5.0))


def _hold(task: SleepTask | None) -> None:
    """A warm-up task: the stand-in, unpickled here, is loaded on this worker."""
    time.sleep(0.5)


#: A job run through the scheduler before the clock starts, so that the figure is a running service's:
#: its writer process started (it imports this module, the parent's main, again: ~0.35 s) and its store
#: opened. Off every plan's grid and roads: nothing of it is reused from the result cache.
WARM_UP = {"kind": "sweep", "roads": ["sine:0.011:3.3"], "grid": "a2_deg=1.5:7.5:2,l2_m=0.0501:0.0601:0.005"}


def _finished(db: Database, jobs: list[int]) -> bool:
    with db.read() as session:
        states = [session.get(Job, job).state for job in jobs]  # type: ignore[union-attr]
    return all(state in ("succeeded", "failed", "cancelled") for state in states)


def _submit(db: Database, specs: list[dict[str, Any]]) -> list[int]:
    return [submit_job(db, JobSpec.model_validate(spec), idempotency_key=None, max_evaluations=10**9,
                       max_cpu_hours=1e9)[0].id for spec in specs]


def _count_submissions(executor: Any) -> list[int]:
    """Count the tasks submitted to ``executor`` from now on (in the returned one-element list)."""
    count = [0]
    submit = executor.submit

    def counted(*args: Any, **kwargs: Any) -> int:
        count[0] += 1
        return submit(*args, **kwargs)

    executor.submit = counted
    return count


#: Where the machine's CPU went while the clock ran: this process, the scheduler's writer process, the
#: database server's processes, this process's other descendants (Ray's), and the rest of the machine.
CPU_ROLES = ("driver", "writer", "database", "ray", "other")


def _processes() -> dict[int, tuple[int, str, float]]:
    """Every process's parent, name and CPU time so far [s] (Linux's /proc; empty elsewhere)."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    out = {}
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # gone meanwhile
            continue
        name, fields = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:].split()
        out[int(entry.name)] = (int(fields[1]), name, (int(fields[11]) + int(fields[12])) / tick)
    return out


def cpu_roles(before: dict[int, tuple[int, str, float]], after: dict[int, tuple[int, str, float]],
              writers: list[int | None]) -> dict[str, float]:
    """CPU seconds each of :data:`CPU_ROLES` used between two :func:`_processes` (a process that ended
    between them is not counted: none of the roles' does while the clock runs)."""
    me = os.getpid()

    def role(pid: int) -> str:
        if pid == me:
            return "driver"
        if pid in writers:
            return "writer"
        if after[pid][1].startswith("postgres"):
            return "database"
        seen = set()
        while pid in after and pid not in seen:  # a descendant of this process
            seen.add(pid)
            pid = after[pid][0]
            if pid == me:
                return "ray"
        return "other"

    used = dict.fromkeys(CPU_ROLES, 0.0)
    for pid, (_, _, cpu) in after.items():
        used[role(pid)] += cpu - (before[pid][2] if pid in before else 0.0)
    return {name: round(value, 2) for name, value in used.items()}


def _stamp(seconds: float) -> tuple[int, float, float]:
    """A measuring task: (process id, start, end) on the wall clock around ``seconds`` of sleep."""
    start = time.time()
    time.sleep(seconds)
    return os.getpid(), start, time.time()


def measure_ray(tasks: int = 400, in_flight: tuple[int, ...] = (4, 256, 2048), calls: int = 30) -> dict[str, Any]:
    """Ray's per-task costs with the real RayExecutor on 2 local CPUs (medians): the driver's CPU a
    task and each worker's gap between tasks, ``tasks`` tasks of 1 ms kept 4 in flight as the
    scheduler does; then ``calls`` timed ``poll(0.0)`` with each count of long tasks in flight and none
    ready (``poll_ms``), which are then cancelled."""
    import ray

    executor: Any = make_executor("ray", num_workers=2)
    try:
        _warm(executor, 2)
        stamps: list[tuple[int, float, float]] = []
        submitted, cpu0, wall0 = 0, time.process_time(), time.perf_counter()
        while len(stamps) < tasks:
            while submitted < tasks and executor.in_flight() < 4:
                executor.submit(_stamp, 0.001)
                submitted += 1
            stamps += [done.result for done in executor.poll(5.0)]
        cpu_s, wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
        gaps = [b[1] - a[2] for pid in {s[0] for s in stamps}
                for a, b in itertools.pairwise(sorted(s for s in stamps if s[0] == pid))]
        polls: dict[int, float] = {}
        for n in in_flight:
            ids = [executor.submit(time.sleep, 60.0) for _ in range(n)]
            walls = []
            for _ in range(calls):
                t0 = time.perf_counter()
                executor.poll(0.0)
                walls.append(time.perf_counter() - t0)
            polls[n] = round(float(np.median(walls)) * 1e3, 3)
            executor.cancel(ids)
            executor.poll(0.0)
    finally:
        executor.close()
    return {"ray": ray.__version__, "tasks": tasks, "task_us": round(cpu_s / tasks * 1e6, 1),
            "tasks_per_s": round(tasks / wall_s, 1), "gap_ms": round(float(np.median(gaps)) * 1e3, 3),
            "gap_p90_ms": round(float(np.percentile(gaps, 90)) * 1e3, 3), "poll_ms": polls,
            "ray_poll": ",".join(f"{n}:{ms}" for n, ms in polls.items()), "machine": describe()}


def run(cpus: int, plan: str, db_url: str | None, executor_kind: str, times: np.ndarray | None, eval_ms: float,
        costs: RayCosts | None, task_cpus: int | None = None, writers: int = SchedulerConfig.writers) -> dict[str, Any]:
    tmp = tempfile.TemporaryDirectory(prefix="finaldrive-bench-")
    url = db_url or f"sqlite:///{Path(tmp.name) / 'bench.db'}"
    settings = Settings(db_url=url, executor="ray", num_workers=cpus)
    gc.set_threshold(*GC_THRESHOLDS)  # as finaldrive.service.jobs.scheduler.run_scheduler
    db = open_database(settings)
    virtual = executor_kind != "ray"
    cluster = VirtualCluster(cpus, costs if executor_kind == "virtual" else None, task_cpus=task_cpus) \
        if virtual else None
    executor: Any = cluster or make_executor("ray", num_workers=cpus, task_cpus=task_cpus)
    try:
        task = SleepTask(eval_ms, sleep=not virtual, times=times)
        if not virtual:
            _warm(executor, executor.num_workers, task)
        scheduler = Scheduler(db, executor, task=task, warmup=None, executor_kind="virtual" if virtual else "ray",
                              config=SchedulerConfig(recordings=False, writers=writers))
        warm_up = _submit(db, [WARM_UP])
        while scheduler.jobs or not _finished(db, warm_up):
            scheduler.turn(0.02)
        held_before = cluster.held_s if cluster is not None else 0.0
        tasks = _count_submissions(executor)
        processes = _processes()
        jobs = _submit(db, PLANS[plan])
        peak = 0
        running = threading.Event()  # never set: the scheduler's loop as ``run`` takes it
        while True:
            scheduler.cycle(running)
            peak = max(peak, scheduler.dispatcher.in_flight())
            if not scheduler.jobs and _finished(db, jobs):  # the scheduler lets a job go once it is finished
                break
        writer = scheduler.writer
        n_writers = len(getattr(writer, "pids", [writer]))
        cpu = cpu_roles(processes, _processes(), getattr(writer, "pids", None) or [getattr(writer, "pid", None)])
        scheduler.shutdown()
        with db.read() as session:
            rows = [session.get(Job, job) for job in jobs]
            stored = sum(row.n_done + row.n_failed for row in rows if row is not None)
            state = ",".join(row.state for row in rows if row is not None)
            # from the submission to the last finish, on the store's clock: not the loop's idle wait after it
            wall = (max(row.finished_at for row in rows) - min(row.created_at for row in rows)).total_seconds()
        size = store_bytes(db)
    finally:
        executor.close()
        db.dispose()
        tmp.cleanup()
    if cluster is not None:
        busy = cluster.held_s - held_before
    else:  # the same draw as the stand-in's, over as many designs: its mean
        busy = stored * (float(times.mean()) if times is not None else eval_ms * 1e-3)
    ideal = busy / cpus
    return {"plan": plan, "executor": executor_kind, "cpus": cpus, "task_cpus": executor.task_cpus,
            "eval_ms": eval_ms if times is None else None,
            "eval_dist": describe_times(times) if times is not None else None,
            "ray_costs": costs.as_dict() if executor_kind == "virtual" and costs else None,
            "store": url.split(":", 1)[0], "writers": n_writers, "state": state,
            "evaluations": stored, "ideal_s": round(ideal, 3), "wall_s": round(wall, 3),
            "efficiency": round(ideal / wall, 4) if wall else None, "peak_in_flight": peak,
            "tasks": tasks[0], "designs_per_task": round(stored / max(1, tasks[0]), 2),
            "evaluations_per_s": round(stored / wall, 1), "cpu_s": cpu,
            "cpu_us_per_evaluation": {name: round(1e6 * value / max(1, stored), 1) for name, value in cpu.items()},
            "store_bytes": size,
            "bytes_per_evaluation": round(size / max(1, stored), 1), "machine": describe()}


def store_bytes(db: Database) -> int:
    """What the store holds on disk: the whole SQLite file (its WAL checkpointed into it first), or on
    PostgreSQL the evaluations table with its indexes and TOAST."""
    with db.engine.connect() as connection:
        if db.engine.dialect.name == "postgresql":
            return int(connection.exec_driver_sql("SELECT pg_total_relation_size('evaluations')").scalar() or 0)
        connection.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
        pages = connection.exec_driver_sql("PRAGMA page_count").scalar() or 0
        return int(pages) * int(connection.exec_driver_sql("PRAGMA page_size").scalar() or 0)


def median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The run of median efficiency; of median rate where no run has an ideal (0 ms designs: every
    efficiency is 0, and sorting by it would keep the runs' order)."""
    key = "efficiency" if any(run["efficiency"] for run in runs) else "evaluations_per_s"
    return sorted(runs, key=lambda run: run[key] or 0.0)[len(runs) // 2]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cpus", type=int, help="logical CPUs of the local Ray or the virtual cluster")
    parser.add_argument("--eval-ms", type=float, help="stand-in evaluation time a design [ms]")
    parser.add_argument("--eval-dist", choices=("engine",),
                        help="engine: each design's time drawn from the engine's measured times (not --eval-ms)")
    parser.add_argument("--eval-designs", type=int, default=100, help="random designs timed for --eval-dist")
    parser.add_argument("--plan", choices=sorted(PLANS), default="paper", help="what to run")
    parser.add_argument("--db", help="SQLAlchemy URL of an empty database (default: a fresh SQLite file)")
    parser.add_argument("--executor", choices=("ray", "virtual", "virtual-free"), default="ray",
                        help="ray: a local Ray with --cpus CPUs; virtual: CPUs on a clock in this process, "
                             "charging Ray's per-task costs; virtual-free: the same without Ray's costs "
                             "(the scheduler and store alone)")
    parser.add_argument("--compare", action="store_true",
                        help="run virtual and virtual-free, --repeat times each, interleaved; print medians and "
                             "their efficiency ratio")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each executor (--compare: the median)")
    parser.add_argument("--ray-task-us", type=float, default=RAY_TASK_US, help="driver CPU a Ray task [us]")
    parser.add_argument("--ray-gap-ms", type=float, default=RAY_GAP_MS, help="a worker's gap between tasks [ms]")
    parser.add_argument("--ray-poll", default=RAY_POLL, help="a poll's cost by tasks in flight, n:ms,...")
    parser.add_argument("--measure-ray", action="store_true",
                        help="measure Ray's per-task costs with the real RayExecutor (2 CPUs) and print them")
    parser.add_argument("--writers", type=int, default=SchedulerConfig.writers,
                        help="the scheduler's writer processes on PostgreSQL (SQLite: one)")
    parser.add_argument("--task-cpus", type=int,
                        help="CPUs a task holds (default: the executor's rule, workers.base.task_width)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    args = parser.parse_args()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if args.measure_ray:
        print(json.dumps(measure_ray()))
        return 0
    if args.cpus is None or args.cpus < 1 or (args.eval_dist is None and (args.eval_ms is None or args.eval_ms < 0)):
        parser.error("--cpus (>= 1) and --eval-ms (>= 0) or --eval-dist are required")
    if args.repeat < 1 or args.eval_designs < 1:
        parser.error("--repeat and --eval-designs must be >= 1")
    costs = RayCosts.parse(args.ray_task_us, args.ray_gap_ms, args.ray_poll)
    times = engine_times(args.eval_designs) if args.eval_dist == "engine" else None
    eval_ms = args.eval_ms if times is None else float(times.mean()) * 1e3
    kinds = ("virtual", "virtual-free") if args.compare else (args.executor,)
    runs: dict[str, list[dict[str, Any]]] = {kind: [] for kind in kinds}
    for _ in range(args.repeat):
        for kind in kinds:
            runs[kind].append(run(args.cpus, args.plan, args.db, kind, times, eval_ms, costs, args.task_cpus,
                                  args.writers))
            if not args.json:
                print(json.dumps(runs[kind][-1]), flush=True)
    medians = {kind: median_run(out) for kind, out in runs.items()}
    if args.compare:
        result: dict[str, Any] = {
            "median": medians, "runs": runs,
            "efficiency_ratio": round(medians["virtual"]["efficiency"] / medians["virtual-free"]["efficiency"], 4)}
    else:
        result = medians[args.executor] if args.repeat == 1 else {"median": medians[args.executor], "runs": runs}
    if args.json:
        print(json.dumps(result))
    else:
        shown = result.get("median", result)
        for key, value in (shown if not args.compare else {"efficiency_ratio": result["efficiency_ratio"]}).items():
            print(f"{key:>18}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
