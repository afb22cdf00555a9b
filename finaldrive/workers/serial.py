"""In-process executor: the default, the test double, and the debugging mode.

``submit`` queues; ``poll`` runs queued tasks in the calling thread. ``cancel`` drops queued
tasks, but it cannot stop the task that ``poll`` is running (another thread's ``cancel``
waits for nothing, and that task is reported with its outcome).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from finaldrive.workers.base import IN_FLIGHT_PER_WORKER, Done, ExecutorMixin, Shared


class SerialExecutor(ExecutorMixin):
    """Runs tasks one after another in the thread that calls ``poll``."""

    num_workers: int = 1
    capacity: int = IN_FLIGHT_PER_WORKER

    def __init__(self) -> None:
        super().__init__()
        self._lock = threading.Lock()
        self._ids = 0
        self._queue: deque[tuple[int, Callable[..., Any], Any, tuple[Shared, ...]]] = deque()
        self._running = 0                      # tasks poll has taken from the queue and not yet returned
        self._done: list[Done] = []
        self._shared: set[int] = set()         # live handles
        self._closed = False

    def share(self, value: Any) -> Shared:
        """The handle holds the value itself."""
        handle = Shared.new(value)
        with self._lock:
            self._shared.add(handle.key)
        return handle

    def release(self, shared: Shared) -> None:
        with self._lock:
            self._shared.discard(shared.key)

    def submit(self, fn: Callable[..., Any], batch: Any, *shared: Shared, again: int = 0) -> int:
        with self._lock:
            if self._closed:
                raise RuntimeError("the executor is closed")
            for handle in shared:
                if handle.key not in self._shared:
                    raise ValueError(f"unknown or released shared handle {handle!r}")
            self._ids += 1
            self._queue.append((self._ids, fn, batch, shared))
            return self._ids

    def poll(self, timeout: float) -> list[Done]:
        """Run queued tasks here: at least one, then more while ``timeout`` lasts; return what finished."""
        deadline = time.monotonic() + max(0.0, timeout)
        ran = False
        while True:
            with self._lock:
                if not self._queue or (ran and time.monotonic() >= deadline):
                    done, self._done = self._done, []
                    return done
                task, fn, batch, shared = self._queue.popleft()
                self._running += 1
            try:
                outcome = Done(task, result=fn(batch, *(handle.ref for handle in shared)))
            except Exception as error:   # a bug in fn
                outcome = Done(task, error=error)
            except BaseException:        # KeyboardInterrupt, SystemExit: they reach the caller
                with self._lock:
                    self._running -= 1
                    self._done.append(Done(task, cancelled=True))
                raise
            with self._lock:
                self._running -= 1
                self._done.append(outcome)
            ran = True

    def cancel(self, tasks: Iterable[int]) -> None:
        """Drop the queued tasks among ``tasks`` (a running one cannot be stopped: it runs in ``poll``'s thread)."""
        wanted = set(tasks)
        with self._lock:
            kept: deque[tuple[int, Callable[..., Any], Any, tuple[Shared, ...]]] = deque()
            for item in self._queue:
                if item[0] in wanted:
                    self._done.append(Done(item[0], cancelled=True))
                else:
                    kept.append(item)
            self._queue = kept

    def in_flight(self) -> int:
        with self._lock:
            return len(self._queue) + self._running + len(self._done)

    def close(self) -> None:
        """Cancel the queued tasks; idempotent."""
        with self._lock:
            self._closed = True
            queued = [item[0] for item in self._queue]
        self.cancel(queued)
