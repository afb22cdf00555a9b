"""The store's two lookups by a key in random order, kept as index tables of two levels.

The result cache looks evaluations up by their key's hash, and /best by a road's fitness. Both
keys arrive in random order, so an index on ``evaluations`` itself had every stored batch dirty
pages all over it: on a store of 1.12 M evaluations the writer fell from ~110,000 rows/s to
~30,000 (docs/performance.md, bench/bench_commit.py --grow). Each lookup is instead a table of
entries (its key and the evaluation's slot), in two levels:

- **level 0** takes each stored batch's entries; it is small (at most :data:`LEVEL0_ROWS`), so a
  batch dirties few pages;
- **level 1** holds the rest. When level 0 is full, the writer moves it to level 1 in one sorted
  statement (a log-structured merge, of two levels): each page of level 1 is then written once
  for up to :data:`LEVEL0_ROWS` entries, not once every few.

A lookup reads both levels (the level is the first column of each table's key: two seeks). An
entry is written in the transaction that stores its evaluation, and moved in one transaction, so
a lookup never misses or doubles one. ``fitness_index`` holds the successful evaluations with a
fitness. Entries name their evaluation by its slot (job, road, step, candidate): a batch's ids are
not known to the driver's ``executemany``.
"""

from __future__ import annotations

from sqlalchemy import Connection
from sqlalchemy.orm import Session

#: Entries level 0 holds before the writer moves it to level 1.
LEVEL0_ROWS = 1 << 16
_SLOT = "job_id, road_index, step, candidate"
#: Each index table: its key's columns (after the level), and which evaluations it holds.
TABLES = {
    "cache_index": ("cache_hash", "TRUE"),
    "fitness_index": ("job_id, road_index, fitness_m", "status = 'ok' AND fitness_m IS NOT NULL"),
}


def _columns(table: str) -> str:
    key = TABLES[table][0]
    return key + "".join(f", {c}" for c in _SLOT.split(", ") if c not in key.split(", "))


def add_entries(session: Session, job_id: int, after_id: int = 0) -> None:
    """Level-0 entries for the job's evaluations with an id above ``after_id``: those stored in this
    transaction by the one writer that owns the job (or, from 0, all of a job stored without them)."""
    connection = session.connection()
    m = _marker(connection)
    for table, (_, where) in TABLES.items():
        columns = _columns(table)
        connection.exec_driver_sql(f"INSERT INTO {table} (level, {columns}) SELECT 0, {columns} FROM evaluations "
                                   f"WHERE job_id = {m} AND id > {m} AND {where}", (job_id, after_id))


def merge_if_full(session: Session, rows: int | None = None) -> bool:
    """Move each table's level 0 to level 1 if it holds ``rows`` (:data:`LEVEL0_ROWS`) entries or more;
    returns whether any moved.

    SQLite: the writer holds the database's write lock, so nothing is added between the copy and the
    delete. PostgreSQL: one statement moves exactly the rows it deletes (an entry another writer adds
    meanwhile stays at level 0)."""
    rows = LEVEL0_ROWS if rows is None else rows
    connection = session.connection()
    moved = False
    for table in TABLES:
        count = connection.exec_driver_sql(
            f"SELECT COUNT(*) FROM (SELECT 1 FROM {table} WHERE level = 0 LIMIT {int(rows)}) AS t").scalar()
        if (count or 0) < rows:
            continue
        columns = _columns(table)
        if connection.dialect.name == "postgresql":
            connection.exec_driver_sql(
                f"WITH moved AS (DELETE FROM {table} WHERE level = 0 RETURNING {columns}) "
                f"INSERT INTO {table} (level, {columns}) SELECT 1, {columns} FROM moved ORDER BY {columns}")
        else:
            connection.exec_driver_sql(f"INSERT INTO {table} (level, {columns}) SELECT 1, {columns} FROM {table} "
                                       f"WHERE level = 0 ORDER BY {columns}")
            connection.exec_driver_sql(f"DELETE FROM {table} WHERE level = 0")
        moved = True
    return moved


def _marker(connection: Connection) -> str:
    return "?" if connection.dialect.paramstyle == "qmark" else "%s"
