"""What the API process holds: settings, the database, and a cache of job bodies.

The API validates, reads and writes the store, nothing more: jobs are run by schedulers
(finaldrive.service.jobs.scheduler), in other processes, possibly on other machines.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from finaldrive.engine import ENGINE_VERSION
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database, display_url
from finaldrive.service.db.migrate import check_revision, head_revision, is_empty, upgrade
from finaldrive.service.status_cache import StatusCache

log = logging.getLogger(__name__)


@dataclass
class Services:
    settings: Settings
    db: Database
    schema_revision: str
    engine_version: str
    status_cache: StatusCache

    def close(self) -> None:
        self.db.dispose()


def open_database(settings: Settings, *, durable: bool = True) -> Database:
    """Open the store; create the schema in an empty database; refuse any other revision.
    ``durable=False``: for a scheduler (finaldrive.service.db.engine)."""
    db = Database(settings.db_url, durable=durable)
    try:
        if settings.auto_create_db and is_empty(db.engine):
            log.info("creating the schema in the empty database %s", display_url(settings.db_url))
            upgrade(settings.db_url)
        check_revision(db.engine, settings.db_url)
    except Exception:
        db.dispose()
        raise
    return db


def start_services(settings: Settings) -> Services:
    return Services(settings, open_database(settings), head_revision(), ENGINE_VERSION,
                    StatusCache(settings.status_cache_seconds))
