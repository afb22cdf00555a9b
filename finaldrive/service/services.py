"""What the API process holds: settings, the database, and a cache of job bodies.

The API validates, reads and writes the store, nothing more: jobs are run by schedulers
(finaldrive.service.jobs.scheduler), in other processes, possibly on other machines.
"""

from __future__ import annotations

from dataclasses import dataclass

from finaldrive.engine import ENGINE_VERSION
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.migrate import ensure_schema, head_revision
from finaldrive.service.status_cache import StatusCache


@dataclass
class Services:
    settings: Settings
    db: Database
    schema_revision: str
    engine_version: str
    status_cache: StatusCache

    def close(self) -> None:
        self.db.dispose()


def open_database(settings: Settings) -> Database:
    """Open the store; create the schema in an empty database; refuse any other revision. A
    migration another process is running (processes started together on an empty store) is
    waited for, at most ``migrate.MIGRATION_WAIT_S``."""
    db = Database(settings.db_url)
    try:
        ensure_schema(db.engine, settings.db_url, create=settings.auto_create_db)
    except Exception:
        db.dispose()
        raise
    return db


def start_services(settings: Settings) -> Services:
    return Services(settings, open_database(settings), head_revision(), ENGINE_VERSION,
                    StatusCache(settings.status_cache_seconds))
