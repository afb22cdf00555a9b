"""The scheduler's way to the store: guarded transactions, and results written by a thread of their own.

:class:`Guard` runs a transaction and turns a database error (locked past the busy timeout, disk
full, connection lost) into ``None`` with back-off, logged once per outage, so the caller keeps
its data and tries again later. :class:`Writer` stores each job's results in order in its own
thread, so its caller keeps going while a write waits for the disk or a lock. A scheduler runs it
in a process of its own (finaldrive.service.jobs.writer_process), off the dispatching loop's GIL.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, TypeVar

from sqlalchemy.exc import SQLAlchemyError

from finaldrive.service.db.engine import Database
from finaldrive.service.db.leases import report_store_error
from finaldrive.service.db.results import LeaseLost, Row, store_results
from finaldrive.service.jobs.rows import CHUNK_ROWS, Block, Finished, block_from_results, rows_from_block

log = logging.getLogger(__name__)
T = TypeVar("T")


@dataclass
class Writes:
    """What a job has to store, in order: evaluations (rows, and blocks and finished results not
    yet made rows), then each completed DE generation; ``seq`` numbers it (the latest merged in)
    for acknowledgements."""

    rows: list[Row] = field(default_factory=list)
    finished: list[Finished] = field(default_factory=list)
    blocks: list[Block] = field(default_factory=list)
    generations: list[dict[str, Any]] = field(default_factory=list)
    unmade: int = 0   # evaluations in ``finished`` and ``blocks``
    seq: int = 0

    def __len__(self) -> int:
        return len(self.rows) + self.unmade + len(self.generations)

    def finish(self, result: Finished) -> None:
        """A finished part of a request, made rows later (:meth:`chunks`)."""
        self.finished.append(result)
        self.unmade += len(result[0])

    def add(self, block: Block) -> None:
        """Evaluations as a block, made rows later."""
        self.pack()
        self.blocks.append(block)
        self.unmade += len(block)

    def extend(self, later: Writes) -> None:
        self.rows += later.rows
        self.pack()
        later.pack()
        self.blocks += later.blocks
        self.unmade += later.unmade
        self.generations += later.generations
        self.seq = max(self.seq, later.seq)

    def pack(self) -> None:
        """The finished results concatenated into a block (a few array operations a result; the
        rows' per-value work is left to :meth:`chunks`, in the writer)."""
        if self.finished:
            self.blocks.append(block_from_results(self.finished))
            self.finished = []

    def chunks(self) -> Iterator[list[Row]]:
        """The rows to store, :data:`CHUNK_ROWS` at a time, the blocks' made rows as they are asked for
        (``store_results`` stores each chunk before the next is built); each call reads them afresh (a
        transaction that failed is tried again with a new one)."""
        self.pack()
        for start in range(0, len(self.rows), CHUNK_ROWS):
            yield self.rows[start:start + CHUNK_ROWS]
        for block in self.blocks:
            for start in range(0, len(block), CHUNK_ROWS):
                yield rows_from_block(block, slice(start, start + CHUNK_ROWS))


#: An outage is logged as over once the store has answered without a failure for this long [s]
#: (some transactions failing while others pass, as on a full disk, is one outage, logged once).
OUTAGE_OVER_S = 5.0


class Guard:
    """Transactions that survive the store's outages: an error is logged, backs off, returns None."""

    def __init__(self, db: Database, name: str) -> None:
        self.db = db
        self.name = name
        self._retry_at = 0.0
        self._down_since: float | None = None
        self._up_since: float | None = None   # the first success since the last failure, in an outage
        self.last_error: str | None = None    # the database's message of the last failure (no SQL)

    def waiting(self) -> float:
        """Seconds until the next attempt is allowed (0: now)."""
        return max(0.0, self._retry_at - time.monotonic())

    def __call__(self, fn: Callable[[Any], T], what: str, *, write: bool = True) -> T | None:
        """``fn(session)`` in a write (or read) transaction; None if the store failed or is backing off.
        :class:`LeaseLost` is raised (nothing was written)."""
        if self.waiting():
            return None
        try:
            with self.db.write() if write else self.db.read() as session:
                result = fn(session)
        except LeaseLost:
            raise
        except SQLAlchemyError as exc:
            now = time.monotonic()
            self._up_since = None
            self.last_error = " ".join(str(getattr(exc, "orig", None) or type(exc).__name__).split())[:300]
            if self._down_since is None:
                self._down_since = now
                log.warning("%s: the store is unavailable (%s): %s; retrying", self.name, what,
                            " ".join(str(exc).split())[:500])
            self._retry_at = now + min(5.0, 0.25 + 0.5 * (now - self._down_since))
            return None
        self._retry_at = 0.0
        if self._down_since is not None:  # an outage ends once the store has answered for a while
            now = time.monotonic()
            self._up_since = self._up_since or now
            if now - self._up_since >= OUTAGE_OVER_S:
                log.warning("%s: the store is back after %.1f s", self.name, self._up_since - self._down_since)
                self._down_since = self._up_since = None
        return result


#: Called with (job, the ``seq`` of the writes, whether the job was found lost) once they are stored or dropped.
Stored = Callable[[int, int, bool], None]


class Writer:
    """Stores jobs' :class:`Writes` in a thread, each job's in the order given, one transaction a
    job at a time (what queued meanwhile is merged into it); finished results are made rows there."""

    def __init__(self, db: Database, scheduler_id: str, on_stored: Stored | None = None) -> None:
        self.scheduler_id = scheduler_id
        self._on_stored = on_stored
        self._guard = Guard(db, f"scheduler {scheduler_id} (writer)")
        self._cond = threading.Condition()
        self._queue: deque[int] = deque()           # jobs with writes waiting, oldest first
        self._waiting: dict[int, Writes] = {}       # job -> its writes not yet taken by the thread
        self._busy: dict[int, int] = {}             # job -> rows+generations being written now
        self._lost: list[int] = []
        self._reported: str | None = "unknown"     # the failure recorded in the scheduler's row (unknown: cleared
                                                    # by the first store that passes)
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="finaldrive-writer", daemon=True)
        self._thread.start()

    def put(self, job_id: int, writes: Writes) -> None:
        """Queue ``writes`` after everything queued for the job before."""
        with self._cond:
            if job_id in self._waiting:
                self._waiting[job_id].extend(writes)
            else:
                self._waiting[job_id] = writes
                self._queue.append(job_id)
            self._cond.notify_all()  # (the scheduler's loop may wait on it too: wait)

    def pending(self, job_id: int) -> int:
        """Rows and generations of the job not yet stored."""
        with self._cond:
            waiting = self._waiting.get(job_id)
            return (len(waiting) if waiting else 0) + self._busy.get(job_id, 0)

    def busy(self) -> bool:
        """Whether anything is being stored or waits to be (a write transaction may hold the store)."""
        with self._cond:
            return bool(self._busy or self._queue)

    def lost(self) -> list[int]:
        """Jobs whose lease was found lost when their results were written (each reported once);
        their results were dropped."""
        with self._cond:
            lost, self._lost = self._lost, []
            return lost

    def forget(self, job_id: int) -> None:
        """Drop the job's writes that wait (the job is no longer ours)."""
        with self._cond:
            if self._waiting.pop(job_id, None) is not None:
                self._queue.remove(job_id)

    def drain(self, timeout: float) -> bool:
        """Wait until everything queued is stored (or ``timeout`` s); True if it was."""
        with self._cond:
            return self._cond.wait_for(lambda: not (self._waiting or self._busy), timeout)

    def wait(self, timeout: float) -> None:
        """Wait until the next transaction ends (or ``timeout`` s); at once if nothing waits to be stored."""
        with self._cond:
            if self._busy or self._queue:
                self._cond.wait(timeout)

    def close(self) -> None:
        """Stop the thread; what still waits is dropped (the jobs resume from what is stored)."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(5.0)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                job_id = self._queue.popleft()
                writes = self._waiting.pop(job_id)
                self._busy[job_id] = len(writes)
            stored = self._store(job_id, writes)
            with self._cond:
                del self._busy[job_id]
                if not stored and not self._stop:  # the store is unavailable: first in line again
                    if job_id in self._waiting:
                        writes.extend(self._waiting[job_id])
                        self._queue.remove(job_id)
                    self._waiting[job_id] = writes
                    self._queue.appendleft(job_id)
                self._cond.notify_all()
            if not stored:
                time.sleep(min(self._guard.waiting(), 0.5) or 0.01)

    def _store(self, job_id: int, writes: Writes) -> bool:
        """True when stored, or dropped because the job is no longer ours."""
        try:
            done = self._guard(
                lambda s: store_results(s, self.scheduler_id, job_id, writes.chunks(), writes.generations),
                f"store results of job {job_id}")
        except LeaseLost:
            log.info("scheduler %s: lost job %s before storing its results", self.scheduler_id, job_id)
            with self._cond:
                self._lost.append(job_id)
            if self._on_stored is not None:
                self._on_stored(job_id, writes.seq, True)
            return True
        if done is not None and self._on_stored is not None:
            self._on_stored(job_id, writes.seq, False)
        if (done is None) != (self._reported is not None):
            self._report(None if done is not None else self._guard.last_error or "unknown error")
        return done is not None

    def _report(self, error: str | None) -> None:
        """Best effort: say in the scheduler's row (for /v1/health) that results cannot be stored, or can
        again. A full disk fails the results' transactions while this small one still passes."""
        try:
            with self._guard.db.write(timeout_s=1.0) as session:
                report_store_error(session, self.scheduler_id, error)
        except SQLAlchemyError:
            return
        self._reported = error
