"""The store's two lookups by a key in random order, kept as index tables of a few levels.

The result cache looks evaluations up by their key's hash, and /best by a road's fitness. Both
keys arrive in random order, so an index on ``evaluations`` itself had every stored batch dirty
pages all over it: on a store of 2.24 M evaluations the writer fell from ~70,000 rows/s to
~22,000 (docs/performance.md, bench/bench_commit.py --grow). Each lookup is instead a table of
entries (its key and the evaluation's slot), in :data:`LEVELS` levels, as a log-structured merge:

- **level 0** takes each stored batch's entries;
- level ``i`` holds about :data:`LEVEL0_ROWS` x :data:`GROWTH` ** ``i`` entries; the last has no limit;
- when a level is full the writer moves one chunk of it (:data:`MOVE_ROWS` entries and its excess,
  the next keys after the last chunk's, round the key range) to the level above. Each move is one
  sorted statement, so a page above is written once for many entries; a chunk's keys span a share of
  its level's key range, so a move writes about as many pages of the level above whatever the levels'
  sizes, and a store's transaction holds the write lock for at most a chunk a level, never for a
  whole level: moving whole levels held SQLite's lock for 24 s at 18 M evaluations stored, growing
  with the store; level 0 of 2^18 entries moved whole held it up to 2 s at 10^7, chunks of 2^16
  under 1 s.

Level 0 is counted, once this process's own count says it is full (its size at the last check plus
what the process added since); the sizes of the others are kept in ``index_levels``, changed by
each move in its transaction. A lookup reads every level (the level is the first column of each
table's key: a seek each). An entry is written in the transaction that stores its evaluation and
moved in one transaction, so a lookup never misses or doubles one. ``fitness_index`` holds the
successful evaluations with a fitness. Entries name their evaluation by its slot (job, road, step,
candidate): a batch's ids are not known to the driver's ``executemany``.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import Connection
from sqlalchemy.orm import Session

from finaldrive.service.db.engine import marker

#: Entries level 0 holds before the writer moves a chunk of it to level 1; level i holds GROWTH ** i times as
#: many. Larger than a move: each entry then passes through fewer levels (a store of 10^6 evaluations
#: fills levels 0 and 1 only).
LEVEL0_ROWS = 1 << 18
#: Entries a move takes from a level at its size (from one over it: its excess as well).
MOVE_ROWS = 1 << 16
GROWTH = 8
#: Levels of each table. The last (from 3.8 x 10^7 entries on) has no limit: a chunk from level 3 writes a
#: slice of it that grows with it (a chunk times its size over level 3's), a few chunks up to 10^8 evaluations.
LEVELS = 5
#: Every level, for ``level IN (...)``.
ALL_LEVELS = ", ".join(str(level) for level in range(LEVELS))
_SLOT = "job_id, road_index, step, candidate"
#: Each index table: its key's columns (after the level), and which evaluations it holds.
TABLES = {
    "cache_index": ("cache_hash", "TRUE"),
    "fitness_index": ("job_id, road_index, fitness_m", "status = 'ok' AND fitness_m IS NOT NULL"),
}


def _columns(table: str) -> str:
    key = TABLES[table][0]
    return key + "".join(f", {c}" for c in _SLOT.split(", ") if c not in key.split(", "))


def add_entries(session: Session, job_id: int, after_id: int = 0, *, own: bool = False) -> int:
    """Level-0 entries for the job's evaluations with an id above ``after_id``: those stored in this
    transaction (or, from 0, all of a job stored without them). ``own``: only the rows this transaction
    inserted (PostgreSQL's ``xmin``), as a scheduler's parallel writers store one job's evaluations at
    once (finaldrive.service.jobs.writer_pool); SQLite writes one transaction at a time. Returns how many
    evaluations got a cache entry."""
    connection = session.connection()
    m = marker(connection)
    mine = " AND xmin = pg_current_xact_id()::xid" if own else ""
    added = [connection.exec_driver_sql(f"INSERT INTO {table} (level, {_columns(table)}) SELECT 0, {_columns(table)} "
                                        f"FROM evaluations WHERE job_id = {m} AND id > {m}{mine} AND {where}",
                                        (job_id, after_id)).rowcount for table, (_, where) in TABLES.items()]
    return int(added[0])   # cache_index: every evaluation


_added: dict[str, int] = {}    # database -> entries this process added since its last check
_level0: dict[str, int] = {}   # database -> level 0's entries at this process's last check, after its moves
#: (database, table, level) -> the key of the last entry this process moved from that level (None: start
#: from the lowest key); lost with the process, which then starts again from the lowest.
_cursors: dict[tuple[str, str, int], tuple[Any, ...] | None] = {}


def merge_if_full(session: Session, added: int) -> None:
    """After ``added`` entries, once level 0 is full by this process's count (its size at the last check
    plus what this process added since: counting it with every store cost the writer more than the
    store): move one chunk of each level that holds its size (:data:`LEVEL0_ROWS` x :data:`GROWTH` **
    level) or more to the level above, of :data:`MOVE_ROWS` entries and the level's excess over its
    size (a level is left :data:`MOVE_ROWS` below its size, however large the stores). Another writer's
    entries are not in this count: they make level 0 fuller than it says until the next check, whose
    chunk takes them as excess.

    SQLite: the writer holds the database's write lock, so nothing is added between the copy and the
    delete. PostgreSQL: one statement moves exactly the rows it deletes (an entry another writer adds
    or moves meanwhile stays where it is), and ``index_levels`` counts what was moved."""
    connection = session.connection()
    store = str(connection.engine.url)
    since = _added.get(store, 0) + added
    if _level0.get(store, LEVEL0_ROWS) + since < LEVEL0_ROWS:
        _added[store] = since
        return
    _added[store] = 0
    m = marker(connection)
    level0 = 0
    for table in TABLES:
        sizes = dict(connection.exec_driver_sql(
            f"SELECT level, entries FROM index_levels WHERE index_table = {m}", (table,)).all())
        sizes[0] = connection.exec_driver_sql(f"SELECT COUNT(*) FROM {table} WHERE level = 0").scalar() or 0
        for level in range(LEVELS - 1):
            excess = sizes.get(level, 0) - LEVEL0_ROWS * GROWTH ** level
            if excess < 0:
                continue
            moved = _move(connection, table, level, *_next_chunk(connection, table, level, MOVE_ROWS + excess, store))
            sizes[level] -= moved
            sizes[level + 1] = sizes.get(level + 1, 0) + moved
            connection.exec_driver_sql(
                f"UPDATE index_levels SET entries = entries + {m} WHERE index_table = {m} AND level = {m}",
                [(sign * moved, table, at) for sign, at in ((-1, level), (1, level + 1)) if at > 0])
        level0 = max(level0, sizes[0])
    _level0[store] = level0


def _next_chunk(connection: Connection, table: str, level: int, chunk: int,
                store: str) -> tuple[str, tuple[Any, ...]]:
    """The condition (after ``level = ?``) and parameters of the next ``chunk`` keys of ``level`` after
    this process's last (the rest of the level if fewer remain: the next chunk starts from the lowest)."""
    key, m = _columns(table), marker(connection)
    row = f"({', '.join([m] * len(key.split(', ')))})"
    last = _cursors.get((store, table, level))
    if last and connection.exec_driver_sql(f"SELECT 1 FROM {table} WHERE level = {m} AND ({key}) > {row} LIMIT 1",
                                           (level, *last)).first() is None:
        last = None  # the last chunk ended at the level's last key
    where, values = (f" AND ({key}) > {row}", tuple(last)) if last else ("", ())
    bound = connection.exec_driver_sql(f"SELECT {key} FROM {table} WHERE level = {m}{where} ORDER BY {key} "
                                       f"LIMIT 1 OFFSET {chunk - 1}", (level, *values)).first()
    _cursors[(store, table, level)] = None if bound is None else tuple(bound)
    return (where, values) if bound is None else (f"{where} AND ({key}) <= {row}", (*values, *bound))


def _move(connection: Connection, table: str, level: int, where: str, values: tuple[Any, ...]) -> int:
    """Move the entries of ``level`` that meet ``where`` to the level above, in key order; returns how many."""
    columns, m = _columns(table), marker(connection)
    if connection.dialect.name == "postgresql":
        return int(connection.exec_driver_sql(
            f"WITH moved AS (DELETE FROM {table} WHERE level = {m}{where} RETURNING {columns}) "
            f"INSERT INTO {table} (level, {columns}) SELECT {level + 1}, {columns} FROM moved "
            f"ORDER BY {columns}", (level, *values)).rowcount)
    connection.exec_driver_sql(f"INSERT INTO {table} (level, {columns}) SELECT {level + 1}, {columns} "
                               f"FROM {table} WHERE level = {m}{where} ORDER BY {columns}", (level, *values))
    return int(connection.exec_driver_sql(f"DELETE FROM {table} WHERE level = {m}{where}",
                                          (level, *values)).rowcount)
