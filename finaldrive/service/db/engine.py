"""Database engine and sessions.

SQLite (the default) gets, on every new connection, ``journal_mode=WAL``, ``synchronous=FULL``
and ``foreign_keys=ON``; a new database file gets pages of :data:`PAGE_SIZE` bytes. pysqlite's
implicit transactions are replaced by explicit ``BEGIN`` (SQLAlchemy's SQLite recipe), each
preceded by the transaction's ``busy_timeout``, and write transactions start with
``BEGIN IMMEDIATE`` so a reader never has to upgrade its lock.
PostgreSQL connections time out after 5 s and a write transaction waits for locks at most its
timeout (``lock_timeout``). Any other SQLAlchemy URL is used as is.

Every commit is durable on every store, results included: a commit that returned survives the
database's crash (PostgreSQL's default ``synchronous_commit=on``; SQLite ``synchronous=FULL``).
An asynchronous commit once lost acknowledged results whole steps at a time when PostgreSQL was
restarted; a scheduler's results are committed in batches, so the flush costs little.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from sqlalchemy import Connection, Engine, create_engine, event, text
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session

#: How long a transaction waits for a lock before it fails (a failed write is retried or answered 503).
LOCK_TIMEOUT_S = 10.0
#: anyio's default worker threads (40) run the sync routes; plus the SSE polls.
POOL_SIZE = 40
#: The page cache [KiB] of a SQLite connection that stores results (the scheduler's writer; the others
#: keep SQLite's 2 MiB), filled only as pages are read. Storing evaluations touches the indexes' pages
#: at random; 16 MiB stores 1.07x as many evaluations a second in 50,000-row transactions
#: (``bench/bench_commit.py --cache-kib``, issue 27, docs/performance-log.md).
WRITER_CACHE_KIB = 16384
#: The page size [bytes] of a SQLite database this service creates (SQLite's default is 4,096; a file
#: keeps the size it was made with). Storing results writes each transaction's pages to the log and
#: moves index entries between levels page by page: with 16 KiB pages the writer used 6 % less CPU on the
#: big plan of bench/bench_scheduler.py (efficiency 0.89-0.90 against 0.87), and /best on a million
#: evaluations took 36 ms against 31 (bench/bench_best.py); 32 KiB stored no faster and read slower
#: (52 ms). Issue 27, docs/performance-log.md.
PAGE_SIZE = 16384
#: Seconds to open a connection to a database server before giving up.
CONNECT_TIMEOUT_S = 5
#: Each PostgreSQL session's settings. No JIT: once a store's tables hold ~10^5 rows the planner's cost of
#: the result cache's lookup passes ``jit_above_cost`` and each lookup of ~900 keys was compiled first,
#: 0.1-0.5 s of the server's CPU for a query that runs in ~10 ms (docs/performance-log.md, 2026-12-08).
PG_OPTIONS = "-c jit=off"


def display_url(url: str) -> str:
    """``url`` with any password masked, for logs and messages."""
    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # not a URL SQLAlchemy can parse: show nothing of it that could be secret
        return "<database URL>"


class Database:
    """An engine plus read and write session factories."""

    def __init__(self, url: str, *, lock_timeout_s: float = LOCK_TIMEOUT_S, cache_kib: int | None = None) -> None:
        """``cache_kib``: each SQLite connection's page cache (None: SQLite's default)."""
        self.url = url
        self.lock_timeout_s = lock_timeout_s
        self.engine = make_engine(url, cache_kib=cache_kib)
        self._postgres = self.engine.dialect.name == "postgresql"
        self._binds: dict[tuple[bool, float], Engine] = {}

    def _bind(self, write: bool, timeout_s: float) -> Engine:
        """The engine with a transaction's options, made once (a new one cost each transaction ~40 us)."""
        bind = self._binds.get((write, timeout_s))
        if bind is None:
            options = {"sqlite_begin": "IMMEDIATE"} if write else {}
            bind = self._binds[(write, timeout_s)] = self.engine.execution_options(lock_timeout_s=timeout_s, **options)
        return bind

    @contextmanager
    def read(self) -> Iterator[Session]:
        """A session for queries; its transaction is rolled back at the end."""
        with Session(self._bind(False, self.lock_timeout_s), expire_on_commit=False) as session:
            yield session

    @contextmanager
    def write(self, *, timeout_s: float | None = None) -> Iterator[Session]:
        """One write transaction: committed on success, rolled back on any exception; it waits for
        locks at most ``timeout_s`` (default: the database's lock timeout)."""
        timeout = self.lock_timeout_s if timeout_s is None else timeout_s
        with Session(self._bind(True, timeout), expire_on_commit=False) as session, session.begin():
            if self._postgres:
                session.execute(text(f"SET LOCAL lock_timeout = '{int(timeout * 1000)}ms'"))
            yield session

    def dispose(self) -> None:
        self.engine.dispose()


def in_memory(url: str) -> bool:
    """Whether ``url`` is an in-memory SQLite database (seen by this process alone)."""
    parsed = make_url(url)
    return parsed.get_backend_name() == "sqlite" and parsed.database in (None, "", ":memory:")


def _journal_mode_wal(cur: Any) -> Any:
    """``PRAGMA journal_mode = WAL``, retried for up to LOCK_TIMEOUT_S: processes opening a new file
    together deadlock in the switch, which SQLite reports at once ("database is locked"), busy
    timeout or not."""
    deadline = time.monotonic() + LOCK_TIMEOUT_S
    while True:
        try:
            return cur.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() >= deadline:
                raise
            time.sleep(0.01)


def marker(connection: Connection) -> str:
    """The driver's placeholder for a bound value in plain SQL: ``?`` (sqlite3) or ``%s`` (psycopg)."""
    return "?" if connection.dialect.paramstyle == "qmark" else "%s"


def make_engine(url: str, *, cache_kib: int | None = None, **kwargs: Any) -> Engine:
    """``create_engine`` with the SQLite connection set-up described in the module docstring
    (``cache_kib``: the page cache of each SQLite connection)."""
    backend = make_url(url).get_backend_name()
    if backend == "postgresql":
        kwargs = {"pool_pre_ping": True, "connect_args": {"connect_timeout": CONNECT_TIMEOUT_S, "options": PG_OPTIONS},
                  **kwargs}
    if backend != "sqlite":
        return create_engine(url, **kwargs)
    memory = in_memory(url)
    if not memory:  # one pooled connection per API worker thread: no reconnect churn under load
        kwargs = {"pool_size": POOL_SIZE, "max_overflow": POOL_SIZE // 2, **kwargs}
    engine = create_engine(url, **kwargs)

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn: Any, _record: Any) -> None:
        dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (see _on_begin)
        cur = dbapi_conn.cursor()
        try:
            cur.execute(f"PRAGMA page_size = {PAGE_SIZE}")  # before the file's first page; else nothing changes
            if not memory:
                mode = _journal_mode_wal(cur)
                if str(mode).lower() != "wal":
                    raise RuntimeError(f"SQLite refused WAL mode (journal_mode is {mode!r})")
            cur.execute("PRAGMA synchronous = FULL")
            if cache_kib is not None:
                cur.execute(f"PRAGMA cache_size = -{int(cache_kib)}")
            cur.execute("PRAGMA foreign_keys = ON")
        finally:
            cur.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn: Any) -> None:
        options = conn.get_execution_options()
        conn.exec_driver_sql(f"PRAGMA busy_timeout = {int(1000 * options.get('lock_timeout_s', LOCK_TIMEOUT_S))}")
        conn.exec_driver_sql(f"BEGIN {options.get('sqlite_begin', 'DEFERRED')}")

    return engine
