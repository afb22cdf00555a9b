"""The scheduler: resuming, leases between schedulers, fencing, cancel, faults of the store.

In-process: the API through TestClient, schedulers in threads, the toy fitness of svc_helpers.
Both stores where it matters: a SQLite file and a real PostgreSQL server (tests/pg.py).
"""

from __future__ import annotations

import os
import signal
import sqlite3
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from finaldrive.service.config import Settings
from finaldrive.service.db.leases import claim_jobs, db_now, scheduler_id
from finaldrive.service.db.models import Evaluation, Generation, Job
from finaldrive.service.db.results import generation_records
from finaldrive.service.jobs.scheduler import Scheduler, SchedulerConfig
from finaldrive.service.jobs.writer import Writer
from finaldrive.service.jobs.writer_process import WriterProcess
from finaldrive.service.main import create_app
from finaldrive.service.services import open_database
from finaldrive.workers import SerialExecutor
from tests.service.svc_helpers import DE, SWEEP, ToyTask, running_scheduler, wait_done


def _submit(settings: Settings, spec: dict[str, Any]) -> int:
    with TestClient(create_app(settings)) as c:
        response = c.post("/v1/jobs", json=spec)
        assert response.status_code == 201, response.text
        return int(response.json()["id"])


def _job(settings: Settings, job_id: int) -> dict[str, Any]:
    with TestClient(create_app(settings)) as c:
        return dict(c.get(f"/v1/jobs/{job_id}").json())


def _wait(settings: Settings, job_id: int, timeout: float = 60.0) -> dict[str, Any]:
    with TestClient(create_app(settings)) as c:
        return wait_done(c, job_id, timeout=timeout)


def _slots(settings: Settings, job_id: int) -> list[tuple[int, int, int]]:
    db = open_database(settings)
    with db.read() as session:
        rows = session.execute(select(Evaluation.road_index, Evaluation.step, Evaluation.candidate)
                               .where(Evaluation.job_id == job_id)).all()
    db.dispose()
    return [tuple(r) for r in rows]  # type: ignore[misc]


def _final_population(settings: Settings, job_id: int) -> dict[int, list[list[float]]]:
    db = open_database(settings)
    with db.read() as session:
        rows = session.execute(select(Generation.run, Generation.generation, Generation.population)
                               .where(Generation.job_id == job_id)).all()
    db.dispose()
    last: dict[int, tuple[int, list[list[float]]]] = {}
    for run, generation, population in rows:
        if run not in last or generation > last[run][0]:
            last[run] = (generation, population)
    return {run: population for run, (_, population) in last.items()}


def _drive(scheduler: Scheduler, until: Any, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not until():
        assert time.monotonic() < deadline, "timed out"
        scheduler.turn(0.01)


def test_a_sweep_resumes_with_only_what_is_missing(settings: Settings) -> None:
    job_id = _submit(settings, SWEEP)
    stop = threading.Event()   # set by the task itself once 6 designs have run: a stop with work left on any machine
    slow = ToyTask(delay=0.02, stop_after=(6, stop))
    with running_scheduler(settings, slow, stop=stop):
        assert stop.wait(30)
    stopped = _job(settings, job_id)
    assert stopped["state"] == "interrupted" and 6 <= stopped["done"] < 24
    fresh = ToyTask()
    with running_scheduler(settings, fresh):
        job = _wait(settings, job_id)
    assert job["state"] == "succeeded" and job["done"] == 24
    assert fresh.simulated == 24 - stopped["done"]
    assert len(set(_slots(settings, job_id))) == len(_slots(settings, job_id)) == 24


@pytest.mark.parametrize("optimiser", ["de", "cmaes"])
def test_a_de_resumes_and_ends_bit_identical_to_an_uninterrupted_run(settings: Settings, tmp_path: Path,
                                                                     optimiser: str) -> None:
    """Any method through the protocol: its state stored each round resumes it exactly."""
    spec = {**DE, "roads": ["flat,sine:0.02:3"], "de": {"np": 6, "iters": 8, "optimiser": optimiser}}
    reference = settings.model_copy(update={"db_url": f"sqlite:///{tmp_path / 'ref.db'}"})
    ref_id = _submit(reference, spec)
    with running_scheduler(reference, ToyTask()):
        assert _wait(reference, ref_id)["state"] == "succeeded"
    job_id = _submit(settings, spec)
    for stop_at in (13, 40):  # mid-generation, twice
        with running_scheduler(settings, ToyTask(delay=0.01)):
            while _job(settings, job_id)["done"] < stop_at:
                time.sleep(0.01)
    with running_scheduler(settings, ToyTask()):
        assert _wait(settings, job_id)["state"] == "succeeded"
    assert sorted(_slots(settings, job_id)) == sorted(_slots(reference, ref_id))
    assert _final_population(settings, job_id) == _final_population(reference, ref_id)
    history = _history(settings, job_id)
    assert history == _history(reference, ref_id)  # resumed twice, the same record of every generation
    assert [r["generation"] for r in history[0]] == list(range(9))
    assert [r["n_evals"] for r in history[0]] == [6 * (g + 1) for g in range(9)]


def test_each_generation_row_holds_its_own_record(settings: Settings) -> None:
    job_id = _submit(settings, {**DE, "de": {"np": 6, "iters": 6}})
    with running_scheduler(settings, ToyTask(fail_above_l2=0.12)):
        job = _wait(settings, job_id)
    assert job["state"] == "succeeded" and job["failed"] > 0
    db = open_database(settings)
    with db.read() as session:
        rows = session.execute(select(Generation.generation, Generation.fitness_m, Generation.mean_fitness_m,
                                      Generation.n_failed, Generation.n_evals)
                               .where(Generation.job_id == job_id).order_by(Generation.generation)).all()
    db.dispose()
    assert [r.generation for r in rows] == list(range(1, 8))
    assert [r.n_evals for r in rows] == [6 * g for g in range(1, 8)]
    for row in rows:  # the population's mean over its successful designs, as the row's own fitness gives it
        finite = [f for f in row.fitness_m if f is not None]
        assert row.mean_fitness_m == pytest.approx(sum(finite) / len(finite), rel=1e-12)
    assert sum(r.n_failed for r in rows) == job["failed"]  # each generation's failures, once


def _history(settings: Settings, job_id: int) -> dict[int, list[dict[str, Any]]]:
    """The job's DE history as its rows hold it; each stored state is O(NP), without the history, and
    without the population and fitness that its row's columns hold."""
    db = open_database(settings)
    with db.read() as session:
        states = session.scalars(select(Generation.state).where(Generation.job_id == job_id)).all()
        records = generation_records(session, job_id)
    db.dispose()
    assert states and not any(key in state for state in states for key in ("history", "population", "fitness"))
    return records


def test_a_failed_simulation_is_stored_and_the_sweep_succeeds(client: TestClient, fake: ToyTask) -> None:
    fake.fail_above_l2 = 0.12
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    assert job["state"] == "succeeded" and (job["done"], job["failed"]) == (16, 8)
    items = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"limit": 100}).json()["items"]
    failed = [e for e in items if e["status"] == "failed"]
    assert {(e["l2_m"], e["reason"], e["fitness_m"]) for e in failed} == {(0.15, "fake divergence", None)}
    assert all(road["best"]["status"] == "ok" for road in job["roads"])


def test_two_schedulers_share_a_database_and_store_every_slot_once(store_url: str, tmp_path: Path) -> None:
    settings = Settings(db_url=store_url, executor="serial", status_cache_seconds=0, allowed_hosts=["testserver"])
    specs = [{**DE, "roads": ["flat,sine:0.02:3"], "de": {"np": 8, "iters": 6, "optimiser": method}, "seed": s}
             for s, method in ((1, "de"), (2, "de"), (3, "cmaes"))]  # every method's state stored on both stores
    alone = Settings(db_url=f"sqlite:///{tmp_path / 'alone.db'}", executor="serial", status_cache_seconds=0,
                     allowed_hosts=["testserver"])
    reference = [_submit(alone, spec) for spec in specs]
    with running_scheduler(alone, ToyTask()):
        for job_id in reference:
            assert _wait(alone, job_id)["state"] == "succeeded"
    jobs = [_submit(settings, spec) for spec in specs]
    with running_scheduler(settings, ToyTask(delay=0.002), scheduler_id="a"), \
            running_scheduler(settings, ToyTask(delay=0.002), scheduler_id="b"):
        done = [_wait(settings, job_id) for job_id in jobs]
    assert all(job["state"] == "succeeded" for job in done)
    for job_id, ref_id in zip(jobs, reference, strict=True):
        slots = _slots(settings, job_id)
        assert len(slots) == len(set(slots)) == len(_slots(alone, ref_id))
        assert _final_population(settings, job_id) == _final_population(alone, ref_id)


def test_a_dead_schedulers_job_is_taken_over_and_it_can_no_longer_write(settings: Settings) -> None:
    job_id = _submit(settings, {**DE, "de": {"np": 6, "iters": 6}})
    short = SchedulerConfig(lease_s=1.0, heartbeat_s=0.05, flush_s=0.0, recordings=False)
    db = open_database(settings)
    dead = Scheduler(db, SerialExecutor(), config=short, task=ToyTask(), warmup=None, scheduler_id="dead")
    _drive(dead, lambda: _job(settings, job_id)["done"] >= 12)   # then it "dies": no more turns, no shutdown
    with db.write() as session:
        assert claim_jobs(session, "other", lease_s=1.0, limit=5) == []  # its lease still holds
    time.sleep(1.2)
    with running_scheduler(settings, ToyTask(), config=short, scheduler_id="heir"):
        assert _wait(settings, job_id)["state"] == "succeeded"
    dead.turn(0.01)   # it wakes up: its results may not be written, and it lets the job go
    dead._flush()
    assert job_id not in dead.jobs
    slots = _slots(settings, job_id)
    assert len(slots) == len(set(slots)) == 6 * 7
    db.dispose()


def test_cancel_is_obeyed_by_the_owner_within_two_seconds(settings: Settings) -> None:
    slow = ToyTask(delay=0.05)
    with TestClient(create_app(settings)) as c, running_scheduler(settings, slow):
        job_id = c.post("/v1/jobs", json={**SWEEP, "grid": "a2_deg=0:358:2,l2_m=0.1,rws_m=0.09"}).json()["id"]
        while c.get(f"/v1/jobs/{job_id}").json()["done"] < 2:
            time.sleep(0.01)
        start = time.monotonic()
        assert c.post(f"/v1/jobs/{job_id}/cancel").json()["state"] == "cancelled"
        before = slow.simulated
        time.sleep(2.0)
        settled = slow.simulated
        time.sleep(0.5)
        # the serial executor cannot stop a running task: at most the two in flight (0.5 s each) finish
        assert slow.simulated == settled and settled - before <= 20, "still simulating after the cancel"
        job = c.get(f"/v1/jobs/{job_id}").json()
    assert job["state"] == "cancelled" and time.monotonic() - start < 10


@pytest.mark.slow   # holds the lock 5 s, past the scheduler's lock timeout
def test_a_store_locked_for_a_while_delays_the_job_but_never_fails_it(settings: Settings) -> None:
    path = settings.db_url.removeprefix("sqlite:///")
    with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask(delay=0.01)):
        job_id = c.post("/v1/jobs", json={**DE, "de": {"np": 6, "iters": 12}}).json()["id"]
        while c.get(f"/v1/jobs/{job_id}").json()["done"] < 6:
            time.sleep(0.01)
        locker = sqlite3.connect(path, timeout=30)
        locker.execute("BEGIN EXCLUSIVE")
        try:
            during = c.get("/v1/health")
            time.sleep(5.0)  # longer than the scheduler's lock timeout (2 s): its writes fail and are retried
            refused = c.post("/v1/jobs", json=DE)
        finally:
            locker.rollback()
            locker.close()
        assert during.status_code == 503 and during.json()["store"]["writable"] is False
        assert refused.status_code == 503 and refused.headers["Retry-After"] and "SELECT" not in refused.text
        job = wait_done(c, job_id)
        assert c.get("/v1/health").status_code == 200
    assert job["state"] == "succeeded" and job["error"] is None and job["done"] == 6 * 13


def test_a_killed_writer_process_is_replaced_and_nothing_is_lost_or_stored_twice(settings: Settings) -> None:
    with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask(delay=0.03)) as scheduler:
        writer = scheduler.writer
        assert isinstance(writer, WriterProcess)
        job_id = c.post("/v1/jobs", json={**DE, "de": {"np": 6, "iters": 12}}).json()["id"]
        killed: list[int] = []
        for done in (12, 50):  # mid-job, the second time on the first one's replacement
            while (job := c.get(f"/v1/jobs/{job_id}").json())["done"] < done:
                time.sleep(0.005)
            pid = writer.pid
            assert pid is not None and pid not in killed and job["state"] == "running" and job["done"] < 6 * 13
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        job = wait_done(c, job_id)
    assert job["state"] == "succeeded" and job["done"] == 6 * 13
    slots = _slots(settings, job_id)
    assert len(slots) == len(set(slots)) == 6 * 13


def test_results_go_to_an_idle_writer_at_once_not_at_the_next_flush(settings: Settings) -> None:
    """The loop hands what arrived to a writer with nothing to store in the same turn: a job's results
    are stored while it runs, although the flush interval is a minute."""
    job_id = _submit(settings, SWEEP)
    config = SchedulerConfig(lease_s=120.0, heartbeat_s=0.05, flush_s=60.0, recordings=False)
    scheduler = Scheduler(open_database(settings), SerialExecutor(), config=config, task=ToyTask(delay=0.02),
                          warmup=None)
    running, stored_meanwhile = threading.Event(), []
    try:
        deadline = time.monotonic() + 30.0
        while _job(settings, job_id)["state"] != "succeeded":
            assert time.monotonic() < deadline, "timed out"
            scheduler.cycle(running)
            job = _job(settings, job_id)
            if job["state"] == "running" and 0 < job["done"] < 24:
                stored_meanwhile.append(job["done"])
    finally:
        scheduler.shutdown()
        scheduler.db.dispose()
    # (the first turn flushes: the interval starts there; later results reach the store only by the rule)
    assert len(set(stored_meanwhile)) >= 2, f"stored while the job ran: {stored_meanwhile}"


def test_a_writer_s_wait_ends_with_its_transaction(settings: Settings) -> None:
    """``wait`` returns when the writer has stored what it holds, not at its timeout; at once when it
    holds nothing (the scheduler's idle loop waits on it)."""
    writer = Writer(open_database(settings), "s1")
    stored = threading.Event()
    writer._store = lambda job_id, writes: (time.sleep(0.3), stored.set(), True)[-1]  # type: ignore[method-assign]
    try:
        writer.put(1, [object()] * 3)  # type: ignore[arg-type]
        begun = time.monotonic()
        writer.wait(10.0)
        assert stored.is_set() and time.monotonic() - begun < 5.0
        begun = time.monotonic()
        writer.wait(10.0)
        assert time.monotonic() - begun < 1.0
    finally:
        writer.close()


def test_health_reports_each_scheduler_and_is_503_without_one(settings: Settings) -> None:
    with TestClient(create_app(settings)) as c:
        alone = c.get("/v1/health")
        assert alone.status_code == 503 and alone.json()["schedulers"] == []
        with running_scheduler(settings, ToyTask(), scheduler_id="s1"):
            time.sleep(0.2)
            body = c.get("/v1/health").json()
        assert body["status"] == "ok" and [s["id"] for s in body["schedulers"]] == ["s1"]
        assert body["schedulers"][0]["heartbeat_age_s"] < 1.0 and body["store"]["writable"]
        assert c.get("/v1/health").status_code == 503  # it stopped


def test_a_new_job_is_claimed_before_the_next_heartbeat(settings: Settings) -> None:
    """A scheduler with room looks for new jobs between heartbeats (a read) and claims one at once;
    one without room does not look (nor beat), and claims a job left queued as soon as it has room."""
    slow_beat = SchedulerConfig(lease_s=120.0, heartbeat_s=60.0, flush_s=0.02, recordings=False)
    with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask(), config=slow_beat) as running:
        deadline = time.monotonic() + 10.0
        while not running._registered:   # its first heartbeat is behind it; the next is a minute away
            assert time.monotonic() < deadline
            time.sleep(0.01)
        job_id = c.post("/v1/jobs", json=DE).json()["id"]
        assert wait_done(c, job_id, timeout=10.0)["state"] == "succeeded"
    full = Scheduler(open_database(settings), SerialExecutor(), config=SchedulerConfig(max_jobs=1, heartbeat_s=60.0,
                     lease_s=120.0, flush_s=0.02, recordings=False), task=ToyTask(delay=0.02), warmup=None)
    beats: list[float] = []
    maintain = full._maintain
    full._maintain = lambda: (beats.append(time.monotonic()), maintain())[1]   # type: ignore[method-assign]
    try:
        full.turn(0.01)   # the first heartbeat: nothing queued
        first, second = _submit(settings, DE), _submit(settings, DE)
        _drive(full, lambda: first in full.jobs, timeout=5.0)
        _drive(full, lambda: second in full.jobs, timeout=20.0)   # once the first is done, well before a heartbeat
        # one beat each: the first, the look that found both jobs (room for one), the look once the first was done
        assert len(beats) == 3 and _job(settings, first)["state"] == "succeeded"
    finally:
        full.shutdown()
        full.db.dispose()


def test_beside_another_scheduler_each_claims_one_job_a_heartbeat_and_none_when_busy(settings: Settings) -> None:
    """Claiming by free capacity: alone, a scheduler takes every queued job it has room for; beside a
    live one, one a heartbeat, and none while its workers were busy (CLAIM_BELOW_BUSY)."""
    config = SchedulerConfig(heartbeat_s=60.0, lease_s=120.0, flush_s=0.02, recordings=False)
    a, b = (Scheduler(open_database(settings), SerialExecutor(), config=config, task=ToyTask(delay=0.05),
                      warmup=None, scheduler_id=name) for name in ("a", "b"))
    try:
        a.turn(0.0)
        b.turn(0.0)   # both registered, nothing queued
        jobs = [_submit(settings, {**DE, "seed": seed}) for seed in range(5)]
        a._maintain()
        b._maintain()
        assert len(a.jobs) == len(b.jobs) == 1 and set(a.jobs) | set(b.jobs) == set(jobs[:2])
        _drive(a, lambda: a.dispatcher.in_flight() > 0, timeout=5.0)
        a.dispatcher.load()
        a.turn(0.5)   # its serial worker busy through the interval: above CLAIM_BELOW_BUSY
        held = set(a.jobs)
        a._maintain()
        assert set(a.jobs) == held and a._load is not None and a._load["busy_share"] >= 0.9, a._load
        held = set(b.jobs)
        b.dispatcher.load()   # a fresh interval, idle: b claims one more
        b._maintain()
        assert len(b.jobs) == len(held) + 1
        b.shutdown()          # alone again: a takes what is left that it has room for
        a._maintain()
        assert set(a.jobs) | set(b.jobs) >= set(jobs)
    finally:
        for scheduler in (a, b):
            scheduler.shutdown()
            scheduler.db.dispose()


def test_a_job_that_cannot_be_planned_fails_with_a_clean_message(settings: Settings) -> None:
    job_id = _submit(settings, DE)
    db = open_database(settings)
    with db.write() as session:  # a spec damaged in the store
        session.get(Job, job_id).spec = {**session.get(Job, job_id).spec, "roads": ["nowhere"]}
    db.dispose()
    with running_scheduler(settings, ToyTask()):
        job = _wait(settings, job_id)
    assert job["state"] == "failed" and job["error"].startswith("invalid job: roads.0: unknown road")


@pytest.mark.parametrize("n", [1, 3])
def test_concurrent_jobs_progress_together(settings: Settings, n: int) -> None:
    slow = ToyTask(delay=0.005)
    ids = [_submit(settings, {**DE, "seed": s, "de": {"np": 6, "iters": 20}}) for s in range(n)]
    with running_scheduler(settings, slow):
        time.sleep(0.8)
        progress = [_job(settings, job_id)["done"] for job_id in ids]
        for job_id in ids:
            assert _wait(settings, job_id)["state"] == "succeeded"
    assert all(p > 0 for p in progress), progress  # none waits for another to finish
    assert np.ptp(progress) <= max(progress) * 0.8 + 6


class Raising(ToyTask):
    """A task that raises (a bug in the worker) for designs with l2 > 0.12."""

    def __call__(self, rows: Any, roads: Any, settings: Any, vehicle: Any) -> Any:
        if (rows[:, 2] > 0.12).any():
            raise RuntimeError("boom")
        return super().__call__(rows, roads, settings, vehicle)


def test_a_task_that_raises_fails_its_designs_never_the_job_and_is_never_reused(settings: Settings) -> None:
    client = TestClient(create_app(settings)).__enter__()
    with running_scheduler(settings, Raising()):
        job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    assert job["state"] == "succeeded" and (job["done"], job["failed"]) == (16, 8)
    items = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"limit": 100}).json()["items"]
    assert {e["reason"] for e in items if e["status"] == "failed"} == {"error in the worker: RuntimeError: boom"}
    db = open_database(settings)
    with db.read() as session:
        flags = set(session.scalars(select(Evaluation.transient).where(Evaluation.status == "failed")))
    db.dispose()
    assert flags == {True}
    with running_scheduler(settings, ToyTask()):  # a healthy worker: the failures are simulated again
        again = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    client.__exit__(None, None, None)
    assert (again["done"], again["failed"], again["cached"]) == (24, 0, 16)


def test_heartbeats_go_on_while_the_loop_runs_a_long_task(settings: Settings) -> None:
    """The serial executor runs tasks in the loop's thread (the engine's warm-up, a long simulation):
    the leases are renewed meanwhile, so the job stays this scheduler's."""
    task = ToyTask()
    task.gate.clear()   # the first task blocks the loop
    config = SchedulerConfig(lease_s=1.0, heartbeat_s=0.1, flush_s=0.02)
    with TestClient(create_app(settings)) as client, running_scheduler(settings, task, config=config) as scheduler:
        job_id = client.post("/v1/jobs", json=SWEEP).json()["id"]
        deadline = time.monotonic() + 10
        while client.get(f"/v1/jobs/{job_id}").json()["state"] != "running":
            assert time.monotonic() < deadline
            time.sleep(0.02)
        time.sleep(3.0)  # three leases
        db = open_database(settings)
        try:
            with db.read() as session:
                job = session.get(Job, job_id)
                assert job is not None and job.owner == scheduler.id
                assert job.lease_until is not None and job.lease_until > db_now(session)
        finally:
            db.dispose()
        task.gate.set()
        assert wait_done(client, job_id)["state"] == "succeeded"


def test_scheduler_ids_fit_the_store(settings: Settings) -> None:
    long = scheduler_id("h" * 300, ":4242:0123abcd")
    assert len(long) == 64 and long.endswith(":4242:0123abcd")
    assert scheduler_id("host", ":1:2") == "host:1:2"
    with pytest.raises(ValueError, match="at most 64"):
        Scheduler(open_database(settings), SerialExecutor(), scheduler_id="x" * 65)


def test_the_intake_splits_a_sweep_s_road_in_place_and_takes_a_de_generation_whole() -> None:
    """About ``designs`` designs a turn, the smallest requests first: a sweep's road (its whole grid) is
    split, its first designs taken and the rest left where it was; a DE generation is never split."""
    from collections import deque

    from finaldrive.engine.study.runs import Request
    from finaldrive.service.jobs.scheduler import _first_designs

    def request(n: int, road: int, *, waited: bool = False) -> Request:
        candidates = np.arange(n)
        return Request(0, 0, road, candidates, np.column_stack([candidates] * 3).astype(float), waited)

    sweep, generation = request(10_000, 0), request(50, 1, waited=True)
    intake = deque([sweep, generation])
    taken = _first_designs(intake, 4096)
    assert taken[0] is generation and [len(r) for r in taken] == [50, 4046]
    assert len(intake) == 3 and intake[0] is taken[1] and intake[2] is generation
    assert np.array_equal(np.concatenate([r.candidates for r in list(intake)[:2]]), sweep.candidates)
    assert np.array_equal(np.concatenate([r.designs for r in list(intake)[:2]]), sweep.designs)
    large = request(5000, 2, waited=True)
    intake = deque([large, request(9000, 0)])
    taken = _first_designs(intake, 4096)
    assert len(taken) == 1 and taken[0] is large and len(intake) == 2
