"""The executor contract shared by every backend, and ``map_batches`` built on it once.

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
  ``max_retries`` times, and only then reported ``Done(lost=True)`` (``map_batches`` raises
  :class:`WorkerLostError`).
* **task error**: ``fn`` raised an exception (a bug). It is not retried: ``Done(error=...)``
  (``map_batches`` re-raises it).
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable, Generator, Iterable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Protocol, Self, cast, runtime_checkable

#: Tasks worth keeping in flight per worker: one running and one queued, so a worker never
#: waits for the driver between tasks, while a generator of batches stays lazy.
IN_FLIGHT_PER_WORKER = 2

#: How long ``map_batches`` waits in one ``poll`` [s] (it loops; this only bounds each wait).
MAP_POLL_S = 1.0

#: How long ``map_batches`` waits, when it stops early, for its cancelled tasks to be reported [s].
MAP_DRAIN_S = 5.0

_handle_ids = itertools.count(1)   # Shared keys, unique in this process (so handles of two executors differ)


class WorkerLostError(RuntimeError):
    """A task's worker process died more than ``max_retries`` times (worker loss)."""


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
    finished task, so there is one consumer per executor). A ``map_batches`` stream is such a
    consumer: while one is open, nothing else may poll the executor (a second open stream
    raises ``RuntimeError``).
    """

    num_workers: int
    capacity: int

    def share(self, value: Any) -> Shared:
        """Make ``value`` available to tasks; it is sent to each worker once (serial: kept as is;
        process: pickled once here, sent to a worker process the first time a task there needs
        it; Ray: ``ray.put`` once)."""
        ...

    def release(self, shared: Shared) -> None:
        """No further task needs the value: free it (in the workers, or Ray's object store)
        once the tasks already submitted with it have finished. Idempotent."""
        ...

    def submit(self, fn: Callable[..., Any], batch: Any, *shared: Shared) -> int:
        """Queue ``fn(batch, *values of shared)``; return its task id. Never blocks."""
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

    def map_batches(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
    ) -> Generator[tuple[int, Any], None, None]:
        """Run ``fn(batch, *shared)`` for each batch; yield ``(batch_index, result)`` as each completes
        (:func:`map_batches`)."""
        ...

    def __enter__(self) -> Self: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...


def map_batches(
    executor: Executor, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
) -> Generator[tuple[int, Any], None, None]:
    """Run ``fn(batch, *shared)`` for each batch on ``executor``; yield ``(batch_index, result)`` as each completes.

    ``shared`` is shared once for the whole stream and released at its end. ``batches`` is
    pulled lazily: a batch is taken only when fewer than ``executor.capacity`` are in flight.
    A task error re-raises the task's exception; a lost task raises :class:`WorkerLostError`.
    Closing the generator early (or an exception) cancels the tasks in flight and waits for
    their reports, so the executor is clean for the next stream.
    """
    handles: list[Shared] = []
    pending: dict[int, int] = {}           # task id -> batch index
    try:
        handles = [executor.share(value) for value in shared]
        source = enumerate(batches)
        exhausted = False
        while True:
            while not exhausted and len(pending) < max(1, executor.capacity):
                item = next(source, None)
                if item is None:
                    exhausted = True
                else:
                    pending[executor.submit(fn, item[1], *handles)] = item[0]
            if not pending:
                return
            for done in executor.poll(MAP_POLL_S):
                index = pending.pop(done.task, None)
                if index is None:
                    continue                   # not this stream's (a task reported late by an earlier one)
                if done.error is not None:
                    raise done.error
                if done.lost:
                    retries = getattr(executor, "max_retries", None)
                    times = "more than max_retries" if retries is None else f"{retries + 1}"
                    raise WorkerLostError(f"batch {index}: its worker died {times} times (worker loss)")
                if done.cancelled:
                    raise RuntimeError(f"batch {index} was cancelled (the executor was closed)")
                yield index, done.result
    finally:
        if pending:
            cancel_unseen(executor, pending)
        for handle in handles:
            executor.release(handle)


def cancel_unseen(executor: Executor, tasks: Iterable[int]) -> None:
    """Cancel the tasks and take their reports off the executor (waiting up to ``MAP_DRAIN_S``), so
    that its next poll does not return them."""
    left = set(tasks)
    executor.cancel(left)
    deadline = time.monotonic() + MAP_DRAIN_S
    while left and executor.in_flight() and time.monotonic() < deadline:
        left -= {done.task for done in executor.poll(min(MAP_POLL_S, max(0.0, deadline - time.monotonic())))}


class ExecutorMixin:
    """What every executor shares: ``map_batches`` (one open stream at a time) and ``with executor:``."""

    def __init__(self) -> None:
        self._stream_open = threading.Lock()

    def close(self) -> None:
        raise NotImplementedError

    def map_batches(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
    ) -> Generator[tuple[int, Any], None, None]:
        """Run ``fn(batch, *shared)`` for each batch; yield ``(batch_index, result)`` as each completes.

        See :func:`map_batches`. One open stream at a time: starting a second raises ``RuntimeError``.
        """
        if not self._stream_open.acquire(blocking=False):
            raise RuntimeError(
                f"{type(self).__name__} serves one map_batches stream at a time; close the open one first"
            )
        try:
            yield from map_batches(cast(Executor, self), fn, batches, shared)
        finally:
            self._stream_open.release()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
