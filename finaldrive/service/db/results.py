"""The scheduler's path through the store: what a job has stored, the result cache, and writes.

Every write of results is fenced: it happens only while the writing scheduler still owns the
job (the job's counters are bumped first, matching only its owner, in the same transaction), so
a scheduler that lost its lease can never store anything. Rows are inserted in bulk, and a slot
(job, road, step, candidate) that is somehow stored already is skipped, never stored twice.
"""

from __future__ import annotations

import base64
import itertools
import json
import logging
import math
from collections.abc import Iterable, Sequence
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import Boolean, func, select, update
from sqlalchemy.orm import Session

from finaldrive.engine import VALUES, plain_json
from finaldrive.service.db.engine import marker
from finaldrive.service.db.leases import db_now, finish_job, owns, release_jobs
from finaldrive.service.db.levels import ALL_LEVELS, add_entries, merge_if_full
from finaldrive.service.db.models import Base, EvalStatus, Evaluation, Generation, Job, JobState
from finaldrive.service.db.summaries import add_explored, recount_explored

log = logging.getLogger(__name__)

#: Rows per ``IN (...)`` query, well under SQLite's variable limit.
_IN_CHUNK = 500


class LeaseLost(Exception):
    """The scheduler no longer owns the job: nothing was written."""


#: The columns of an evaluation the scheduler writes, in the order of a row tuple (units in the
#: names, docs/fields.md): the slot, the design, the result record (engine.VALUES; NULL where not
#: produced, fitness NULL when the simulation failed), then its status and cache bookkeeping.
ROW_COLUMNS: tuple[str, ...] = (
    "road_index", "step", "candidate", "a2_deg", "l2_m", "rws_m", *VALUES,
    "status", "reason", "cached", "cache_key", "cache_hash", "transient")
ROAD, STEP, CANDIDATE, A2, L2, RWS, FITNESS, STATUS, CACHED = (ROW_COLUMNS.index(c) for c in (
    "road_index", "step", "candidate", "a2_deg", "l2_m", "rws_m", "fitness_m", "status", "cached"))
_OK = EvalStatus.ok.value

#: A cache key's layout (finaldrive.service.jobs.cache makes the keys): hex digits of its context's digest (128
#: bits), then characters of base64 of its design (three float64 values, 24 bytes).
CONTEXT_DIGITS, DESIGN_CHARS = 32, 32
#: The finaliser of MurmurHash3's 64-bit hash (its multipliers), which mixes each of a key's words into the hash.
_MIX = (np.uint64(0xFF51AFD7ED558CCD), np.uint64(0xC4CEB9FE1A85EC53))


def key_hashes(keys: Sequence[str]) -> np.ndarray:
    """The indexed hash of each cache key (:data:`CONTEXT_DIGITS` hex digits of its context, then
    :data:`DESIGN_CHARS` characters of base64 of its design): its five 64-bit words mixed into 60 bits (a positive
    BIGINT on every backend), so that keys that share their context spread over the index. Not a
    secret: a collision only costs a comparison of the whole key."""
    contexts = bytes.fromhex("".join([key[:CONTEXT_DIGITS] for key in keys]))
    designs = base64.b64decode("".join([key[CONTEXT_DIGITS:] for key in keys]), validate=True)
    words = np.hstack([np.frombuffer(contexts, dtype=">u8").reshape(-1, 2),
                       np.frombuffer(designs, dtype=">u8").reshape(-1, 3)]).astype(np.uint64)
    mixed = np.zeros(len(words), dtype=np.uint64)
    with np.errstate(over="ignore"):  # multiplications modulo 2^64
        for word in words.T[::-1]:
            mixed ^= word
            for multiplier in _MIX:
                mixed ^= mixed >> np.uint64(33)
                mixed *= multiplier
            mixed ^= mixed >> np.uint64(33)
    return (mixed >> np.uint64(4)).astype(np.int64)


def key_hash(key: str) -> int:
    """:func:`key_hashes` of one key."""
    return int(key_hashes([key])[0])


#: An evaluation to store: values in :data:`ROW_COLUMNS` order.
Row = tuple[Any, ...]


def stored_fitness(session: Session, job_id: int, road_index: int, step: int,
                   candidates: Iterable[int]) -> dict[int, float]:
    """Candidates of (road, step) the job has stored already, with their fitness (NaN when failed)."""
    out: dict[int, float] = {}
    wanted = sorted({int(c) for c in candidates})
    for start in range(0, len(wanted), _IN_CHUNK):
        chunk = wanted[start:start + _IN_CHUNK]
        query = select(Evaluation.candidate, Evaluation.fitness_m).where(
            Evaluation.job_id == job_id, Evaluation.road_index == road_index, Evaluation.step == step,
            Evaluation.candidate.in_(chunk))
        for candidate, fitness in session.execute(query):
            out[int(candidate)] = math.nan if fitness is None else float(fitness)
    return out


def stored_slots(session: Session, job_id: int, step: int) -> set[tuple[int, int]]:
    """(road, candidate) of the job's stored evaluations at ``step``."""
    query = select(Evaluation.road_index, Evaluation.candidate).where(Evaluation.job_id == job_id,
                                                                      Evaluation.step == step)
    return {(int(r), int(c)) for r, c in session.execute(query)}


#: What a cache hit gives a new row: the stored result (the rest of a row is the new slot's own).
CACHED_COLUMNS = (*(name for name in VALUES if name != "wall_s"), "status", "reason")


def cached_evaluations(session: Session, keys: Iterable[str]) -> dict[str, dict[str, Any]]:
    """The values (:data:`CACHED_COLUMNS`) of the first stored evaluation for each cache key that
    has one (transient failures excluded).

    Looked up by the keys' hashes in every level of ``cache_index`` (finaldrive.service.db.levels), then
    matched on the whole key, with plain SQL through the driver (the scheduler asks for every
    generation it hands out; building a SQLAlchemy statement each time cost it ~2 ms of the GIL).

    On PostgreSQL each hash is looked up by itself (a LATERAL subquery, fenced by ``OFFSET 0``): the
    plain join's plan depended on the tables' statistics, which a new job's tables do not have until
    autovacuum's next ANALYZE, and without them PostgreSQL scanned both tables for every lookup
    (about 100 ms a lookup of 900 keys against 5 ms: 5 s of a paper-plan run's 10 s in the scheduler's loop)."""
    wanted = set(keys)
    hashes = sorted(set(key_hashes(list(wanted)).tolist()))
    connection = session.connection()
    m = marker(connection)
    values = ", ".join("e." + c for c in CACHED_COLUMNS)
    slot = ("JOIN evaluations e ON e.job_id = c.job_id AND e.road_index = c.road_index AND e.step = c.step "
            "AND e.candidate = c.candidate")
    out: dict[str, dict[str, Any]] = {}
    for start in range(0, len(hashes), _IN_CHUNK):
        chunk = hashes[start:start + _IN_CHUNK]
        if connection.dialect.name == "postgresql":
            sql = (f"SELECT e.cache_key, {values} FROM unnest({m}::bigint[]) AS h(cache_hash) CROSS JOIN LATERAL "
                   f"(SELECT * FROM cache_index WHERE level IN ({ALL_LEVELS}) AND cache_hash = h.cache_hash "
                   f"OFFSET 0) c {slot} WHERE e.transient = FALSE ORDER BY e.id")
            parameters: tuple[Any, ...] = (chunk,)
        else:
            sql = (f"SELECT e.cache_key, {values} FROM cache_index c {slot} WHERE c.level IN ({ALL_LEVELS}) "
                   f"AND c.cache_hash IN ({', '.join([m] * len(chunk))}) AND e.transient = FALSE ORDER BY e.id")
            parameters = tuple(chunk)
        for key, *found in connection.exec_driver_sql(sql, parameters):
            if key in wanted and key not in out:
                out[key] = dict(zip(CACHED_COLUMNS, found, strict=True))
    return out


def last_generations(session: Session, job_id: int) -> dict[int, Generation]:
    """The latest stored generation of each DE run of a job."""
    latest = (
        select(Generation.run, func.max(Generation.generation).label("g"))
        .where(Generation.job_id == job_id).group_by(Generation.run).subquery()
    )
    query = select(Generation).join(
        latest, (Generation.run == latest.c.run) & (Generation.generation == latest.c.g)
    ).where(Generation.job_id == job_id)
    return {g.run: g for g in session.scalars(query)}


def generation_records(session: Session, job_id: int, run: int | None = None) -> dict[int, list[dict[str, Any]]]:
    """Each DE run's history, one record per told generation in the outputs' names (generation
    counted from 0, the initial population, as the optimiser counts): run -> records in order."""
    g = Generation
    query = (select(g.run, g.generation, g.n_evals, g.n_failed, g.best_fitness_m, g.mean_fitness_m)
             .where(g.job_id == job_id).order_by(g.run, g.generation))
    if run is not None:
        query = query.where(g.run == run)
    out: dict[int, list[dict[str, Any]]] = {}
    for row in session.execute(query):
        out.setdefault(row.run, []).append({
            "generation": row.generation - 1, "n_evals": row.n_evals, "n_failed": row.n_failed,
            "best_fitness_m": row.best_fitness_m, "mean_fitness_m": row.mean_fitness_m})
    return out


def store_results(session: Session, scheduler_id: str, job_id: int, chunks: Iterable[Sequence[Row]],
                  generations: Sequence[dict[str, Any]]) -> int:
    """Insert evaluations (then told DE generations), their entries in the cache's and fitness's index
    tables (levels.add_entries), bump the job's counters, each road's best and its explored ranges
    (summaries.add_explored); returns how many evaluations were new.

    The evaluations come as ``chunks`` of rows, each stored (and its columns read) as it comes: the
    writer builds each chunk just before (``Writes.chunks``), so its values are still in the CPU's
    cache when the driver binds them (issue 27: 4.1 us a row built and inserted 1,000 at a time
    against 6.0 for 20,000 at once).

    Fenced: the counters' update, the transaction's last statement, matches only while the scheduler
    owns the running job; otherwise it raises :class:`LeaseLost` and the caller's rollback writes
    nothing. Last, so that the job's row is locked only from there to the commit: on PostgreSQL the
    heartbeat's lease renewal (in the scheduler's loop) waited for it behind the whole store, 0.19 s a
    time. Rows go to the driver's ``executemany`` as they are (no ORM, no per-row statement building);
    a slot stored already is skipped, never stored twice.
    """
    values = _Columns()
    now = db_now(session)
    m = marker(session.connection())
    before = session.connection().exec_driver_sql(f"SELECT MAX(id) FROM evaluations WHERE job_id = {m}",
                                                  (job_id,)).scalar() or 0
    inserted = _insert_many(session, "evaluations", ROW_COLUMNS, map(values.add, chunks),
                            ("job_id", "road_index", "step", "candidate"), fixed={"job_id": job_id, "created_at": now})
    values.close()
    merge_if_full(session, add_entries(session, job_id, before, own=session.get_bind().dialect.name == "postgresql"))
    if inserted != len(values):  # some slots were stored already: count the job's ranges afresh
        recount_explored(session, job_id)
    else:
        good = values.ok & np.isfinite(values.fitness)
        add_explored(session, job_id, *(column[good] for column in (values.road, values.a2_deg, values.l2_m,
                                                                    values.rws_m, values.fitness)))
    _update_best(session, job_id, values.best)
    if generations:
        columns = ("run", "generation", "population", "fitness_m", "state", "best_fitness_m", "mean_fitness_m",
                   "n_evals", "n_failed")
        _insert_many(session, "generations", columns, [[  # arrays made plain JSON here, in the writer
            (g["run"], g["generation"], *(json.dumps(plain_json(g[name])) for name in columns[2:5]),
             g["best_fitness_m"], g["mean_fitness_m"], g["n_evals"], g["n_failed"]) for g in generations]],
            ("job_id", "run", "generation"), fixed={"job_id": job_id, "created_at": now})
    ok, cached = int(values.ok.sum()), int(values.cached.sum())
    fenced = session.execute(
        update(Job).where(Job.id == job_id, Job.owner == scheduler_id, Job.state == JobState.running.value)
        .values(n_done=Job.n_done + ok, n_failed=Job.n_failed + len(values) - ok, n_cached=Job.n_cached + cached))
    if fenced.rowcount != 1:  # type: ignore[attr-defined]
        raise LeaseLost(job_id)
    if inserted != len(values):  # and its counters
        _recount(session, job_id)
    return inserted


def finish_if_complete(session: Session, scheduler_id: str, job_id: int, *, evaluations: int,
                       generations: int, planned: int) -> str:
    """Finish a job whose runs are done as ``succeeded``, if the store holds each of its
    ``evaluations`` and ``generations`` (counted here, in the finishing transaction); else give it
    back ``interrupted``, so that it resumes and recomputes what is missing. Returns "finished",
    "reopened", or "lost" (the job was no longer this scheduler's).

    ``total`` becomes ``evaluations`` only when the runs made fewer than the ``planned`` ones (a DE
    that stopped early), and only then: it is never fitted to what the store happens to hold.
    """
    if not owns(session, scheduler_id, job_id):
        return "lost"
    stored = session.scalar(select(func.count()).where(Evaluation.job_id == job_id)) or 0
    told = session.scalar(select(func.count()).where(Generation.job_id == job_id)) or 0
    if (stored, told) != (evaluations, generations):
        release_jobs(session, scheduler_id, [job_id])
        return "reopened"
    counted = session.scalar(select(Job.n_done + Job.n_failed).where(Job.id == job_id))
    if counted != stored:  # the counters change with each store, in its transaction: recounted only if off
        log.warning("job %s: its counters hold %s evaluations, the store %s: recounted", job_id, counted, stored)
        _recount(session, job_id)   # (a scan of the job's rows: 0.1 s a 10^5 evaluations, under the write lock)
    total = evaluations if evaluations < planned else None
    return "finished" if finish_job(session, scheduler_id, job_id, JobState.succeeded, total=total) else "lost"


#: Rows from which PostgreSQL gets them by ``COPY`` into a staging table rather than ``executemany``.
COPY_ROWS = 100


def _insert_many(session: Session, table: str, columns: Sequence[str], chunks: Iterable[Sequence[Row]],
                 unique: Sequence[str], fixed: dict[str, int | datetime]) -> int:
    """``INSERT ... ON CONFLICT (unique) DO NOTHING`` of the rows of ``chunks`` (rows of ``columns``, each
    chunk read once, in order), each with the ``fixed`` values (the same for every row: the job, the
    time); returns how many rows were inserted.

    Through the driver's executemany a chunk at a time, the fixed values written into the statement (a
    row repacked with them cost the writer about 7 % of its rows a second); on PostgreSQL, from
    :data:`COPY_ROWS` rows or a second chunk, ``COPY`` into a temporary table of the transaction, then one
    ``INSERT ... SELECT`` (COPY itself cannot skip a slot stored already)."""
    postgres = session.get_bind().dialect.name == "postgresql"
    chunks = (rows for rows in chunks if rows)
    first = next(chunks, None)
    if first is None:
        return 0
    if postgres:
        second = next(chunks, None)
        chunks = itertools.chain([] if second is None else [second], chunks)
        if second is not None or len(first) >= COPY_ROWS:
            return _copy_many(session, table, columns, itertools.chain([first], chunks), unique, fixed)
    m = marker(session.connection())
    flags = {at for at, name in enumerate(columns)  # PostgreSQL takes a bool for a boolean, not 0 or 1
             if postgres and isinstance(Base.metadata.tables[table].c[name].type, Boolean)}
    sql = (f"INSERT INTO {table} ({', '.join([*fixed, *columns])}) "
           f"VALUES ({', '.join([*map(_constant, fixed.values()), *[m] * len(columns)])}) "
           f"ON CONFLICT ({', '.join(unique)}) DO NOTHING")
    inserted = 0
    for rows in itertools.chain([first], chunks):
        if postgres:  # SQLite stores a NaN as NULL itself, and a flag's 0 or 1 as it is
            rows = [tuple(None if isinstance(v, float) and v != v else bool(v) if at in flags else v
                          for at, v in enumerate(row)) for row in rows]
        inserted += int(session.connection().exec_driver_sql(sql, list(rows)).rowcount)
    return inserted


def _constant(value: int | datetime) -> str:
    """A value in a statement's text: an integer, or a time as the store keeps it (SQLAlchemy's SQLite
    format; PostgreSQL reads it as a timestamp). Digits only, made here: nothing to quote or escape."""
    if isinstance(value, datetime):
        return f"'{value:%Y-%m-%d %H:%M:%S.%f}'"
    return str(int(value))


def _copy_many(session: Session, table: str, columns: Sequence[str], chunks: Iterable[Sequence[Row]],
               unique: Sequence[str], fixed: dict[str, int | datetime]) -> int:
    """PostgreSQL: the rows of ``chunks`` through ``COPY`` into ``_staging_<table>`` (temporary, emptied at commit), in
    the binary format with the staging table's column types (8 times the text format's rows a second for
    the evaluations' rows: no number formatted as text and parsed back); in text when a column is JSON,
    whose binary dumper would encode the stored JSON text again. A NaN goes in as PostgreSQL's NaN and
    becomes NULL in the ``INSERT ... SELECT`` (``NULLIF``: PostgreSQL's NaN equals NaN), not in Python: the
    rows' conversion value by value cost the writer more than the COPY (issue 27). The ``fixed`` values
    are parameters of the ``INSERT ... SELECT``."""
    names = ", ".join(columns)
    staging = f"_staging_{table}"
    connection = session.connection()
    connection.exec_driver_sql(f"CREATE TEMPORARY TABLE IF NOT EXISTS {staging} ON COMMIT DELETE ROWS AS "
                               f"SELECT {names} FROM {table} WITH NO DATA")
    oids: dict[str, int] = dict(connection.exec_driver_sql(
        f"SELECT attname, atttypid FROM pg_attribute WHERE attrelid = '{staging}'::regclass AND attnum > 0").all())
    types = [_TEXT_OID if oids[name] == _VARCHAR_OID else int(oids[name]) for name in columns]
    binary = not set(types) & _JSON_OIDS
    raw = connection.connection.driver_connection
    assert raw is not None
    with raw.cursor() as cursor:
        with cursor.copy(f"COPY {staging} ({names}) FROM STDIN" + (" (FORMAT BINARY)" if binary else "")) as copy:
            if binary:
                copy.set_types(types)
            for rows in chunks:
                for row in rows:
                    copy.write_row(row)
        selected = [f"NULLIF({name}, 'NaN')" if oid in _FLOAT_OIDS else name for name, oid in zip(columns, types,
                                                                                                   strict=True)]
        cursor.execute(f"INSERT INTO {table} ({', '.join([*fixed, *columns])}) SELECT "
                       f"{', '.join([*['%s'] * len(fixed), *selected])} FROM {staging} "
                       f"ON CONFLICT ({', '.join(unique)}) DO NOTHING", tuple(fixed.values()))
        inserted = cursor.rowcount
        cursor.execute(f"DELETE FROM {staging}")  # a second insert in the transaction starts empty (no new file)
    return int(inserted)


#: PostgreSQL's json and jsonb type oids; real and double precision's.
_JSON_OIDS, _FLOAT_OIDS = {114, 3802}, {700, 701}
#: varchar goes by text's binary dumper (the same bytes; psycopg 3.1 has no binary dumper for varchar).
_VARCHAR_OID, _TEXT_OID = 1043, 25


def _recount(session: Session, job_id: int) -> None:
    def count(*where: Any) -> Any:
        return select(func.count()).where(Evaluation.job_id == job_id, *where).scalar_subquery()

    session.execute(update(Job).where(Job.id == job_id).values(
        n_done=count(Evaluation.status == EvalStatus.ok.value),
        n_failed=count(Evaluation.status != EvalStatus.ok.value), n_cached=count(Evaluation.cached.is_(True))))


class _Columns:
    """The columns of the stored rows that the counters, the explored ranges and the best need, as
    arrays (fitness NaN where NULL), read a chunk at a time (:meth:`add`, while its rows are in the
    CPU's cache) and joined by :meth:`close`; ``best``: each road's best row (the first of equals)."""

    _NAMES = ("ok", "cached", "road", "a2_deg", "l2_m", "rws_m", "fitness")

    def __init__(self) -> None:
        self._parts: list[tuple[np.ndarray, ...]] = []
        self.best: dict[int, Row] = {}
        self.ok, self.cached, self.road = np.empty(0, bool), np.empty(0, bool), np.empty(0, np.int64)
        self.a2_deg = self.l2_m = self.rws_m = self.fitness = np.empty(0)

    def add(self, rows: Sequence[Row]) -> Sequence[Row]:
        """Read the columns of ``rows``; returns them."""
        n = len(rows)

        def column(at: int, dtype: Any) -> np.ndarray:
            return np.fromiter((row[at] for row in rows), dtype=dtype, count=n)

        ok = np.fromiter((row[STATUS] == _OK for row in rows), dtype=bool, count=n)
        road = column(ROAD, np.int64)
        fitness = np.fromiter((math.nan if row[FITNESS] is None else row[FITNESS] for row in rows), dtype=float,
                              count=n)
        self._parts.append((ok, np.fromiter((bool(row[CACHED]) for row in rows), dtype=bool, count=n), road,
                            column(A2, float), column(L2, float), column(RWS, float), fitness))
        good = ok & np.isfinite(fitness)
        for at in np.unique(road[good]).tolist():
            candidates = np.flatnonzero(good & (road == at))
            row = rows[int(candidates[np.argmax(fitness[candidates])])]
            if at not in self.best or row[FITNESS] > self.best[at][FITNESS]:
                self.best[at] = row
        return rows

    def close(self) -> None:
        """Join the chunks' columns."""
        if not self._parts:
            return
        for name, parts in zip(self._NAMES, zip(*self._parts, strict=True), strict=True):
            setattr(self, name, np.concatenate(parts))
        self._parts = []

    def __len__(self) -> int:
        return len(self.ok)


def _update_best(session: Session, job_id: int, best: dict[int, Row]) -> None:
    """Each road's best evaluation, if the road's ``best`` stored row beats it (plain SQL through the
    driver: the writer runs this with every batch of rows it stores)."""
    if not best:
        return
    m = marker(session.connection())
    connection = session.connection()
    stored: dict[int, float | None] = dict(connection.exec_driver_sql(
        f"SELECT road_index, best_fitness_m FROM job_roads WHERE job_id = {m}", (job_id,)).all())
    better = [row for road, row in sorted(best.items()) if road in stored and _better(row[FITNESS], stored[road])]
    if better:  # compared again in the statement: another writer of the job may have stored a better one since
        connection.exec_driver_sql(
            f"UPDATE job_roads SET best_fitness_m = {m}, best_evaluation_id = (SELECT id FROM evaluations "
            f"WHERE job_id = {m} AND road_index = {m} AND step = {m} AND candidate = {m}) "
            f"WHERE job_id = {m} AND road_index = {m} AND (best_fitness_m IS NULL OR best_fitness_m < {m})",
            [(row[FITNESS], job_id, row[ROAD], row[STEP], row[CANDIDATE], job_id, row[ROAD], row[FITNESS])
             for row in better])


def _better(a: float | None, b: float | None) -> bool:
    return a is not None and math.isfinite(a) and (b is None or a > b)

