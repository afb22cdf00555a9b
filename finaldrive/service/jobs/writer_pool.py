"""Several writer processes storing one scheduler's results at once, for PostgreSQL.

One writer keeps PostgreSQL to one backend, and a transaction's work alternates between them: the
writer's Python builds and sends the rows, then the server inserts them and their index entries (31-42
us of its CPU an evaluation against the writer's 8-13: docs/performance-log.md). :class:`WriterPool`
runs ``n`` :class:`~finaldrive.service.jobs.writer_process.WriterProcess` children, with their
interface: each put goes to the child with the fewest rows pending, so one job's evaluations are
stored by several transactions at once. Each stores a slot once (``ON CONFLICT``), adds to the job's
counters and ranges in the statement (never a value read before), enters only the rows it inserted in
the index tables (finaldrive.service.db.levels.add_entries), and takes its row locks in one order.
SQLite takes one write transaction at a time: it keeps one writer.

A DE's generation (the state a job resumes from) is stored only after the evaluations it follows: the
pool holds a job's generations until every evaluation handed over before them is acknowledged, then
hands them, in order, to the job's own child (one per job), so a resumed job finds each generation's
evaluations and every earlier generation stored.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

from finaldrive.service.db.engine import Database
from finaldrive.service.jobs.writer import Writes
from finaldrive.service.jobs.writer_process import WriterProcess


@dataclass
class _Held:
    """A job's generations, and the puts of its evaluations they wait for: (child, seq)."""

    generations: list[dict[str, Any]]
    after: list[tuple[WriterProcess, int]]


class WriterPool:
    """``writers`` :class:`WriterProcess` children: ``put``, ``pending``, ``busy``, ``lost``, ``forget``,
    ``drain``, ``wait`` and ``close`` as one writer's. Held generations whose evaluations are stored are
    handed over by whichever of these the scheduler calls next (it calls them every turn)."""

    def __init__(self, db: Database, scheduler_id: str, writers: int) -> None:
        if writers < 1:
            raise ValueError(f"a writer pool has at least one writer, not {writers}")
        self.scheduler_id = scheduler_id
        self._cond = threading.Condition()
        self._children = [WriterProcess(db, scheduler_id, cond=self._cond) for _ in range(writers)]
        self._puts: dict[int, list[tuple[WriterProcess, int]]] = {}   # job -> its evaluations' puts not yet seen acked
        self._held: dict[int, deque[_Held]] = {}                      # job -> its generations held, in order

    def put(self, job_id: int, writes: Writes) -> None:
        """Hand the evaluations of ``writes`` to the least busy child; hold its generations until
        those and every earlier evaluation of the job are stored."""
        with self._cond:
            generations, writes.generations = writes.generations, []
            if len(writes):
                child = min(self._children, key=WriterProcess.pending_rows)
                self._puts.setdefault(job_id, []).append((child, child.put(job_id, writes)))
            if generations:
                self._held.setdefault(job_id, deque()).append(_Held(generations, list(self._puts.get(job_id, ()))))
            self._release()

    def pending(self, job_id: int) -> int:
        """Rows and generations of the job not yet stored (held ones included)."""
        with self._cond:
            self._release()
            held = sum(len(h.generations) for h in self._held.get(job_id, ()))
            return held + sum(child.pending(job_id) for child in self._children)

    def busy(self) -> bool:
        with self._cond:
            self._release()
            return bool(self._held) or any(child.busy() for child in self._children)

    def lost(self) -> list[int]:
        """Jobs found lost by any child (each once); their held generations are dropped."""
        with self._cond:
            lost = sorted({job for child in self._children for job in child.lost()})
            for job_id in lost:
                self._held.pop(job_id, None)
                self._puts.pop(job_id, None)
            return lost

    def forget(self, job_id: int) -> None:
        with self._cond:
            self._held.pop(job_id, None)
            self._puts.pop(job_id, None)
            for child in self._children:
                child.forget(job_id)

    def drain(self, timeout: float) -> bool:
        """Wait until everything handed over (held generations too) is stored, or ``timeout`` s."""
        end = time.monotonic() + timeout
        with self._cond:
            while self.busy():
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    def wait(self, timeout: float) -> None:
        """Wait until a child acknowledges a transaction (or ``timeout`` s); at once if nothing waits."""
        with self._cond:
            if self.busy():
                self._cond.wait(timeout)

    def close(self) -> None:
        for child in self._children:
            child.close()

    @property
    def pids(self) -> list[int]:
        """The children's process ids."""
        return [pid for child in self._children if (pid := child.pid) is not None]

    def _release(self) -> None:
        """Hand over each job's held generations whose evaluations are stored, in order, to the job's child."""
        for job_id in list(self._held):
            held = self._held[job_id]
            while held and all(child.acknowledged(job_id, seq) for child, seq in held[0].after):
                writes = Writes(generations=held.popleft().generations)
                child = self._children[job_id % len(self._children)]
                self._puts.setdefault(job_id, []).append((child, child.put(job_id, writes)))
            if not held:
                del self._held[job_id]
        for job_id, puts in list(self._puts.items()):  # forget the puts seen stored
            puts[:] = [(child, seq) for child, seq in puts if not child.acknowledged(job_id, seq)]
            if not puts:
                del self._puts[job_id]
