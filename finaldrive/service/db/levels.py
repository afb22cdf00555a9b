"""The store's two lookups by a key in random order, kept as index tables of a few levels.

The result cache looks evaluations up by their key's hash, and /best by a road's fitness. Both
keys arrive in random order, so an index on ``evaluations`` itself had every stored batch dirty
pages all over it: on a store of 2.24 M evaluations the writer fell from ~70,000 rows/s to
~22,000 (docs/performance.md, bench/bench_commit.py --grow). Each lookup is instead a table of
entries (its key and the evaluation's slot), in :data:`LEVELS` levels, as a log-structured merge:

- **level 0** takes each stored batch's entries; it is small (at most :data:`LEVEL0_ROWS`), so a
  batch dirties few pages;
- when level ``i`` is full (:data:`LEVEL0_ROWS` x :data:`GROWTH` ** ``i`` entries), the writer moves
  it to level ``i + 1`` in one sorted statement, so each page there is written once for many
  entries; the last level has no limit.

A lookup reads every level (the level is the first column of each table's key: a seek each). An
entry is written in the transaction that stores its evaluation, and moved in one transaction, so
a lookup never misses or doubles one. ``fitness_index`` holds the successful evaluations with a
fitness. Entries name their evaluation by its slot (job, road, step, candidate): a batch's ids are
not known to the driver's ``executemany``.
"""

from __future__ import annotations

from sqlalchemy.orm import Session

from finaldrive.service.db.engine import marker

#: Entries level 0 holds before the writer moves it to level 1; level i holds GROWTH ** i times as many.
LEVEL0_ROWS = 1 << 16
GROWTH = 8
#: Levels of each table: the last (3.7 x 10^7 entries and more) holds what the others moved there.
LEVELS = 4
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


def add_entries(session: Session, job_id: int, after_id: int = 0) -> int:
    """Level-0 entries for the job's evaluations with an id above ``after_id``: those stored in this
    transaction by the one writer that owns the job (or, from 0, all of a job stored without them).
    Returns how many evaluations got a cache entry."""
    connection = session.connection()
    m = marker(connection)
    added = [connection.exec_driver_sql(f"INSERT INTO {table} (level, {_columns(table)}) SELECT 0, {_columns(table)} "
                                        f"FROM evaluations WHERE job_id = {m} AND id > {m} AND {where}",
                                        (job_id, after_id)).rowcount for table, (_, where) in TABLES.items()]
    return int(added[0])   # cache_index: every evaluation


#: Level 0 is counted once this process has added this share of :data:`LEVEL0_ROWS` entries since it
#: last counted it (a count of up to 65,536 entries with every small store cost the writer more than the
#: store); it may then hold a few times that share more than its limit.
CHECK_SHARE = 1 / 16
_unchecked: dict[str, int] = {}   # database -> entries this process added since it last counted level 0


def merge_if_full(session: Session, added: int, rows: int | None = None) -> None:
    """After ``added`` entries: move each table's level 0 to level 1 if it holds ``rows``
    (:data:`LEVEL0_ROWS`) entries or more, then level 1 to 2 if that filled it (``rows`` x
    :data:`GROWTH`), and so on. Counted only every :data:`CHECK_SHARE` of ``rows`` added.

    SQLite: the writer holds the database's write lock, so nothing is added between the copy and the
    delete. PostgreSQL: one statement moves exactly the rows it deletes (an entry another writer adds
    meanwhile stays where it is)."""
    rows = LEVEL0_ROWS if rows is None else rows
    connection = session.connection()
    store = str(connection.engine.url)
    _unchecked[store] = _unchecked.get(store, 0) + added
    if _unchecked[store] < rows * CHECK_SHARE:
        return
    _unchecked[store] = 0
    for table in TABLES:
        columns = _columns(table)
        for level in range(LEVELS - 1):
            full = rows * GROWTH ** level
            count = connection.exec_driver_sql(
                f"SELECT COUNT(*) FROM (SELECT 1 FROM {table} WHERE level = {level} LIMIT {full}) AS t").scalar()
            if (count or 0) < full:
                break
            if connection.dialect.name == "postgresql":
                connection.exec_driver_sql(
                    f"WITH moved AS (DELETE FROM {table} WHERE level = {level} RETURNING {columns}) "
                    f"INSERT INTO {table} (level, {columns}) SELECT {level + 1}, {columns} FROM moved "
                    f"ORDER BY {columns}")
            else:
                connection.exec_driver_sql(f"INSERT INTO {table} (level, {columns}) SELECT {level + 1}, {columns} "
                                           f"FROM {table} WHERE level = {level} ORDER BY {columns}")
                connection.exec_driver_sql(f"DELETE FROM {table} WHERE level = {level}")
