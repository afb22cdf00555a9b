"""The job runner: one background thread that drives every active job, round-robin.

Each turn takes the next job, evaluates that job's next request through the evaluation
stream (the workers executor), and puts the job back at the end of the queue, so
concurrent jobs share the executor request by request. The thread is the store's only
writer of results; the event loop never waits on it.

Cancelling sets a flag checked between batches: the runner stops dispatching for that job
and drops it; what is stored stays consistent (whole evaluations, whole DE generations).
On stop the current job is left ``running`` and becomes ``interrupted`` at the next start.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Iterator

import numpy as np

from finaldrive.engine import BatchResult, Road, SimSettings, Vehicle
from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import Job, JobState
from finaldrive.service.db.repository import (
    claim_job,
    finish_job,
    interrupt_running,
    set_running_to,
    unfinished_job_ids,
)
from finaldrive.service.jobs.drivers import Driver, EvalRequest, JobContext, make_driver
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.schemas import JobSpec

log = logging.getLogger(__name__)

#: ``evaluate_stream`` with the executor bound: (designs, road, settings, vehicle) -> batches.
EvalStream = Callable[[np.ndarray, Road, SimSettings, "Vehicle | None"], Iterator[tuple[np.ndarray, BatchResult]]]


class _Stopping(Exception):
    """The runner is shutting down in the middle of a request."""


class JobRunner:
    def __init__(self, db: Database, stream: EvalStream, *, engine_version: str, sweep_chunk: int) -> None:
        self._db = db
        self._stream = stream
        self._engine_version = engine_version
        self._sweep_chunk = sweep_chunk
        self._queue: deque[int] = deque()
        self._drivers: dict[int, tuple[Driver, JobContext]] = {}
        self._cancelled: set[int] = set()
        self._wake = threading.Condition()
        self._stopping = False
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ control (any thread)
    def start(self) -> None:
        """Mark jobs a dead process left running as interrupted, queue all unfinished jobs, start."""
        with self._db.write() as session:
            interrupt_running(session)
        with self._db.read() as session:
            pending = unfinished_job_ids(session)
        with self._wake:
            self._queue.extend(pending)
        self._thread = threading.Thread(target=self._loop, name="finaldrive-job-runner", daemon=True)
        self._thread.start()

    def submit(self, job_id: int) -> None:
        with self._wake:
            self._queue.append(job_id)
            self._wake.notify()

    def cancel(self, job_id: int) -> None:
        """Stop dispatching for a job (its state is set to cancelled by the caller)."""
        with self._wake:
            self._cancelled.add(job_id)
            self._wake.notify()

    def stop(self, timeout: float = 10.0) -> None:
        """Stop after the current batch; jobs in progress become ``interrupted``."""
        with self._wake:
            self._stopping = True
            self._wake.notify()
        if self._thread is not None:
            self._thread.join(timeout)
        if self._thread is None or not self._thread.is_alive():
            with self._db.write() as session:
                set_running_to(session, list(self._drivers), JobState.interrupted)

    # ------------------------------------------------------------------ the runner thread
    def _loop(self) -> None:
        while True:
            with self._wake:
                while not self._queue and not self._stopping:
                    self._wake.wait()
                if self._stopping:
                    return
                job_id = self._queue.popleft()
            try:
                keep = self._turn(job_id)
            except _Stopping:
                return
            except Exception as exc:  # a bug or an infrastructure failure: fail the job, keep serving
                if self._is_stopping():  # the executor or database closed under us: resume next start
                    return
                log.exception("job %s failed", job_id)
                self._drop(job_id)
                with self._db.write() as session:
                    finish_job(session, job_id, JobState.failed, error=f"{type(exc).__name__}: {exc}")
                continue
            if keep:
                with self._wake:
                    self._queue.append(job_id)
            else:
                self._drop(job_id)

    def _turn(self, job_id: int) -> bool:
        """Run one request of a job; False when the job is finished or gone."""
        if self._is_cancelled(job_id):
            return False
        entry = self._drivers.get(job_id) or self._open(job_id)
        if entry is None:
            return False
        driver, ctx = entry
        try:
            request = next(driver)
        except StopIteration:
            with self._db.write() as session:
                finish_job(session, job_id, JobState.succeeded)
            log.info("job %s succeeded", job_id)
            return False
        return self._run(job_id, ctx, request)

    def _open(self, job_id: int) -> tuple[Driver, JobContext] | None:
        with self._db.write() as session:
            job: Job | None = claim_job(session, job_id)
            spec = None if job is None else JobSpec.model_validate(job.spec)
        if spec is None:
            return None
        ctx = JobContext(job_id, build_plan(spec), self._db, self._engine_version, self._sweep_chunk)
        entry = (make_driver(ctx), ctx)
        self._drivers[job_id] = entry
        return entry

    def _run(self, job_id: int, ctx: JobContext, request: EvalRequest) -> bool:
        plan = ctx.plan
        batches = self._stream(request.designs, request.road, plan.settings, plan.vehicle)
        try:
            for rows, batch in batches:
                request.on_batch(rows, batch)
                if self._stopping:
                    raise _Stopping
                if self._is_cancelled(job_id):
                    return False
            return True
        finally:  # leaving early: let the stream drop what it still has in flight
            close = getattr(batches, "close", None)
            if close is not None:
                close()

    def _is_stopping(self) -> bool:
        with self._wake:
            return self._stopping

    def _is_cancelled(self, job_id: int) -> bool:
        with self._wake:
            return job_id in self._cancelled

    def _drop(self, job_id: int) -> None:
        entry = self._drivers.pop(job_id, None)
        if entry is not None:
            entry[0].close()
        with self._wake:
            self._cancelled.discard(job_id)
