"""Schema migrations: run them, and check a database is at the code's revision.

The Alembic scripts live in the ``migrations`` package, so they ship with finaldrive
(the pattern of Optuna's ``_create_alembic_config``).

Migrations of one database are serialised (:func:`migration_lock`): on PostgreSQL by a
session-level advisory lock, on a SQLite file by ``flock`` on ``<file>.migrate.lock``. Processes
started together on an empty store (two ``serve``, a ``scheduler``) then create the schema once:
the others wait for the lock and find it at head.
"""

from __future__ import annotations

import fcntl
import logging
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Engine, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.pool import NullPool

from finaldrive.service.db.engine import display_url, in_memory, make_engine

log = logging.getLogger(__name__)

#: How long a process waits for another's migration of the same database before giving up [s].
MIGRATION_WAIT_S = 60.0
#: The PostgreSQL advisory-lock key of migrations ("finaldrv"; advisory locks are per database).
ADVISORY_LOCK_KEY = 0x66696E616C647276


class SchemaMismatchError(RuntimeError):
    """The database is not at the revision this version of finaldrive expects."""


class MigrationBusyError(SchemaMismatchError):
    """Another process held the migration lock for longer than the wait allowed."""


def alembic_config(url: str) -> Config:
    """An Alembic config pointing at the packaged scripts and at ``url``."""
    here = Path(str(resources.files("finaldrive.migrations")))  # named, not imported: migrations import the store
    config = Config(str(here / "alembic.ini"))
    config.set_main_option("script_location", str(here))
    config.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return config


def head_revision() -> str:
    head = ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head()
    if head is None:
        raise RuntimeError("the migrations package has no revision")
    return head


def upgrade(url: str, revision: str = "head", *, wait_s: float = MIGRATION_WAIT_S) -> None:
    """Bring the database at ``url`` to ``revision`` (``finaldrive db upgrade``), under the
    migration lock; Alembic reads the revision once it holds it, so a migration another process
    just ran is not run again."""
    with migration_lock(url, wait_s):
        command.upgrade(alembic_config(url), revision)


@contextmanager
def migration_lock(url: str, wait_s: float = MIGRATION_WAIT_S) -> Iterator[None]:
    """Hold the lock that serialises migrations of the database at ``url``, waiting for it at most
    ``wait_s`` (then :class:`MigrationBusyError`). An in-memory SQLite database, seen by this process
    alone, and other stores take no lock. A process that dies releases the lock with it."""
    parsed = make_url(url)
    backend = parsed.get_backend_name()
    if backend == "postgresql":
        engine = make_engine(url, poolclass=NullPool)
        try:
            with engine.connect().execution_options(isolation_level="AUTOCOMMIT") as conn:
                _wait_for(lambda: _try_advisory_lock(conn), url, wait_s)
                yield  # closing the session (above) releases its lock
        finally:
            engine.dispose()
    elif backend == "sqlite" and not in_memory(url):
        fd = os.open(f"{parsed.database}.migrate.lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            _wait_for(lambda: _try_flock(fd), url, wait_s)
            yield  # closing the file (below) releases its lock
        finally:
            os.close(fd)
    else:
        yield


def _try_advisory_lock(conn: Connection) -> bool:
    return bool(conn.execute(text("SELECT pg_try_advisory_lock(:key)"), {"key": ADVISORY_LOCK_KEY}).scalar())


def _try_flock(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _wait_for(acquire: Callable[[], bool], url: str, wait_s: float) -> None:
    """Poll ``acquire`` (every 10 to 200 ms) until it succeeds or ``wait_s`` has passed."""
    deadline, delay = time.monotonic() + wait_s, 0.01
    while not acquire():
        if time.monotonic() >= deadline:
            raise MigrationBusyError(f"another process has been migrating the database {display_url(url)} for "
                                     f"more than {wait_s:g} s; start this one again once it is done")
        time.sleep(delay)
        delay = min(2 * delay, 0.2)


def current_revision(engine: Engine) -> str | None:
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def is_empty(engine: Engine) -> bool:
    """True when the database has no tables at all (a new file)."""
    return not inspect(engine).get_table_names()


def ensure_schema(engine: Engine, url: str, *, create: bool, wait_s: float = MIGRATION_WAIT_S) -> None:
    """Return once the database is at head: it is (no lock taken), or it is once another process's
    migration is over (waiting for the lock at most ``wait_s``), or it was empty and ``create``
    made the schema. Otherwise raise :class:`SchemaMismatchError`, saying what to run."""
    if current_revision(engine) == head_revision():
        return
    with migration_lock(url, wait_s):
        if create and is_empty(engine):
            log.info("creating the schema in the empty database %s", display_url(url))
            command.upgrade(alembic_config(url), "head")
        check_revision(engine, url)


def check_revision(engine: Engine, url: str) -> None:
    """Raise :class:`SchemaMismatchError`, saying what to run, unless the DB is at head."""
    current, head = current_revision(engine), head_revision()
    if current == head:
        return
    known = {rev.revision for rev in ScriptDirectory.from_config(alembic_config(url)).walk_revisions()}
    if current is not None and current not in known:
        hint = "it was written by a newer finaldrive; upgrade finaldrive"
    else:
        hint = f"run `finaldrive db upgrade --db {display_url(url)}`"
    raise SchemaMismatchError(
        f"database {display_url(url)} is at schema revision {current or 'none'}, this finaldrive needs {head}: {hint}"
    )
