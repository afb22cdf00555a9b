"""Schema migrations: run them, and check a database is at the code's revision.

The Alembic scripts live in the ``migrations`` package, so they ship with finaldrive
(the pattern of Optuna's ``_create_alembic_config``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Engine, inspect

from finaldrive.service.db.engine import display_url


class SchemaMismatchError(RuntimeError):
    """The database is not at the revision this version of finaldrive expects."""


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


def upgrade(url: str, revision: str = "head") -> None:
    """Bring the database at ``url`` to ``revision`` (``finaldrive db upgrade``)."""
    command.upgrade(alembic_config(url), revision)


def current_revision(engine: Engine) -> str | None:
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def is_empty(engine: Engine) -> bool:
    """True when the database has no tables at all (a new file)."""
    return not inspect(engine).get_table_names()


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
