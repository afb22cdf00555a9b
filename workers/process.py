"""Process-pool executor: ``concurrent.futures`` with the *spawn* start method.

Never fork: a forked child shares the parent's Ray sockets and threads (Ray's
``patterns/fork-new-processes``). Each worker process receives ``shared`` once, through the
pool initializer; the pool is kept between ``map_batches`` calls and rebuilt only when
``shared`` changes or a worker dies.

Workers ignore SIGINT (Ctrl-C reaches the whole process group; the parent alone decides
to stop and closes the pool), and a watchdog thread in each worker exits the process
when its parent is gone (parent pid changed, e.g. after the parent was SIGKILLed), so
workers are never left orphaned.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import pickle
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from finaldrive.workers.base import IN_FLIGHT_PER_WORKER, ClosingMixin, WorkerLostError

#: How often a worker checks that its parent is alive [s].
PARENT_POLL_S = 0.5

_shared: tuple[Any, ...] = ()


def _init_worker(shared: tuple[Any, ...], parent_pid: int) -> None:
    """Pool initializer: keep the shared arguments, ignore Ctrl-C, watch the parent."""
    global _shared
    _shared = shared
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="parent-watchdog", daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    """Exit this worker at once when its parent process is gone (it was re-parented)."""
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def _run(fn: Callable[..., Any], batch: Any) -> Any:
    return fn(batch, *_shared)


class ProcessExecutor(ClosingMixin):
    """Runs batches on a pool of spawned worker processes.

    If a worker dies (``BrokenProcessPool``), the pool is rebuilt and only the unfinished
    batches are resubmitted. Every batch in flight when the pool broke counts one attempt,
    since the pool cannot tell which one killed it; a batch that exceeds ``max_retries``
    raises :class:`WorkerLostError`.

    Not thread-safe: one ``map_batches`` stream at a time per executor (a second stream
    started while one is open, from any thread, raises ``RuntimeError``). Give each
    concurrent job its own executor, or use Ray.
    """

    def __init__(self, num_workers: int | None = None, max_retries: int = 3) -> None:
        if max_retries < 0:
            raise ValueError("max_retries must be >= 0")
        self.num_workers = num_workers or os.cpu_count() or 1
        self.max_retries = max_retries
        self._pool: ProcessPoolExecutor | None = None
        self._pool_key: bytes | None = None
        self._busy = threading.Lock()  # held while a map_batches stream is open

    def map_batches(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
    ) -> Generator[tuple[int, Any], None, None]:
        if not self._busy.acquire(blocking=False):
            raise RuntimeError(
                "ProcessExecutor runs one map_batches stream at a time; give each concurrent job its own executor"
            )
        try:
            yield from self._map(fn, batches, shared)
        finally:
            self._busy.release()

    def _map(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...]
    ) -> Iterator[tuple[int, Any]]:
        self._ensure_pool(shared)
        source = enumerate(batches)
        todo: dict[int, Any] = {}              # unfinished batches by index
        failures: dict[int, int] = {}
        retry: deque[int] = deque()
        pending: dict[Future[Any], int] = {}
        try:
            while True:
                self._fill(fn, source, todo, retry, pending, shared)
                if not pending:
                    if not retry:
                        return
                    self._rebuild(shared)          # the pool broke while submitting
                    continue
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                    done, _ = wait(pending)        # the rest fail at once; settle them all
                finished: list[tuple[int, Any]] = []
                for future in done:
                    index = pending.pop(future)
                    error = future.exception()
                    if error is None:
                        finished.append((index, future.result()))
                        del todo[index]
                    elif isinstance(error, BrokenProcessPool):
                        failures[index] = failures.get(index, 0) + 1
                        if failures[index] > self.max_retries:
                            raise WorkerLostError(
                                f"batch {index}: worker process died {failures[index]} times"
                            ) from error
                        retry.append(index)
                    else:
                        raise error
                if retry:
                    self._rebuild(shared)
                self._fill(fn, source, todo, retry, pending, shared)
                yield from finished
        finally:
            for future in pending:
                future.cancel()

    def _fill(
        self,
        fn: Callable[..., Any],
        source: Iterator[tuple[int, Any]],
        todo: dict[int, Any],
        retry: deque[int],
        pending: dict[Future[Any], int],
        shared: tuple[Any, ...],
    ) -> None:
        """Submit retries first, then new batches, up to the in-flight bound."""
        assert self._pool is not None
        while len(pending) < IN_FLIGHT_PER_WORKER * self.num_workers:
            if retry:
                index = retry.popleft()
            else:
                item = next(source, None)
                if item is None:
                    return
                index, todo[index] = item
            try:
                pending[self._pool.submit(_run, fn, todo[index])] = index
            except BrokenProcessPool:
                retry.appendleft(index)            # not charged: it never started
                if pending:
                    return                         # their failures trigger the rebuild
                self._rebuild(shared)

    def _ensure_pool(self, shared: tuple[Any, ...]) -> None:
        key = hashlib.sha256(pickle.dumps(shared)).digest()
        if self._pool is None or key != self._pool_key:
            self._rebuild(shared)
            self._pool_key = key

    def _rebuild(self, shared: tuple[Any, ...]) -> None:
        self._shutdown_pool()
        self._pool = ProcessPoolExecutor(
            max_workers=self.num_workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(shared, os.getpid()),
        )

    def _shutdown_pool(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def close(self) -> None:
        """Stop the worker processes (waits for running batches)."""
        self._shutdown_pool()
        self._pool_key = None
