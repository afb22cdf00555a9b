"""Test helpers of the service: a toy evaluation, a scheduler in a thread, waiting for jobs."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from finaldrive.engine import BatchResult, Road, SimSettings, Vehicle
from finaldrive.service.config import Settings
from finaldrive.service.jobs.scheduler import Scheduler, SchedulerConfig
from finaldrive.service.services import open_database
from finaldrive.workers import Executor, SerialExecutor
from finaldrive.workers.evaluate import by_road

TERMINAL = {"succeeded", "failed", "cancelled"}


def toy_batch(x: np.ndarray, road: Road, fail_above_l2: float | None = None) -> BatchResult:
    """fitness = 20 - (a2 - 1)^2 - 10 (l2 - 0.1)^2 - 100 (rws - 0.09)^2 - road height;
    designs with l2 > ``fail_above_l2`` fail with reason "fake divergence"."""
    fitness = 20 - (x[:, 0] - 1) ** 2 - 10 * (x[:, 1] - 0.1) ** 2 - 100 * (x[:, 2] - 0.09) ** 2 - road.height
    failed = np.zeros(len(x), bool) if fail_above_l2 is None else x[:, 1] > fail_above_l2
    fitness = np.where(failed, np.nan, fitness)
    return BatchResult.of(
        x, tuple("failed" if f else "ok" for f in failed), tuple("fake divergence" if f else "" for f in failed),
        distance_m=fitness + 0.5, squat_ratio=0.9, slack_m=0.001, fitness_m=fitness, chain_length_m=1.2, wall_s=0.01,
    )


def toy_rows(rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
             vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
    """The worker task of the scheduler, with the toy fitness instead of the engine (picklable)."""
    return [(road, toy_batch(x, roads[road])) for road, x in by_road(rows)]


class ToyTask:
    """:func:`toy_rows` run in this process (serial executor), with a counter, a delay a design, a gate
    and, for each design in the order they were run, its own road's spec. ``stop_after`` (n, event):
    set the event once n designs or more have run (a scheduler's stop, seen as this task returns)."""

    def __init__(self, *, fail_above_l2: float | None = None, delay: float = 0.0,
                 stop_after: tuple[int, threading.Event] | None = None) -> None:
        self.fail_above_l2 = fail_above_l2
        self.delay = delay
        self.stop_after = stop_after
        self.simulated = 0
        self.roads_run: list[str] = []
        self.gate = threading.Event()
        self.gate.set()

    def __call__(self, rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
                 vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
        self.gate.wait()
        if self.delay:
            time.sleep(self.delay * len(rows))
        self.simulated += len(rows)
        self.roads_run += [roads[int(road)].spec for road in rows[:, 0]]
        if self.stop_after is not None and self.simulated >= self.stop_after[0]:
            self.stop_after[1].set()
        return [(road, toy_batch(x, roads[road], self.fail_above_l2)) for road, x in by_road(rows)]


#: Fast pacing for tests: leases short enough to take over quickly, heartbeats and writes often.
#: (two writers: a pool on PostgreSQL, finaldrive.service.jobs.writer_pool; one on SQLite)
FAST = SchedulerConfig(lease_s=3.0, heartbeat_s=0.05, flush_s=0.02, recordings=True, writers=2)


@contextmanager
def running_scheduler(settings: Settings, task: Any, *, executor: Executor | None = None,
                      config: SchedulerConfig = FAST, scheduler_id: str | None = None,
                      stop: threading.Event | None = None) -> Iterator[Scheduler]:
    """A scheduler on ``settings.db_url`` in a thread, stopped (and its jobs given back) on exit, or
    once ``stop`` is set."""
    db = open_database(settings)
    scheduler = Scheduler(db, executor or SerialExecutor(), config=config, task=task, warmup=None,
                          scheduler_id=scheduler_id, executor_kind="serial")
    stop = stop or threading.Event()
    thread = threading.Thread(target=scheduler.run, args=(stop,), name="test-scheduler", daemon=True)
    thread.start()
    deadline = time.monotonic() + 30.0
    while not scheduler.registered and thread.is_alive() and time.monotonic() < deadline:
        time.sleep(0.005)  # a test starts with the scheduler registered (health counts it), not racing it
    try:
        yield scheduler
    finally:
        stop.set()
        thread.join(30)
        db.dispose()


def best_when_done(client: Any, url: str, option: str, jobs: dict[str, int]) -> dict[str, Any]:
    """GET ``url`` (a job's /best) with ``option``=true once the service's own ``jobs`` for it have
    finished: 200, and ``<option>_state`` succeeded."""
    for job_id in jobs.values():
        wait_done(client, job_id)
    done = client.get(url, params={option: "true"})
    assert done.status_code == 200 and done.json()[f"{option}_state"] == "succeeded", done.json()
    body: dict[str, Any] = done.json()
    return body


def wait_done(client: Any, job_id: int, timeout: float = 30.0, poll: float = 0.02) -> dict[str, Any]:
    """Poll GET /v1/jobs/{id} until the job reaches a terminal state."""
    deadline = time.monotonic() + timeout
    job: dict[str, Any] = {}
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["state"] in TERMINAL:
            return job
        time.sleep(poll)
    raise AssertionError(f"job {job_id} did not finish: {job}")


SWEEP = {"kind": "sweep", "roads": ["flat", "sine:0.025:3"], "grid": "a2_deg=0:90:30,l2_m=0.05|0.1|0.15,rws_m=0.09"}
DE = {"kind": "de", "roads": ["flat"], "de": {"np": 6, "iters": 4}, "seed": 3}
