"""The executor contract shared by every backend.

An executor runs tasks ``fn(batch, *values)`` without blocking its caller (docs/workers.md,
"Interface"):

* ``share(value) -> Shared``: a value many tasks need (road, settings, vehicle), sent to the
  workers once; ``release(shared)`` when no further task needs it.
* ``submit(fn, batch, *shared) -> task id``: never blocks; any number may be in flight
  (``capacity`` says how many are worth keeping in flight).
* ``poll(timeout) -> list[Done]``: every task finished since the last poll, each reported once.
* ``cancel(task ids)``: queued tasks are dropped, running ones stopped (process and Ray: the
  worker is killed and replaced); each is reported by ``poll`` as ``Done(cancelled=True)``.
* ``close()``: cancel everything and stop every worker.

Failures, named precisely (docs/workers.md, "Retries"):

* **simulation failure**: the engine returns a result with status ``"failed"``; executors
  never see it and never retry it.
* **worker loss**: the process (or node) running a task died. The task is retried, up to
  ``max_retries`` times, and only then reported ``Done(lost=True)``.
* **task error**: ``fn`` raised an exception (a bug). It is not retried: ``Done(error=...)``.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Protocol, Self, runtime_checkable

#: Tasks worth keeping in flight per worker: one running and one queued, so a worker never
#: waits for the driver between tasks, while a generator of batches stays lazy.
IN_FLIGHT_PER_WORKER = 2

#: On a cluster of more CPUs than this, a task holds several CPUs (:func:`task_width`), so that about this
#: many run at once: a round of waited-on work (a DE generation of every road) then costs the one driver
#: thread about this many tasks (~1 ms each), not one a CPU (docs/workers.md, "Wide tasks").
TASK_SLOTS = 16
#: The most CPUs one task holds: its designs run on as many threads of one process, and the engine's
#: Python around its compiled loops (<= 0.1 ms a design, holding the GIL) would bound wider ones.
MAX_TASK_CPUS = 16
#: A task is no wider than the smallest of the largest nodes that hold this share of the CPUs: smaller nodes
#: beyond it stay idle rather than narrow every task.
MAIN_NODES_SHARE = 0.9


def task_width(node_cpus: Iterable[int], fixed: int | None = None, *, cpus: int | None = None) -> tuple[int, int]:
    """(CPUs a task holds, tasks that run at once) on nodes of ``node_cpus`` CPUs, using ``cpus`` of them in all
    (default: every one). The width is ``fixed`` if given; else 1 CPU a task up to :data:`TASK_SLOTS` CPUs,
    and beyond, ``ceil(cpus / TASK_SLOTS)``, at most :data:`MAX_TASK_CPUS` and at most the smallest of the
    largest nodes that hold :data:`MAIN_NODES_SHARE` of the CPUs (a task runs on one node: a few small
    nodes do not narrow every task, they stay idle). A node's CPUs beyond a multiple of the width stay idle
    too. ValueError if no node has ``fixed`` CPUs."""
    nodes = sorted((int(n) for n in node_cpus if n >= 1), reverse=True) or [1]
    total = min(sum(nodes), cpus or sum(nodes))
    held, cap = 0, nodes[0]
    for cap in nodes:   # the smallest of the largest nodes that hold MAIN_NODES_SHARE of the CPUs
        held += cap
        if held >= MAIN_NODES_SHARE * sum(nodes):
            break
    width = fixed or max(1, min(MAX_TASK_CPUS, cap, math.ceil(total / TASK_SLOTS)))
    held_slots = sum(n // width for n in nodes)
    if not held_slots:
        raise ValueError(f"task_cpus {width} is more than any node's CPUs (at most {nodes[0]})")
    return width, min(held_slots, max(1, total // width))


#: How long :func:`cancel_unseen` waits for its cancelled tasks to be reported [s], in polls of at most 1 s.
CANCEL_DRAIN_S = 5.0

_handle_ids = itertools.count(1)   # Shared keys, unique in this process (so handles of two executors differ)


@dataclass(frozen=True)
class Done:
    """A finished task: exactly one of result / error / lost / cancelled describes how it ended."""

    task: int                            #: the id ``submit`` returned
    result: Any = None                   #: ``fn``'s return value
    error: BaseException | None = None   #: ``fn`` raised: a bug; never retried
    lost: bool = False                   #: its worker died more than ``max_retries`` times (worker loss)
    cancelled: bool = False              #: ``cancel()`` (or ``close()``) stopped it, queued or running

    @property
    def ok(self) -> bool:
        """``fn`` returned: ``result`` holds its value."""
        return self.error is None and not self.lost and not self.cancelled


@dataclass(frozen=True, eq=False)
class Shared:
    """An opaque handle to a value sent to the workers once (``Executor.share``).

    Pass it to ``submit``; ``release`` it when no further task needs it. Only the executor
    that made it can use it. ``ref`` is the backend's own: the value (serial), its pickle
    (process), an ``ObjectRef`` (Ray).
    """

    key: int
    ref: Any = field(repr=False)

    @classmethod
    def new(cls, ref: Any) -> Shared:
        return cls(next(_handle_ids), ref)


@runtime_checkable
class Executor(Protocol):
    """Runs tasks ``fn(batch, *shared values)`` in-process or in worker processes, without blocking.

    Thread safety: ``submit``, ``share``, ``release``, ``cancel``, ``in_flight`` and ``close``
    may be called from any thread; ``poll`` from one thread at a time (it returns every
    finished task, so there is one consumer per executor: the dispatcher).
    """

    num_workers: int
    capacity: int
    #: CPUs a task holds, its designs run on as many threads (1 but for Ray's wide tasks)
    task_cpus: int

    def share(self, value: Any) -> Shared:
        """Make ``value`` available to tasks; it is sent to each worker once (serial: kept as is;
        process: pickled once here, sent to a worker process the first time a task there needs
        it; Ray: ``ray.put`` once)."""
        ...

    def release(self, shared: Shared) -> None:
        """No further task needs the value: free it (in the workers, or Ray's object store)
        once the tasks already submitted with it have finished. Idempotent."""
        ...

    def submit(self, fn: Callable[..., Any], batch: Any, *shared: Shared, again: int = 0) -> int:
        """Queue ``fn(batch, *values of shared)``; return its task id. Never blocks. ``again``: 0, or
        ``k`` for the k-th copy of a task still in flight, submitted because it is overdue (the
        dispatcher's hedging): an executor that places tasks (Ray) places copies apart."""
        ...

    def poll(self, timeout: float) -> list[Done]:
        """Every task finished since the last poll. Waits up to ``timeout`` s for at least one
        while tasks are in flight; returns ``[]`` at once when none are."""
        ...

    def cancel(self, tasks: Iterable[int]) -> None:
        """Drop queued tasks, stop running ones (process, Ray: within 2 s, by killing the worker).

        Each task still in flight is reported once by ``poll``: ``Done(cancelled=True)``, or
        with its outcome if it had already finished. Unknown or reported ids are ignored.
        """
        ...

    def in_flight(self) -> int:
        """Tasks submitted and not yet returned by ``poll``."""
        ...

    def close(self) -> None:
        """Cancel everything and stop every worker (within 2 s); idempotent."""
        ...

    def __enter__(self) -> Self: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...


def cancel_unseen(executor: Executor, tasks: Iterable[int]) -> None:
    """Cancel the tasks and take their reports off the executor (waiting up to ``CANCEL_DRAIN_S``), so
    that its next poll does not return them."""
    left = set(tasks)
    executor.cancel(left)
    deadline = time.monotonic() + CANCEL_DRAIN_S
    while left and executor.in_flight() and time.monotonic() < deadline:
        left -= {done.task for done in executor.poll(min(1.0, max(0.0, deadline - time.monotonic())))}


class ExecutorMixin:
    """What every executor shares: ``with executor:`` closes it; a task on one thread, unless the
    executor says otherwise."""

    task_cpus: int = 1

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
