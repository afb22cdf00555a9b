"""What durable commits cost the scheduler's store: results stored through ``store_results`` with
each commit flushed (what finaldrive does) against an asynchronous commit (SQLite
``synchronous=NORMAL``, PostgreSQL ``synchronous_commit=off``: what it did before results were lost
in a PostgreSQL crash), in one run, as a ratio.

    python bench/bench_commit.py                                  # a temporary SQLite file
    python bench/bench_commit.py --db postgresql+psycopg://...    # any store; repeat --db for several
    python bench/bench_commit.py --grow 1000000 --rows 16000      # the rate as one store grows
    python bench/bench_commit.py --writers 1 2 --rows 8000 --db postgresql+psycopg://...  # writers at once

Each measurement stores ``--transactions`` transactions of ``--rows`` evaluations (the writer's
transaction holds what arrived in one flush); printed: evaluations stored per second, the median of
``--repeat`` runs for each mode, alternated, and durable/async.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from bench_scheduler import SleepTask
from sqlalchemy import event

from finaldrive.engine import Request, Road, SimSettings
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import WRITER_CACHE_KIB, Database
from finaldrive.service.db.leases import claim_jobs, register_scheduler
from finaldrive.service.db.results import store_results
from finaldrive.service.jobs.cache import context_digest, design_keys
from finaldrive.service.jobs.rows import rows_from_results
from finaldrive.service.jobs.submit import submit_job
from finaldrive.service.machine import describe
from finaldrive.service.schemas import JobSpec
from finaldrive.service.services import open_database

SPEC = {"kind": "sweep", "roads": ["flat"], "grid": "a2_deg=0:90:30"}


def _rows(n: int, first: int) -> list[tuple[object, ...]]:
    """``n`` evaluations of one road, candidates ``first`` on (the stand-in's results, engine-shaped:
    every value finite; the scheduler's cache keys, so their index is filled at random places as in a
    real job)."""
    rng = np.random.default_rng(first)
    designs = np.column_stack([rng.uniform(0, 6.28, n), rng.uniform(0, 0.2, n), rng.uniform(0.05, 0.2, n)])
    part = Request(0, 0, 0, np.arange(first, first + n), designs)
    batch = SleepTask(0.0, sleep=False).results(designs)
    keys = design_keys(context_digest(Road("flat"), SimSettings(), None, "bench"), designs)
    return rows_from_results([(part, batch, batch.fitness_m, keys, False)])


def _store(db: Database, rows: int, transactions: int, first: int) -> float:
    """Evaluations stored per second by ``transactions`` transactions of ``rows`` rows."""
    job, _ = submit_job(db, JobSpec.model_validate(SPEC), idempotency_key=None, max_evaluations=10**9,
                        max_cpu_hours=1e6)
    with db.write() as session:
        register_scheduler(session, "bench", host="h", pid=0, executor="serial", capacity=1)
        claim_jobs(session, "bench", lease_s=3600, limit=100)
    batches = [_rows(rows, first + i * rows) for i in range(transactions)]
    start = time.perf_counter()
    for batch in batches:
        with db.write() as session:
            store_results(session, "bench", job.id, [batch], [])
    return rows * transactions / (time.perf_counter() - start)


def _database(url: str, durable: bool, cache_kib: int | None) -> Database:
    """The store as finaldrive's writer opens it, or with every commit asynchronous."""
    db = Database(url, cache_kib=cache_kib)
    if not durable:  # after finaldrive's own set-up of each new connection
        if db.engine.dialect.name == "postgresql":
            event.listen(db.engine, "connect", lambda c, _: c.execute("SET synchronous_commit = off"))
        else:
            event.listen(db.engine, "connect", lambda c, _: c.execute("PRAGMA synchronous = NORMAL"))
    return db


def measure(url: str, rows: int, transactions: int, repeat: int,
            cache_kib: int | None = WRITER_CACHE_KIB) -> dict[str, object]:
    open_database(Settings(db_url=url)).dispose()  # the schema
    found: dict[bool, list[float]] = {True: [], False: []}
    store = ""
    for r in range(repeat):
        for durable in (True, False):
            db = _database(url, durable, cache_kib)
            store = db.engine.dialect.name
            try:
                found[durable].append(_store(db, rows, transactions, (2 * r + int(durable)) * rows * transactions))
            finally:
                db.dispose()
    durable, fast = statistics.median(found[True]), statistics.median(found[False])
    return {"store": store, "rows_per_transaction": rows, "transactions": transactions,
            "durable_evaluations_per_s": round(durable), "async_evaluations_per_s": round(fast),
            "durable_over_async": round(durable / fast, 3), "runs": repeat}


def grow(url: str, rows: int, total: int, steps: int, drop: list[str], cache_kib: int | None) -> dict[str, object]:
    """Durable evaluations stored a second as the store grows to ``total``, in transactions of ``rows``: the
    rate over each of ``steps`` equal parts (rows made before each part's clock starts) and its slowest
    transaction (the longest the writer held the write lock), after dropping the
    ``drop`` indexes of ``evaluations`` (what each costs)."""
    open_database(Settings(db_url=url)).dispose()  # the schema
    db = Database(url, cache_kib=cache_kib)
    try:
        with db.engine.begin() as connection:
            for name in drop:
                connection.exec_driver_sql(f"DROP INDEX {name}")
        job, _ = submit_job(db, JobSpec.model_validate(SPEC), idempotency_key=None, max_evaluations=10**9,
                            max_cpu_hours=1e6)
        with db.write() as session:
            register_scheduler(session, "bench", host="h", pid=0, executor="serial", capacity=1)
            claim_jobs(session, "bench", lease_s=3600, limit=100)
        per_step, rates, stored = max(1, total // steps // rows), [], 0
        for _ in range(steps):
            batches = [_rows(rows, stored + i * rows) for i in range(per_step)]
            start, slowest = time.perf_counter(), 0.0
            for batch in batches:
                began = time.perf_counter()
                with db.write() as session:
                    store_results(session, "bench", job.id, [batch], [])
                slowest = max(slowest, time.perf_counter() - began)
            seconds = time.perf_counter() - start
            stored += per_step * rows
            rates.append({"stored": stored, "evaluations_per_s": round(per_step * rows / seconds),
                          "slowest_transaction_s": round(slowest, 2)})
    finally:
        db.dispose()
    return {"store": url.split(":", 1)[0], "rows_per_transaction": rows, "dropped": drop, "rates": rates}


def _writer(url: str, job_id: int, firsts: list[int], rows: int, cache_kib: int | None, start: Any,
            done: Any) -> None:
    """One writer process of :func:`parallel`: its transactions' rows made, then stored from ``start``."""
    db = Database(url, cache_kib=cache_kib)
    batches = [_rows(rows, first) for first in firsts]
    start.wait()
    for batch in batches:
        with db.write() as session:
            store_results(session, "bench", job_id, [batch], [])
    db.dispose()
    done.put(time.perf_counter())


def parallel(url: str, rows: int, total: int, writers: list[int], repeat: int,
             cache_kib: int | None) -> dict[str, object]:
    """Durable evaluations stored a second by ``n`` writer processes at once, for each ``n`` of ``writers``
    (finaldrive.service.jobs.writer_pool): ``total`` evaluations of one job, in transactions of ``rows``
    dealt round the writers; a new job each measurement, the counts alternated ``repeat`` times."""
    open_database(Settings(db_url=url)).dispose()  # the schema
    context = multiprocessing.get_context("spawn")
    found: dict[int, list[float]] = {n: [] for n in writers}
    db = Database(url, cache_kib=cache_kib)
    try:
        with db.write() as session:
            register_scheduler(session, "bench", host="h", pid=0, executor="serial", capacity=1)
        for r in range(repeat):
            for n in writers if r % 2 == 0 else writers[::-1]:
                job, _ = submit_job(db, JobSpec.model_validate(SPEC), idempotency_key=None, max_evaluations=10**9,
                                    max_cpu_hours=1e6)
                with db.write() as session:
                    claim_jobs(session, "bench", lease_s=3600, limit=100)
                firsts = list(range(0, total // rows * rows, rows))
                start, done = context.Event(), context.Queue()
                processes = [context.Process(target=_writer, args=(url, job.id, firsts[k::n], rows, cache_kib, start,
                                                                   done)) for k in range(n)]
                for process in processes:
                    process.start()
                time.sleep(1.0 + 0.5 * n)   # their rows made (the clock starts after)
                began = time.perf_counter()
                start.set()
                ended = max(done.get(timeout=600) for _ in processes)
                for process in processes:
                    process.join()
                found[n].append(len(firsts) * rows / (ended - began))
    finally:
        db.dispose()
    return {"store": url.split(":", 1)[0], "rows_per_transaction": rows, "evaluations": total,
            "evaluations_per_s": {n: round(statistics.median(found[n])) for n in writers},
            "runs": {n: [round(v) for v in found[n]] for n in writers}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", action="append", help="SQLAlchemy URL (repeatable; default a temporary SQLite file)")
    parser.add_argument("--rows", type=int, nargs="+", default=[100, 1000, 10000], help="rows a transaction")
    parser.add_argument("--evaluations", type=int, default=20000, help="evaluations a measurement")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cache-kib", type=int, default=WRITER_CACHE_KIB,
                        help="SQLite page cache of the storing connection [KiB] (the writer's; 0: SQLite's default)")
    parser.add_argument("--grow", type=int, metavar="N",
                        help="instead: durable rates as one store grows to N evaluations (--rows a transaction), "
                             "over 10 parts")
    parser.add_argument("--drop-index", action="append", default=[], metavar="NAME",
                        help="with --grow: drop this index of evaluations first (repeatable)")
    parser.add_argument("--writers", type=int, nargs="+", metavar="N",
                        help="instead: durable rates of N writer processes storing one job at once (--rows a "
                             "transaction, --evaluations in all), alternated --repeat times")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.writers and (args.grow or min(args.writers) < 1):
        parser.error("--writers takes counts of 1 or more, and not --grow")
    if args.drop_index and not args.grow:
        parser.error("--drop-index goes with --grow")
    if args.grow and (len(args.rows) != 1 or args.grow < 10 * args.rows[0]):
        parser.error("--grow N takes one --rows R, and N >= 10 R (10 parts)")
    with tempfile.TemporaryDirectory() as tmp:
        urls = args.db or [f"sqlite:///{Path(tmp) / 'commit.db'}"]
        if args.writers:
            found = [parallel(url, rows, args.evaluations, args.writers, args.repeat, args.cache_kib or None)
                     for url in urls for rows in args.rows]
            print(json.dumps({"machine": describe(), "results": found}, indent=None if args.json else 1))
            return 0
        if args.grow:
            grown = [grow(url, args.rows[0], args.grow, 10, args.drop_index, args.cache_kib or None) for url in urls]
            print(json.dumps({"machine": describe(), "results": grown}, indent=None if args.json else 1))
            return 0
        out = [measure(url, rows, max(1, args.evaluations // rows), args.repeat, args.cache_kib or None)
               for url in urls for rows in args.rows]
    if args.json:
        print(json.dumps({"machine": describe(), "results": out}, indent=1))
    else:
        print(describe())
        for r in out:
            print(f"{r['store']:10} {r['rows_per_transaction']:6} rows/commit: durable "
                  f"{r['durable_evaluations_per_s']:8} /s, async {r['async_evaluations_per_s']:8} /s, "
                  f"ratio {r['durable_over_async']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
