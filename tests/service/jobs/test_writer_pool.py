"""The scheduler's writer pool on PostgreSQL: a job's evaluations stored by several writers at once, its
DE generations only after the evaluations before them, in order; nothing lost when a writer dies."""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from finaldrive.service.config import Settings
from finaldrive.service.db.models import Evaluation, Generation
from finaldrive.service.jobs import writer_pool
from finaldrive.service.jobs.writer import Writes
from finaldrive.service.jobs.writer_pool import WriterPool
from finaldrive.service.main import create_app
from finaldrive.service.services import open_database
from tests.service.svc_helpers import DE, ToyTask, running_scheduler, wait_done


class _Child:
    """A writer process's interface, acknowledging only when told (``ack``)."""

    def __init__(self, db: Any, scheduler_id: str, *, cond: threading.Condition) -> None:
        self.puts: list[tuple[int, Writes]] = []
        self.acked = 0

    def put(self, job_id: int, writes: Writes) -> int:
        self.puts.append((job_id, writes))
        return len(self.puts)

    def ack(self, upto: int) -> None:
        self.acked = upto

    def acknowledged(self, job_id: int, seq: int) -> bool:
        return seq <= self.acked

    def pending_rows(self) -> int:
        return sum(len(writes) for _, writes in self.puts[self.acked:])

    def pending(self, job_id: int) -> int:
        return sum(len(writes) for job, writes in self.puts[self.acked:] if job == job_id)

    def busy(self) -> bool:
        return self.acked < len(self.puts)

    def lost(self) -> list[int]:
        return []

    def forget(self, job_id: int) -> None:
        return None

    def close(self) -> None:
        return None

    pid = None


def _generations(child: _Child) -> list[int]:
    return [g["generation"] for _, writes in child.puts for g in writes.generations]


def test_generations_wait_for_the_evaluations_before_them_and_keep_their_order(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(writer_pool, "WriterProcess", _Child)
    pool = WriterPool(None, "s", 2)  # type: ignore[arg-type]
    first, second = pool._children  # type: ignore[attr-defined]
    pool.put(1, Writes(rows=[("row",)] * 3, generations=[{"generation": 0}]))
    pool.put(1, Writes(rows=[("row",)] * 2, generations=[{"generation": 1}]))
    assert [len(w) for _, w in first.puts] == [3] and [len(w) for _, w in second.puts] == [2]  # the least busy
    assert _generations(first) + _generations(second) == [] and pool.pending(1) == 3 + 2 + 2
    second.ack(1)  # the second put's evaluations are stored, the first's not: generation 0 waits, and 1 behind it
    assert _generations(first) + _generations(second) == [] and pool.busy()
    first.ack(1)  # every evaluation before them stored: both go, in order, to the job's own child
    assert pool.pending(1) == 2 and _generations(second) == [0, 1] and _generations(first) == []
    second.ack(3)
    assert not pool.busy() and pool.drain(0.1) and pool.pending(1) == 0


@pytest.fixture
def pg_settings(postgres: Any) -> Settings:
    return Settings(db_url=str(postgres.new_database()), executor="serial", events_poll_seconds=0.02,
                    status_cache_seconds=0, allowed_hosts=["testserver"])


def test_killed_writers_of_a_pool_are_replaced_and_nothing_is_lost_or_stored_twice(pg_settings: Settings) -> None:
    with TestClient(create_app(pg_settings)) as c, \
            running_scheduler(pg_settings, ToyTask(delay=0.03)) as scheduler:
        pool = scheduler.writer
        assert isinstance(pool, WriterPool) and len(pool.pids) == 2
        job_id = c.post("/v1/jobs", json={**DE, "de": {"np": 6, "iters": 12}}).json()["id"]
        killed: list[int] = []
        for done, child in ((12, 0), (40, 1)):  # mid-job, each writer once
            while (job := c.get(f"/v1/jobs/{job_id}").json())["done"] < done:
                time.sleep(0.005)
            pid = pool.pids[child]
            assert pid not in killed and job["state"] == "running"
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        job = wait_done(c, job_id)
    assert job["state"] == "succeeded" and job["done"] == 6 * 13
    db = open_database(pg_settings)
    with db.read() as session:
        slots = session.execute(select(Evaluation.road_index, Evaluation.step, Evaluation.candidate)
                                .where(Evaluation.job_id == job_id)).all()
        generations = session.scalars(select(Generation.generation).where(Generation.job_id == job_id)).all()
    db.dispose()
    assert len(slots) == len(set(slots)) == 6 * 13
    assert sorted(generations) == list(range(1, 14))  # the state after each of the 13 tells, once
