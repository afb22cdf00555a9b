"""Database engine and sessions.

SQLite (the default) gets, on every new connection, ``busy_timeout`` (set first),
``journal_mode=WAL``, ``synchronous=FULL`` and ``foreign_keys=ON``. pysqlite's implicit
transactions are replaced by explicit ``BEGIN`` (SQLAlchemy's SQLite recipe), and write
transactions start with ``BEGIN IMMEDIATE`` so a reader never has to upgrade its lock.
Any other SQLAlchemy URL is used as is.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

BUSY_TIMEOUT_MS = 10_000
#: anyio's default worker threads (40) run the sync routes; plus the runner and SSE polls.
POOL_SIZE = 40
_WRITE = {"sqlite_begin": "IMMEDIATE"}


def display_url(url: str) -> str:
    """``url`` with any password masked, for logs and messages."""
    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # not a URL SQLAlchemy can parse: show nothing of it that could be secret
        return "<database URL>"


class Database:
    """An engine plus read and write session factories."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.engine = make_engine(url)
        self._read = sessionmaker(self.engine, expire_on_commit=False)
        self._write = sessionmaker(self.engine.execution_options(**_WRITE), expire_on_commit=False)

    @contextmanager
    def read(self) -> Iterator[Session]:
        """A session for queries; its transaction is rolled back at the end."""
        with self._read() as session:
            yield session

    @contextmanager
    def write(self) -> Iterator[Session]:
        """One write transaction: committed on success, rolled back on any exception."""
        with self._write() as session, session.begin():
            yield session

    def dispose(self) -> None:
        self.engine.dispose()


def make_engine(url: str, **kwargs: Any) -> Engine:
    """``create_engine`` with the SQLite connection set-up described in the module docstring."""
    if make_url(url).get_backend_name() != "sqlite":
        return create_engine(url, **kwargs)
    memory = make_url(url).database in (None, "", ":memory:")
    if not memory:  # one pooled connection per API worker thread: no reconnect churn under load
        kwargs = {"pool_size": POOL_SIZE, "max_overflow": POOL_SIZE // 2, **kwargs}
    engine = create_engine(url, **kwargs)

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn: Any, _record: Any) -> None:
        dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (see _on_begin)
        cur = dbapi_conn.cursor()
        try:
            cur.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
            if not memory:
                mode = cur.execute("PRAGMA journal_mode = WAL").fetchone()[0]
                if str(mode).lower() != "wal":
                    raise RuntimeError(f"SQLite refused WAL mode (journal_mode is {mode!r})")
            cur.execute("PRAGMA synchronous = FULL")
            cur.execute("PRAGMA foreign_keys = ON")
        finally:
            cur.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn: Any) -> None:
        conn.exec_driver_sql(f"BEGIN {conn.get_execution_options().get('sqlite_begin', 'DEFERRED')}")

    return engine
