"""The scheduler's path through the store, on SQLite and PostgreSQL: fenced bulk writes and the
result cache read back through the driver."""

from __future__ import annotations

import dataclasses
import math
from functools import partial

import numpy as np
import pytest
from sqlalchemy import func, select, update

from finaldrive.engine import DIAGNOSTICS, BatchResult, Request, Road
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.leases import claim_jobs, register_scheduler
from finaldrive.service.db.models import Evaluation, Job, JobRoad
from finaldrive.service.db.results import CACHED_COLUMNS, cached_evaluations, finish_if_complete, store_results
from finaldrive.service.jobs.rows import rows_from_results
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database
from tests.service.svc_helpers import SWEEP, toy_batch


def _claimed_sweep(db: Database) -> Job:
    """A sweep job, claimed by the scheduler "s1"."""
    job, _ = submit_job(db, JobSpec.model_validate(SWEEP), idempotency_key=None, max_evaluations=1000,
                        max_cpu_hours=1.0)
    with db.write() as session:
        register_scheduler(session, "s1", host="h", pid=1, executor="serial", capacity=1)
        assert claim_jobs(session, "s1", lease_s=30.0, limit=1) == [job.id]
    return job


def test_rows_are_stored_once_with_the_roads_best_and_read_back_as_cache_hits(store_url: str) -> None:
    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        k0, k1, k2, k3 = (f"{i:x}" * 64 for i in range(4))  # sha256-shaped keys
        designs = np.array([[0.5, 0.1, 0.09], [1.0, 0.2, 0.09], [1.5, 0.1, 0.09]])
        part = Request(0, 0, 1, np.arange(3), designs)
        road = Road.parse("sine:0.025:3")
        first, last = part.split(2)
        batch = toy_batch(first.designs, road, fail_above_l2=0.15)  # the second design fails
        again = BatchResult.failed(last.designs, "worker lost: its process died repeatedly while simulating")
        stable, lost = (rows_from_results([finished]) for finished in (
            (first, batch, batch.fitness_m, [k0, k1], False), (last, again, again.fitness_m, [k2], True)))
        with db.write() as session:
            assert store_results(session, "s1", job.id, [stable + lost], []) == 3
        with db.write() as session:  # the same slots again: stored once
            assert store_results(session, "s1", job.id, [stable], []) == 0
        with db.read() as session:
            hits = cached_evaluations(session, [k0, k1, k2, k3])
            job_road = session.get(JobRoad, (job.id, 1))
            assert job_road is not None and job_road.best_evaluation_id is not None
            best = session.get(Evaluation, job_road.best_evaluation_id)
    finally:
        db.dispose()
    assert set(hits) == {k0, k1}  # k2's worker was lost (transient); k3 was never stored
    assert set(hits[k0]) == set(CACHED_COLUMNS)
    assert math.isclose(hits[k0]["distance_m"], batch.distance_m[0])
    assert math.isclose(hits[k0]["fitness_m"], batch.fitness_m[0]) and hits[k0]["status"] == "ok"
    assert hits[k1]["fitness_m"] is None and hits[k1]["status"] == "failed"
    assert hits[k1]["reason"] == "fake divergence"
    assert all(hits[k0][name] is None for name in DIAGNOSTICS)  # NaN stored as NULL
    assert best is not None and best.candidate == 0 and job_road.best_fitness_m == batch.fitness_m[0]


def test_a_row_holds_each_column_s_value_as_a_plain_python_value() -> None:
    """Each row, built a block at a time, holds ROW_COLUMNS' values for its own design: the slot, the
    design in degrees and metres, the result record with the job's fitness (NaN where not produced),
    status, reason, flags (0 or 1) and key, each a plain int, float or str (the driver binds no numpy
    scalar, and no bool: SQLite's driver adapts a bool at a cost), whatever the row's neighbours."""
    from finaldrive.engine import VALUES
    from finaldrive.service.db.results import ROW_COLUMNS, key_hash

    designs = np.array([[0.5, 0.1, 0.09], [1.0, 0.2, 0.09], [-1.5, 0.05, 0.12]])
    part = Request(2, 7, 3, np.array([4, 9, 11]), designs)
    batch = toy_batch(designs, Road.parse("sine:0.025:3"), fail_above_l2=0.15)   # the second fails
    job_fitness = np.array([1.5, np.nan, np.inf])                                # the third not finite
    keys = [f"{i:x}" * 64 for i in (10, 11, 12)]
    rows = rows_from_results([(part, batch, job_fitness, keys, False)])
    for i, row in enumerate(rows):
        fitness = float(job_fitness[i])
        record = dict(zip(VALUES, batch.values[i].tolist(), strict=True)) | {"fitness_m": fitness}
        fails = not math.isfinite(fitness)
        a2, l2, rws = designs[i].tolist()
        want = {"road_index": 3, "step": 7, "candidate": [4, 9, 11][i], "a2_deg": math.degrees(a2), "l2_m": l2,
                "rws_m": rws,
                **{name: v if math.isfinite(v) else math.nan for name, v in record.items()},
                "status": "failed" if fails else "ok",
                "reason": batch.reason[i] or (f"non-finite fitness ({fitness})" if fails else ""),
                "cached": 0, "cache_key": keys[i], "cache_hash": key_hash(keys[i]),
                "transient": 0}
        assert list(want) == list(ROW_COLUMNS)
        got = dict(zip(ROW_COLUMNS, row, strict=True))
        for name, value in want.items():
            assert type(got[name]) is type(value), (name, type(got[name]))   # int, float or str: plain
            assert got[name] == value or (math.isnan(value) and math.isnan(got[name])), (i, name)


def test_a_job_succeeds_only_over_a_complete_store_and_a_hole_reopens_it(store_url: str) -> None:
    """finish_if_complete counts what the store holds in the finishing transaction: fewer rows than the
    runs made (results lost after they were acknowledged) give the job back to resume, never a success."""
    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        part = Request(0, 0, 0, np.arange(3), np.array([[0.5, 0.1, 0.09], [1.0, 0.1, 0.09], [1.5, 0.1, 0.09]]))
        batch = toy_batch(part.designs, Road.parse("flat"))
        rows = rows_from_results([(part, batch, batch.fitness_m, [f"{i:x}" * 64 for i in range(3)], False)])
        with db.write() as session:
            store_results(session, "s1", job.id, [rows], [])
        finish = partial(finish_if_complete, scheduler_id="s1", job_id=job.id, generations=0, planned=job.total)
        with db.write() as session:  # the runs made 4: one is missing
            assert finish(session, evaluations=4) == "reopened"
        with db.read() as session:
            reopened = session.get(Job, job.id)
        with db.write() as session:
            assert claim_jobs(session, "s1", lease_s=30.0, limit=1) == [job.id]
            assert finish(session, evaluations=3) == "finished"
        with db.write() as session:  # finished: no longer this scheduler's
            assert finish(session, evaluations=3) == "lost"
        with db.read() as session:
            done = session.get(Job, job.id)
    finally:
        db.dispose()
    assert reopened is not None and (reopened.state, reopened.owner) == ("interrupted", None)
    assert done is not None and done.state == "succeeded" and (done.n_done, done.total) == (3, 3)


def test_a_store_by_a_scheduler_that_lost_the_job_writes_nothing(store_url: str) -> None:
    """The fence is the store's last statement (the job's row is locked only from there to the commit):
    a store by a scheduler that does not own the job raises LeaseLost, and none of its rows, index
    entries, best, ranges or generations is left; the owner's store of the same slots then stores each
    once, and a repeat leaves the counters equal to the rows."""
    from finaldrive.service.db.levels import TABLES
    from finaldrive.service.db.models import Generation, RoadExplored
    from finaldrive.service.db.results import LeaseLost

    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        part = Request(0, 0, 1, np.arange(3), np.array([[0.5, 0.1, 0.09], [1.0, 0.2, 0.09], [1.5, 0.1, 0.09]]))
        batch = toy_batch(part.designs, Road.parse("sine:0.025:3"), fail_above_l2=0.15)
        rows = rows_from_results([(part, batch, batch.fitness_m, [f"{i:x}" * 64 for i in range(3)], False)])
        told = [{"run": 0, "generation": 1, "population": [[0.5, 0.1, 0.09]], "fitness_m": [20.0], "state": {},
                 "best_fitness_m": 20.0, "mean_fitness_m": 20.0, "n_evals": 3, "n_failed": 1}]

        def left() -> tuple[int, ...]:
            with db.read() as session:
                counts = [session.scalar(select(func.count()).select_from(table).where(table.job_id == job.id))
                          for table in (Evaluation, Generation, RoadExplored)]
                entries = [session.connection().exec_driver_sql(f"SELECT COUNT(*) FROM {name}").scalar()
                           for name in TABLES]
                road = session.get(JobRoad, (job.id, 1))
                stored = session.get(Job, job.id)
                assert road is not None and stored is not None
                return (*counts, *entries, road.best_evaluation_id is not None,
                        stored.n_done, stored.n_failed, stored.n_cached)

        with pytest.raises(LeaseLost), db.write() as session:
            store_results(session, "s2", job.id, [rows], told)
        assert left() == (0, 0, 0, 0, 0, False, 0, 0, 0)
        with db.write() as session:
            assert store_results(session, "s1", job.id, [rows], told) == 3
        with db.write() as session:  # the same slots again: nothing new, counted once
            assert store_results(session, "s1", job.id, [rows], []) == 0
        evaluations, generations, ranges, *entries, best, n_done, n_failed, n_cached = left()
    finally:
        db.dispose()
    assert (evaluations, generations, entries, best, n_done, n_failed, n_cached) == (3, 1, [3, 2], True, 2, 1, 0)
    assert ranges >= 1


def test_a_finished_job_s_counters_equal_its_rows(store_url: str) -> None:
    """The counters change with each store, in its transaction; finishing recounts them only when their
    sum is not the store's count (a scan of every row of the job, under the write lock)."""
    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        part = Request(0, 0, 0, np.arange(3), np.array([[0.5, 0.1, 0.09], [1.0, 0.2, 0.09], [1.5, 0.1, 0.09]]))
        batch = toy_batch(part.designs, Road.parse("flat"), fail_above_l2=0.15)  # the second design fails
        rows = rows_from_results([(part, batch, batch.fitness_m, [f"{i:x}" * 64 for i in range(3)], False)])
        with db.write() as session:
            store_results(session, "s1", job.id, [rows], [])
        with db.write() as session:  # counters off, as no store leaves them
            session.execute(update(Job).where(Job.id == job.id).values(n_done=7, n_failed=0, n_cached=5))
        with db.write() as session:
            assert finish_if_complete(session, scheduler_id="s1", job_id=job.id, evaluations=3, generations=0,
                                      planned=job.total) == "finished"
        with db.read() as session:
            done = session.get(Job, job.id)
    finally:
        db.dispose()
    assert done is not None and (done.n_done, done.n_failed, done.n_cached) == (2, 1, 0)


def test_bulk_stores_keep_every_value_and_skip_what_is_stored(store_url: str) -> None:
    """Hundreds of rows a transaction (PostgreSQL: by COPY), in chunks smaller than COPY_ROWS: every
    column read back as given, NULLs, flags of 1 (a boolean's true), a reason with tabs, newlines and
    backslashes; a second store overlapping the first, in the same transaction, adds only the new slots;
    the explored ranges equal their recount; the road's best is the best of all the chunks' rows."""
    from sqlalchemy import text

    from finaldrive.service.db.results import COPY_ROWS, ROW_COLUMNS
    from finaldrive.service.db.summaries import recount_explored

    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        n = 3 * COPY_ROWS
        rng = np.random.default_rng(2)
        designs = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(0, 0.2, n), rng.uniform(0.05, 0.2, n)])
        road = Road.parse("sine:0.025:3")
        batch = toy_batch(designs, road, fail_above_l2=0.15)
        reasons = tuple(r and "bad\tvalue\nline 2 \\N \\ end" for r in batch.reason)
        batch = dataclasses.replace(batch, reason=reasons)
        keys = [f"{i:064x}" for i in range(n)]
        rows = rows_from_results([(Request(0, 0, 0, np.arange(n), designs), batch, batch.fitness_m, keys, False)])
        cached, transient = ROW_COLUMNS.index("cached"), ROW_COLUMNS.index("transient")
        rows = [tuple(1 if (at == cached and i % 3 == 0) or (at == transient and i % 5 == 0) else v  # flags set
                      for at, v in enumerate(row)) for i, row in enumerate(rows)]
        half = 2 * COPY_ROWS
        explored = "SELECT * FROM road_explored ORDER BY road_index, bucket"
        with db.write() as session:  # new slots only: the writer merges them into road_explored
            chunks = [rows[start:min(start + COPY_ROWS // 3, half)] for start in range(0, half, COPY_ROWS // 3)]
            assert store_results(session, "s1", job.id, chunks, []) == half
            best = session.execute(text("SELECT best_fitness_m FROM job_roads WHERE job_id = :j AND road_index = 0"),
                                   {"j": job.id}).scalar()
            assert best == max(r[ROW_COLUMNS.index("fitness_m")] for r in rows[:half]
                           if r[ROW_COLUMNS.index("status")] == "ok")
            merged = session.execute(text(explored)).all()
            recount_explored(session, job.id)
            assert merged == session.execute(text(explored)).all() and len(merged) > 30
            assert store_results(session, "s1", job.id, [rows[COPY_ROWS:]], []) == n - half
        with db.read() as session:
            stored = session.execute(text(f"SELECT {', '.join(ROW_COLUMNS)} FROM evaluations WHERE job_id = :j "
                                          "ORDER BY candidate"), {"j": job.id}).all()
            after = session.execute(text(explored)).all()
            counts = session.execute(text("SELECT n_done, n_failed FROM jobs WHERE id = :j"), {"j": job.id}).one()
        with db.write() as session:
            recount_explored(session, job.id)
        with db.read() as session:
            recounted = session.execute(text(explored)).all()
    finally:
        db.dispose()
    assert len(stored) == n and any(r[ROW_COLUMNS.index("fitness_m")] is None for r in stored)
    for got, given in zip(stored, rows, strict=True):  # a row's NaN (not produced) is stored as NULL; a flag's
        assert tuple(got) == tuple(None if isinstance(w, float) and math.isnan(w) else w for w in given)  # 1: true
    assert after == recounted and sum(c[3] for c in after) == counts[0]
    assert counts == (sum(r[ROW_COLUMNS.index("status")] == "ok" for r in rows),
                      sum(r[ROW_COLUMNS.index("status")] != "ok" for r in rows))


def test_stored_rows_carry_their_job_and_the_store_s_time(store_url: str) -> None:
    """The job and the time, the same for every row of a store, are written into the statement (or, by
    COPY, the INSERT's parameters): read back as the job's id and the database's time of the store."""
    from finaldrive.service.db.leases import db_now
    from finaldrive.service.db.results import COPY_ROWS

    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        n = 3 + 3 * COPY_ROWS   # a store of 3 rows (executemany), then one of 300 (PostgreSQL: COPY)
        designs = np.column_stack([np.linspace(0, 3, n), np.full(n, 0.1), np.full(n, 0.09)])
        batch = toy_batch(designs, Road.parse("flat"))
        rows = rows_from_results([(Request(0, 0, 0, np.arange(n), designs), batch, batch.fitness_m,
                                   [f"{i:064x}" for i in range(n)], False)])
        times = []
        for part in (rows[:3], rows[3:]):
            with db.write() as session:
                times.append(db_now(session))
                store_results(session, "s1", job.id, [part], [])
                times.append(db_now(session))
        with db.read() as session:
            stored = session.execute(select(Evaluation.candidate, Evaluation.job_id, Evaluation.created_at)
                                     .order_by(Evaluation.candidate)).all()
    finally:
        db.dispose()
    assert [c for c, *_ in stored] == list(range(n)) and {j for _, j, _ in stored} == {job.id}
    for (low, high), part in zip([times[:2], times[2:]], [stored[:3], stored[3:]], strict=True):
        assert all(low <= created <= high for *_, created in part), (low, high, part[0])


def test_bulk_stored_generations_keep_their_json(store_url: str) -> None:
    """Hundreds of told generations a transaction (PostgreSQL: by COPY, in text for their JSON columns, whose
    binary format would encode the stored JSON text again): population, fitness and state read back as given."""
    from sqlalchemy import select

    from finaldrive.service.db.models import Generation
    from finaldrive.service.db.results import COPY_ROWS

    generations = [{"run": 0, "generation": g, "population": [[0.5 * g, 0.1, 0.09]], "fitness_m": [20.0 - g, None],
                    "state": {"method": "de", "generation": g, "rng": [g, "a\tb\\N"]}, "best_fitness_m": 20.0 - g,
                    "mean_fitness_m": None, "n_evals": 12 * g, "n_failed": g % 3} for g in range(1, COPY_ROWS + 2)]
    db = open_database(Settings(db_url=store_url))
    try:
        job = _claimed_sweep(db)
        with db.write() as session:
            store_results(session, "s1", job.id, [], generations)
        with db.read() as session:
            stored = session.execute(select(Generation).where(Generation.job_id == job.id)
                                     .order_by(Generation.generation)).scalars().all()
            got = [{"run": r.run, "generation": r.generation, "population": r.population, "fitness_m": r.fitness_m,
                    "state": r.state, "best_fitness_m": r.best_fitness_m, "mean_fitness_m": r.mean_fitness_m,
                    "n_evals": r.n_evals, "n_failed": r.n_failed} for r in stored]
    finally:
        db.dispose()
    assert got == generations


def _interleaved(postgres: object, pause: str) -> tuple[int, list[tuple[float, int]], float | None]:
    """Two writers of one job on PostgreSQL (finaldrive.service.jobs.writer_pool): writer A stores three
    designs but stops at ``pause`` (a name in finaldrive.service.db.results) while writer B stores three
    better ones of the same road and commits; then A goes on. Returns the evaluations stored, the fitness
    index's entries (fitness, candidate) and the road's best fitness."""
    import threading

    from sqlalchemy import text

    from finaldrive.service.db import results as store

    db = open_database(Settings(db_url=str(postgres.new_database())))  # type: ignore[attr-defined]
    road = Road.parse("sine:0.025:3")

    def rows(candidates: list[int], a2: list[float], tag: str) -> list[tuple[object, ...]]:
        designs = np.array([[a, 0.1, 0.09] for a in a2])  # other a2 buckets: no row lock in common before B ends
        batch = toy_batch(designs, road)
        keys = [f"{tag}{i:063x}" for i in candidates]
        return rows_from_results([(Request(0, 0, 0, np.array(candidates), designs), batch, batch.fitness_m, keys,
                                   False)])

    paused, resume = threading.Event(), threading.Event()
    real, writer_b = getattr(store, pause), threading.current_thread()
    errors: list[BaseException] = []

    def stop_in_a(*args: object, **kwargs: object) -> object:
        if threading.current_thread() is not writer_b:
            paused.set()
            assert resume.wait(30)
        return real(*args, **kwargs)

    def store_a() -> None:
        try:
            with db.write() as session:
                store_results(session, "s1", job.id, [rows([0, 1, 2], [3.0, 3.1, 3.2], "a")], [])
        except BaseException as exc:  # reported by the test
            errors.append(exc)

    try:
        job = _claimed_sweep(db)
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(store, pause, stop_in_a)
            thread = threading.Thread(target=store_a)
            thread.start()
            assert paused.wait(30)
            with db.write() as session:  # writer B, whole, while A waits in its transaction
                assert store_results(session, "s1", job.id, [rows([3, 4, 5], [1.0, 1.05, 1.1], "b")], []) == 3
            resume.set()
            thread.join(30)
        assert not errors, errors
        with db.read() as session:
            stored = session.scalar(select(func.count()).where(Evaluation.job_id == job.id))
            entries = session.execute(text("SELECT fitness_m, candidate FROM fitness_index ORDER BY candidate")).all()
            best = session.execute(text("SELECT best_fitness_m FROM job_roads WHERE job_id = :j AND road_index = 0"),
                                   {"j": job.id}).scalar()
            assert session.scalar(text("SELECT COUNT(*) FROM cache_index")) == stored
    finally:
        db.dispose()
    return int(stored or 0), [tuple(e) for e in entries], best


def test_a_writer_enters_only_its_own_rows_while_another_stores_the_same_job(postgres: object) -> None:
    """Writer B commits while A has inserted its rows but not yet entered them in the index tables:
    A enters its own three (B's, visible to it by then, are B's to enter: once each)."""
    stored, entries, best = _interleaved(postgres, "add_entries")
    assert stored == 6 and [candidate for _, candidate in entries] == list(range(6))
    assert best == max(fitness for fitness, _ in entries[3:]) > max(fitness for fitness, _ in entries[:3])


def test_a_writer_keeps_the_better_best_another_stored_since_it_read_it(postgres: object) -> None:
    """Writer A read the road's best (none) before B stored a better one and committed: A's worse best
    does not overwrite it (the comparison is made again in A's update)."""
    stored, entries, best = _interleaved(postgres, "_better")
    assert stored == 6 and len(entries) == 6
    assert best == max(fitness for fitness, _ in entries[3:]) > max(fitness for fitness, _ in entries[:3])


def test_postgresql_sessions_run_without_jit(postgres: object) -> None:
    """The store's sessions turn PostgreSQL's JIT off: with a growing store's statistics it compiled each
    result-cache lookup first (0.1-0.5 s of the server's CPU for a ~10 ms query; docs/performance-log.md)."""
    from sqlalchemy import text

    db = open_database(Settings(db_url=str(postgres.new_database())))  # type: ignore[attr-defined]
    try:
        with db.read() as session:
            assert session.execute(text("SHOW jit")).scalar() == "off"
    finally:
        db.dispose()
