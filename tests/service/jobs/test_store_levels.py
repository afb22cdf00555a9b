"""The result cache's and /best's index tables of levels (finaldrive.service.db.levels), on SQLite and
PostgreSQL: through the writer's stores and the moves from level to level, every evaluation has exactly
one entry, the lookups read every level, each level's kept size is its size, and a full level moves a
chunk at a time, round its keys."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
from sqlalchemy import select, text
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from finaldrive.engine import BatchResult, Request, best_distinct, near_optimal
from finaldrive.service.api.bands import top_designs
from finaldrive.service.config import Settings
from finaldrive.service.db import levels
from finaldrive.service.db.leases import claim_jobs, register_scheduler
from finaldrive.service.db.models import Evaluation, Job
from finaldrive.service.db.results import COPY_ROWS, cached_evaluations, key_hash, store_results
from finaldrive.service.db.summaries import road_sharpness
from finaldrive.service.jobs.rows import rows_from_results
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database
from tests.service.api.test_best_summaries import _same
from tests.service.jobs.test_store_results import SWEEP, _claimed_sweep


def _batch(rng: np.random.Generator, road: int, first: int, n: int) -> tuple[list[tuple[object, ...]], list[str]]:
    """``n`` evaluations of candidates ``first`` on: random designs, a few failed, a few transient,
    fitness on a coarse grid (ties)."""
    designs = np.column_stack([rng.uniform(-3, 3, n), rng.choice([0.0, 0.05, 0.1], n), rng.uniform(0.08, 0.1, n)])
    fitness = np.round(20 - designs[:, 0] ** 2, 1)
    failed = rng.random(n) < 0.2
    fitness[failed] = math.nan
    status = tuple("failed" if f else "ok" for f in failed)
    batch = BatchResult.of(designs, status, tuple("x" if f else "" for f in failed), distance_m=fitness + 0.5,
                           squat_ratio=0.9, slack_m=0.001, fitness_m=fitness,
                           chain_length_m=1.2, wall_s=0.01)
    keys = [f"{rng.integers(2**63):016x}" * 4 for _ in range(n)]
    part = Request(0, 0, road, np.arange(first, first + n), designs)
    return rows_from_results([(part, batch, batch.fitness_m, keys, bool(rng.random() < 0.3))]), keys


def _entries(session: Session, table: str) -> tuple[list[tuple[object, ...]], set[int]]:
    """Each entry without its level, and the levels that hold some; checks ``index_levels`` against them."""
    rows = session.execute(text(f"SELECT * FROM {table}")).mappings().all()
    kept = dict(session.execute(text("SELECT level, entries FROM index_levels WHERE index_table = :t"),
                                {"t": table}).all())
    assert kept == {level: sum(r["level"] == level for r in rows) for level in range(1, levels.LEVELS)}
    return sorted(tuple(v for k, v in r.items() if k != "level") for r in rows), {r["level"] for r in rows}


def _check(session: Session, job: Job, keys: list[str]) -> tuple[set[int], set[int]]:
    """Each evaluation has one entry in each table it belongs in, and the cache, the near-optimal sets and
    the best designs read through them are what the stored evaluations give; returns the levels in use."""
    stored = session.execute(select(Evaluation).where(Evaluation.job_id == job.id)).scalars().all()
    slot = {e.id: (e.job_id, e.road_index, e.step, e.candidate) for e in stored}
    cache, cache_levels = _entries(session, "cache_index")
    fitness, fitness_levels = _entries(session, "fitness_index")
    assert cache == sorted((key_hash(e.cache_key), *slot[e.id]) for e in stored)
    ok = [e for e in stored if e.status == "ok" and e.fitness_m is not None]
    assert fitness == sorted((e.job_id, e.road_index, e.fitness_m, e.step, e.candidate) for e in ok)
    assert set(cached_evaluations(session, keys)) == {e.cache_key for e in stored if not e.transient}
    top = {job_road.road_index: designs for job_road, designs in top_designs(session, job)}
    for road in (0, 1):
        mine = sorted((e for e in ok if e.road_index == road), key=lambda e: (-e.fitness_m, e.id))
        designs = np.array([[math.radians(e.a2_deg), e.l2_m, e.rws_m] for e in mine]).reshape(-1, 3)
        f, d = np.array([e.fitness_m for e in mine]), np.array([e.distance_m for e in mine])
        for pct in (0.5, 5.0, 50.0):
            _same(road_sharpness(session, job.id, road, pct), near_optimal(designs, f, d, pct))
        assert [g[:4] for g in top[road]] == [(mine[i].a2_deg, mine[i].l2_m, mine[i].rws_m, mine[i].fitness_m)
                                              for i in best_distinct(designs, f)]
    return cache_levels, fitness_levels


def test_every_evaluation_is_looked_up_through_every_level(store_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(levels, "LEVEL0_ROWS", 3)
    monkeypatch.setattr(levels, "MOVE_ROWS", 2)
    monkeypatch.setattr(levels, "GROWTH", 2)
    rng = np.random.default_rng(5)
    db = open_database(Settings(db_url=store_url))
    seen: tuple[set[int], set[int]] = (set(), set())  # the levels that held entries of each table
    try:
        job = _claimed_sweep(db)
        keys: list[str] = []
        for i in range(12):  # the last batch as many rows as PostgreSQL takes by COPY
            rows, batch_keys = _batch(rng, i % 2, 10 * i, COPY_ROWS + 5 if i == 11 else 1 + i % 5)
            keys += batch_keys
            with db.write() as session:
                store_results(session, "s1", job.id, [rows], [])
            if i == 5:  # slots stored already add no entry, beside new ones
                more, more_keys = _batch(rng, 1, 1000, 3)
                keys += more_keys
                with db.write() as session:
                    assert store_results(session, "s1", job.id, [rows + more], []) == len(more)
            with db.read() as session:
                for levels_seen, now in zip(seen, _check(session, session.get(Job, job.id), keys), strict=True):
                    levels_seen |= now
    finally:
        db.dispose()
    assert seen == (set(range(levels.LEVELS)),) * 2  # entries moved up to the last level


def test_a_full_level_moves_a_chunk_at_a_time_round_its_keys(store_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A level at its size gives the level above one chunk a check (``MOVE_ROWS`` entries, and its excess
    when over it), the next keys after the last chunk's, the rest of the level when fewer remain, then
    from the lowest again: a store's transaction never moves a whole large level."""
    monkeypatch.setattr(levels, "LEVEL0_ROWS", 4)
    monkeypatch.setattr(levels, "MOVE_ROWS", 4)
    monkeypatch.setattr(levels, "GROWTH", 2)
    monkeypatch.setattr(levels, "_cursors", {})
    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        rows, _ = _batch(np.random.default_rng(8), 0, 0, 80)
        with db.write() as session:
            store_results(session, "s1", job.id, [rows], [])
            for table in levels.TABLES:  # all on level 2 (size 16), level 3 empty
                n = session.execute(text(f"UPDATE {table} SET level = 2")).rowcount  # type: ignore[attr-defined]
                session.execute(text("UPDATE index_levels SET entries = CASE WHEN level = 2 THEN :n ELSE 0 END "
                                     "WHERE index_table = :t"), {"n": n, "t": table})
        with db.read() as session:
            keys = {table: _entries(session, table)[0] for table in levels.TABLES}
        assert min(len(k) for k in keys.values()) >= 16 + 4 + 9 + 4 + 2 + 4 + 4

        def merge(chunk: int) -> dict[str, list[tuple[object, ...]]]:
            """A check, with level 2 kept as ``chunk`` - MOVE_ROWS over its size of 16."""
            with db.write() as session:
                session.execute(text("UPDATE index_levels SET entries = :n WHERE level = 2"), {"n": 16 + chunk - 4})
                levels.merge_if_full(session, levels.LEVEL0_ROWS)
            with db.read() as session:
                return {table: _entries_at(session, table, 3) for table in levels.TABLES}

        levels._cursors.clear()
        for table, k in merge(4).items():
            assert k == keys[table][:4]
        for table, k in merge(9).items():  # over its size: its excess as well
            assert k == keys[table][:13]
        low = {"cache_index": [(h, job.id, 0, -1, h) for h in (0, 1)],   # keys below the first chunk's
               "fitness_index": [(job.id, -1, f, 0, 0) for f in (0.0, 1.0)]}
        with db.write() as session:
            for table, entries in low.items():
                for entry in entries:
                    session.execute(text(f"INSERT INTO {table} (level, {levels._columns(table)}) "
                                         f"VALUES (2, :a, :b, :c, :d, :e)"), dict(zip("abcde", entry, strict=True)))
                session.execute(text("UPDATE index_levels SET entries = entries + 2 WHERE index_table = :t "
                                     "AND level = 2"), {"t": table})
        for table, k in merge(4).items():  # the keys after the last chunk's, not the lowest
            assert k == keys[table][:17]
        for table, k in keys.items():  # this process last moved the third key from the end
            levels._cursors[(str(db.engine.url), table, 2)] = k[-3]
        for table, k in merge(4).items():  # the rest of the level
            assert k == keys[table][:17] + keys[table][-2:]
        for table, k in merge(4).items():  # then from the lowest
            assert k == sorted(low[table] + keys[table][:19] + keys[table][-2:])
        for table, k in keys.items():  # the last chunk ended at the level's last key
            levels._cursors[(str(db.engine.url), table, 2)] = k[-3]
        for table, k in merge(4).items():  # from the lowest at once
            assert k == sorted(low[table] + keys[table][:23] + keys[table][-2:])
    finally:
        db.dispose()


def test_level_0_moves_a_chunk_once_full(store_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Level 0 at its size gives level 1 ``MOVE_ROWS`` entries, its lowest keys, and is not emptied;
    over its size, its excess as well."""
    for name, value in (("LEVEL0_ROWS", 8), ("MOVE_ROWS", 2), ("_cursors", {}), ("_added", {}), ("_level0", {})):
        monkeypatch.setattr(levels, name, value)
    rng = np.random.default_rng(3)
    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)

        def store(first: int, n: int) -> tuple[list[tuple[object, ...]], list[tuple[object, ...]]]:
            with db.write() as session:
                store_results(session, "s1", job.id, [_batch(rng, 0, first, n)[0]], [])
            with db.read() as session:
                return _entries_at(session, "cache_index", 0), _entries_at(session, "cache_index", 1)

        for i in range(7):
            level0, level1 = store(i, 1)
        assert (len(level0), level1) == (7, [])
        level0, level1 = store(7, 1)   # at its size: a chunk
        assert (len(level0), len(level1)) == (6, 2)
        assert max(level1) < min(level0)   # the lowest keys
        level0, level1 = store(8, 3)   # 9 entries: one over, and a chunk
        assert (len(level0), len(level1)) == (6, 5)
    finally:
        db.dispose()


def _entries_at(session: Session, table: str, level: int) -> list[tuple[object, ...]]:
    """The entries of a level, without it, by key."""
    rows = session.execute(text(f"SELECT * FROM {table} WHERE level = {level}")).mappings().all()
    return sorted(tuple(v for k, v in r.items() if k != "level") for r in rows)


def test_two_writers_moving_levels_at_once_keep_one_entry_each(store_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two schedulers' writers storing at once, each moving full levels as it goes (level 0 of 3 entries,
    so nearly every store moves some): every evaluation of both jobs keeps exactly one entry in each
    table it belongs in, and the kept sizes are the levels'. On PostgreSQL the moves run concurrently; a
    deadlock between two of them, which PostgreSQL breaks, is retried, as the writer retries a failed
    store."""
    monkeypatch.setattr(levels, "LEVEL0_ROWS", 3)
    monkeypatch.setattr(levels, "MOVE_ROWS", 3)
    monkeypatch.setattr(levels, "GROWTH", 2)
    db = open_database(Settings(db_url=store_url))
    errors: list[BaseException] = []
    try:
        first = _claimed_sweep(db)
        second, _ = submit_job(db, JobSpec.model_validate(SWEEP), idempotency_key=None, max_evaluations=1000,
                               max_cpu_hours=1.0)
        with db.write() as session:
            register_scheduler(session, "s2", host="h", pid=2, executor="serial", capacity=1)
            assert claim_jobs(session, "s2", lease_s=30.0, limit=1) == [second.id]

        def write(job_id: int, scheduler: str, seed: int) -> None:
            rng = np.random.default_rng(seed)
            try:
                for i in range(40):
                    rows, _ = _batch(rng, i % 2, 10 * i, 1 + i % 7)
                    for _attempt in range(20):
                        try:
                            with db.write() as session:
                                store_results(session, scheduler, job_id, [rows], [])
                            break
                        except OperationalError as exc:
                            if "deadlock" not in str(exc):
                                raise
            except BaseException as exc:
                errors.append(exc)

        threads = [threading.Thread(target=write, args=args) for args in ((first.id, "s1", 1), (second.id, "s2", 2))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert not errors, errors
        with db.read() as session:
            stored = session.execute(select(Evaluation)).scalars().all()
            cache, cache_levels = _entries(session, "cache_index")
            fitness, fitness_levels = _entries(session, "fitness_index")
    finally:
        db.dispose()
    assert len(stored) == 2 * sum(1 + i % 7 for i in range(40))
    assert cache == sorted((key_hash(e.cache_key), e.job_id, e.road_index, e.step, e.candidate) for e in stored)
    assert fitness == sorted((e.job_id, e.road_index, e.fitness_m, e.step, e.candidate) for e in stored
                             if e.status == "ok" and e.fitness_m is not None)
    assert {2, 3} <= cache_levels & fitness_levels  # entries moved on, chunks included
