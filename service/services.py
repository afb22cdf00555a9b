"""What the running service holds: settings, database, executor and job runner.

Built in the app's lifespan (in a worker thread: it opens the database and may start
worker processes), torn down in reverse order.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from finaldrive.engine import ENGINE_VERSION, BatchResult, Road, SimSettings, Vehicle
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.migrate import check_revision, head_revision, is_empty, upgrade
from finaldrive.service.jobs.recordings import RecordingProducer, data_dir
from finaldrive.service.jobs.runner import EvalStream, JobRunner
from finaldrive.service.status_cache import StatusCache

if TYPE_CHECKING:
    from finaldrive.workers import Executor

log = logging.getLogger(__name__)


@dataclass
class Services:
    settings: Settings
    db: Database
    runner: JobRunner
    executor: Executor | None
    schema_revision: str
    engine_version: str
    status_cache: StatusCache
    recorder: RecordingProducer | None = None

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.stop()
        self.runner.stop()
        if self.executor is not None:
            self.executor.close()
        self.db.dispose()


def open_database(settings: Settings) -> Database:
    """Open the store; create the schema in an empty database; refuse any other revision."""
    db = Database(settings.db_url)
    try:
        if settings.auto_create_db and is_empty(db.engine):
            log.info("creating the schema in the empty database %s", settings.db_url)
            upgrade(settings.db_url)
        check_revision(db.engine, settings.db_url)
    except Exception:
        db.dispose()
        raise
    return db


def start_services(settings: Settings, stream: EvalStream | None = None) -> Services:
    """Open everything; ``stream`` replaces the workers executor (tests inject fakes)."""
    db = open_database(settings)
    executor: Executor | None = None
    if stream is None:
        from finaldrive.workers import make_executor

        executor = make_executor(settings.executor, num_workers=settings.num_workers, address=settings.ray_address)
        stream = executor_stream(executor, settings.batch_size)
    runner = JobRunner(db, stream, engine_version=ENGINE_VERSION, sweep_chunk=settings.sweep_chunk)
    runner.start()
    recorder = RecordingProducer(db, data_dir(settings))
    recorder.start()
    return Services(
        settings, db, runner, executor, head_revision(), ENGINE_VERSION, StatusCache(settings.status_cache_seconds),
        recorder,
    )


def executor_stream(executor: Executor, batch_size: int | None) -> EvalStream:
    """``workers.evaluate_stream`` bound to an executor and a batch size."""
    from finaldrive.workers import evaluate_stream

    def stream(
        designs: np.ndarray, road: Road, sim: SimSettings, vehicle: Vehicle | None
    ) -> Iterator[tuple[np.ndarray, BatchResult]]:
        return evaluate_stream(executor, designs, road, sim, vehicle, batch_size=batch_size)

    return stream
