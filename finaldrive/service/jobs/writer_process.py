"""The scheduler's writer in a process of its own, so storing results takes nothing from the
dispatching loop's GIL.

In one process the writer thread's 6.5-7.5 s of CPU a paper-study run (binding each row's values
for the driver) and the rows' building (1.9 s) shared the GIL with the loop that dispatches
30,000 tasks; a simulated 256-CPU cluster ran at 0.86-0.89 of its ideal for that alone
(docs/performance-log.md). :class:`WriterProcess` has the interface of the thread
:class:`~finaldrive.service.jobs.writer.Writer` and runs one in a child process, started from a
fork server (spawned once, so a new child costs a fork, not an interpreter's start and imports).

Nothing is lost or stored twice when the child dies: the parent keeps each :class:`Writes` it
handed over until the child acknowledges it (stored, or dropped because the job was found lost),
and a new child is sent everything not acknowledged, in order (a slot stored already is skipped
by the store). The child ends when the scheduler's process does: its pipe closes.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import queue
import signal
import threading
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import Any

from finaldrive.service.db.engine import WRITER_CACHE_KIB, Database
from finaldrive.service.jobs.writer import Writer, Writes

log = logging.getLogger(__name__)

#: Pause before a child that died is replaced [s]: the first, doubled each time a child dies within the
#: second, up to the second.
RESTART_BACKOFF_S = (0.5, 10.0)
#: A closing child gets this long to stop before it is killed [s].
_CLOSE_S = 5.0


def _context() -> Any:
    """The fork server: a clean single-threaded process (never a fork of the scheduler, which holds
    Ray's threads and sockets) with this module imported."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload([__name__])
    return context


def start_fork_server() -> None:
    """Start the fork server now (it imports this module and the store's, ~0.8 s of CPU), rather than
    when the first writer starts: the scheduler calls it before Ray's start and the wait for the
    engine's compilation, which it then overlaps."""
    import multiprocessing.forkserver

    _context()
    multiprocessing.forkserver.ensure_running()


class WriterProcess:
    """A :class:`Writer` in a child process: ``put``, ``pending``, ``busy``, ``lost``, ``forget``,
    ``drain``, ``wait`` and ``close`` as the thread's."""

    def __init__(self, db: Database, scheduler_id: str, *, cond: threading.Condition | None = None) -> None:
        """``cond``: the condition its acknowledgements notify (shared by a pool's writers)."""
        self.scheduler_id = scheduler_id
        self._store = (db.url, db.lock_timeout_s)
        self._cond = cond or threading.Condition()
        self._unacked: dict[int, deque[tuple[int, Writes]]] = {}  # job -> (seq, writes) handed over
        self._pending: dict[int, int] = {}                         # job -> rows and generations of those
        self._lost: list[int] = []
        self._seq = 0
        self._epoch = 0
        self._closed = False
        self._backoff = RESTART_BACKOFF_S[0] / 2
        self._outbox: queue.SimpleQueue[tuple[int, tuple[Any, ...]]] = queue.SimpleQueue()
        self._link = self._start()
        threading.Thread(target=self._send, name="finaldrive-writer-send", daemon=True).start()

    # ------------------------------------------------------------------ the Writer interface
    def put(self, job_id: int, writes: Writes) -> int:
        """Hand ``writes`` to the child after everything handed over for the job before; returns their
        number (:meth:`acknowledged`)."""
        writes.pack()  # a block pickles in a few arrays; a result holds 30
        with self._cond:
            self._seq += 1
            writes.seq = self._seq
            self._unacked.setdefault(job_id, deque()).append((writes.seq, writes))
            self._pending[job_id] = self._pending.get(job_id, 0) + len(writes)
            self._outbox.put((self._epoch, ("put", job_id, writes)))
            return writes.seq

    def acknowledged(self, job_id: int, seq: int) -> bool:
        """Whether the job's writes numbered ``seq`` (and those before) are stored, or were dropped."""
        with self._cond:
            entries = self._unacked.get(job_id)
            return not entries or entries[0][0] > seq

    def pending_rows(self) -> int:
        """Rows and generations of every job not yet stored."""
        with self._cond:
            return sum(self._pending.values())

    def pending(self, job_id: int) -> int:
        """Rows and generations of the job not yet stored."""
        with self._cond:
            return self._pending.get(job_id, 0)

    def busy(self) -> bool:
        """Whether anything is being stored or waits to be."""
        with self._cond:
            return bool(self._unacked)

    def lost(self) -> list[int]:
        """Jobs whose lease was found lost when their results were written (each reported once)."""
        with self._cond:
            lost, self._lost = self._lost, []
            return lost

    def forget(self, job_id: int) -> None:
        """Drop the job's writes not yet stored (the job is no longer ours)."""
        with self._cond:
            self._unacked.pop(job_id, None)
            self._pending.pop(job_id, None)
            self._outbox.put((self._epoch, ("forget", job_id)))
            self._cond.notify_all()

    def drain(self, timeout: float) -> bool:
        """Wait until everything handed over is stored (or ``timeout`` s); True if it was."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._unacked, timeout)

    def wait(self, timeout: float) -> None:
        """Wait until the child acknowledges its next transaction (or ``timeout`` s); at once if
        nothing waits to be stored."""
        with self._cond:
            if self._unacked:
                self._cond.wait(timeout)

    def close(self) -> None:
        """Stop the child; what it has not stored is dropped (the jobs resume from what is stored)."""
        with self._cond:
            self._closed = True
            self._outbox.put((self._epoch, ("stop",)))
        process = self._link[0]
        process.join(_CLOSE_S)
        if process.is_alive():
            process.kill()
            process.join()

    @property
    def pid(self) -> int | None:
        """The child's process id (a new one after a restart)."""
        return int(self._link[0].pid) if self._link[0].pid is not None else None

    # ------------------------------------------------------------------ the child
    def _start(self) -> tuple[Any, Connection]:
        """A child with a pipe each way, and a thread that reads its acknowledgements."""
        context = _context()
        inbox, to_child = context.Pipe(duplex=False)
        from_child, outbox = context.Pipe(duplex=False)
        process = context.Process(target=_serve, name="finaldrive-writer", daemon=True,
                                  args=(*self._store, self.scheduler_id, logging.getLogger().level, inbox, outbox))
        process.start()
        inbox.close()
        outbox.close()
        threading.Thread(target=self._receive, args=(process, from_child), name="finaldrive-writer-acks",
                         daemon=True).start()
        return process, to_child

    def _send(self) -> None:
        """Pickle and send what the loop handed over, in order (the loop never waits on the pipe)."""
        while True:
            epoch, message = self._outbox.get()
            with self._cond:
                if epoch != self._epoch:  # sent again to a new child from what is unacknowledged
                    continue
                pipe = self._link[1]
            with contextlib.suppress(OSError):  # the child is gone: it is replaced and sent what is unacknowledged
                pipe.send(message)
            if message[0] == "stop":
                return

    def _receive(self, process: Any, pipe: Connection) -> None:
        """Take the child's acknowledgements; when it ends unasked, start another and send it what
        is unacknowledged."""
        started = time.monotonic()
        while True:
            try:
                job_id, seq, lost = pipe.recv()
            except (EOFError, OSError):
                break
            with self._cond:
                self._acknowledge(job_id, seq, lost)
        process.join()
        if not self._replacing():
            return
        quick = time.monotonic() - started < RESTART_BACKOFF_S[1]  # it keeps dying: wait longer each time
        self._backoff = min(2 * self._backoff, RESTART_BACKOFF_S[1]) if quick else RESTART_BACKOFF_S[0]
        log.error("scheduler %s: the writer process ended (exit code %s); starting another in %.1f s",
                  self.scheduler_id, process.exitcode, self._backoff)
        time.sleep(self._backoff)
        with self._cond:
            if not self._replacing():
                return
            self._epoch += 1
            self._link = self._start()
            for job_id, entries in self._unacked.items():  # in order: seq grows within each job
                for _, writes in entries:
                    self._outbox.put((self._epoch, ("put", job_id, writes)))

    def _replacing(self) -> bool:
        """Whether a child that ended is to be replaced: not closed, and the interpreter not exiting."""
        return not self._closed and threading.main_thread().is_alive()

    def _acknowledge(self, job_id: int, seq: int, lost: bool) -> None:
        entries = self._unacked.get(job_id)
        while entries and entries[0][0] <= seq:
            _, writes = entries.popleft()
            self._pending[job_id] -= len(writes)
        if entries is not None and not entries:
            del self._unacked[job_id], self._pending[job_id]
        if lost:
            self._lost.append(job_id)
        self._cond.notify_all()


def _serve(url: str, lock_timeout_s: float, scheduler_id: str, log_level: int,
           inbox: Connection, outbox: Connection) -> None:
    """The child: a :class:`Writer` fed from ``inbox``, acknowledging on ``outbox``, until told to
    stop or the scheduler's process is gone (a Ctrl-C in the terminal is the scheduler's to obey:
    it still drains what it has into this child)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.basicConfig(level=log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    db = Database(url, lock_timeout_s=lock_timeout_s, cache_kib=WRITER_CACHE_KIB)
    sending = threading.Lock()

    def stored(job_id: int, seq: int, lost: bool) -> None:
        with sending:
            outbox.send((job_id, seq, lost))

    writer = Writer(db, scheduler_id, on_stored=stored)
    try:
        while True:
            try:
                message = inbox.recv()
            except (EOFError, OSError):
                break  # the scheduler is gone
            if message[0] == "put":
                writer.put(message[1], message[2])
            elif message[0] == "forget":
                writer.forget(message[1])
            else:
                break
    finally:
        writer.close()
        db.dispose()
