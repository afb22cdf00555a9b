"""The executor contract shared by every backend.

An executor runs ``fn(batch, *shared)`` for many batches and yields ``(batch_index, result)``
as each batch completes. ``shared`` (road, settings, ...) is shipped to the workers once per
``map_batches`` call, not once per batch. ``batches`` may be any iterable, including a
generator: executors pull it lazily, only when a worker slot is free, so a caller can size
later batches from the timings of earlier ones (see :mod:`workers.batching`).

Failures, named precisely (docs/workers.md, "Retries"):

* **simulation failure**: the engine returns a result with status ``"failed"``; executors
  never see it and never retry it.
* **worker loss**: the process (or node) running a batch died. The batch is retried, up to
  ``max_retries`` times, and only then :class:`WorkerLostError` is raised.
* **task error**: ``fn`` raised an exception (a bug). It is not retried; it propagates
  from ``map_batches`` unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterable
from types import TracebackType
from typing import Any, Protocol, Self, runtime_checkable

#: Batches submitted but not finished, per worker: one running and one queued, so a worker
#: never waits for the driver between batches, while the generator of batches stays lazy.
IN_FLIGHT_PER_WORKER = 2


class WorkerLostError(RuntimeError):
    """A batch's worker process died more than ``max_retries`` times (worker loss)."""


@runtime_checkable
class Executor(Protocol):
    """Runs batches of work, in-process or in worker processes.

    Thread safety: an executor serves **one** ``map_batches`` stream at a time. Open a
    stream, consume or close it, then open the next; never share one executor between
    threads (or interleave two open streams in one thread). The process pool enforces
    this (a second open stream raises ``RuntimeError``); give each concurrent job its own
    executor.
    """

    num_workers: int

    def map_batches(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
    ) -> Generator[tuple[int, Any], None, None]:
        """Run ``fn(batch, *shared)`` for each batch; yield ``(batch_index, result)`` as each completes.

        ``shared`` is sent once (process initializer or ``ray.put``). Closing the iterator
        early cancels the batches not yet started.
        """
        ...

    def close(self) -> None:
        """Release workers; idempotent."""
        ...

    def __enter__(self) -> Self: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None: ...


class ClosingMixin:
    """``with executor:`` calls ``close()`` on exit."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
