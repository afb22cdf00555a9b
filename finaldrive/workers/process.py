"""Process executor: a small pool of *spawned* worker processes that can be killed one by one.

``concurrent.futures`` cannot stop a running task, so the pool is its own: ``num_workers``
processes, each started with the *spawn* method (never fork: a forked child shares the
parent's Ray sockets and threads, Ray's ``patterns/fork-new-processes``) and connected to
the parent by its own duplex pipe. The parent keeps the submitted tasks in a queue and
gives the next one to an idle worker; a worker runs one task at a time.

* **Shared values** are pickled once, by ``share``, and sent to a worker process with the
  first task there that needs them; the worker keeps them by handle until ``release``
  (after the tasks using them have finished) tells it to drop them.
* **poll** waits on the pipes and the process sentinels (``multiprocessing.connection.wait``).
* **Worker loss.** A worker that dies (sentinel, or EOF on its pipe) is replaced and its task
  retried, up to ``max_retries`` times; then the task is reported ``lost``.
* **cancel** of a queued task drops it; of a running task, SIGKILLs its worker (a long
  compiled computation cannot be interrupted otherwise). A replacement is started when
  there is work for it.
* Workers are started when the first task needs them, and kept.

Workers ignore SIGINT (Ctrl-C reaches the whole process group; the parent alone decides to
stop and closes the executor), run at ``niceness`` (``os.nice``, once per process), and a
watchdog thread in each worker exits the process when its parent is gone (parent pid
changed, e.g. after the parent was SIGKILLed), so workers are never left orphaned.

Thread safety: every method takes the executor's lock; ``poll`` waits without it, and a
``submit``, ``cancel`` or ``close`` from another thread wakes a waiting ``poll``.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import pickle
import signal
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from typing import Any

from finaldrive.workers.base import IN_FLIGHT_PER_WORKER, Done, ExecutorMixin, Shared

#: How often a worker checks that its parent is alive [s].
PARENT_POLL_S = 0.5
#: A message up to this size is written at once to a worker still starting (it fits the pipe's
#: buffer); a larger one waits for the worker's "ready", so ``submit`` never blocks.
EARLY_SEND_BYTES = 32 * 1024
#: How long ``close`` lets idle workers exit on their own before it kills them [s].
STOP_GRACE_S = 0.5

_PICKLE = pickle.HIGHEST_PROTOCOL


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process (its ``__cause__``)."""

    def __init__(self, tb: str) -> None:
        super().__init__(tb)
        self.tb = tb

    def __str__(self) -> str:
        return self.tb


# ---------------------------------------------------------------------- the worker process
#: In a worker process: the shared values it has received, by handle key.
_values: dict[int, Any] = {}


def held_keys() -> list[int]:
    """In a worker process: the keys of the shared values it holds (for tests and diagnostics)."""
    return sorted(_values)


def _worker_main(conn: Connection, parent_pid: int, niceness: int) -> None:
    """A worker: ignore Ctrl-C, lower the priority, watch the parent, then run tasks until EOF."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if niceness:
        os.nice(niceness)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="parent-watchdog", daemon=True).start()
    values = _values
    conn.send(("ready", os.getpid()))
    while True:
        try:
            message = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):       # the parent closed the pipe (close) or is gone
            return
        if message[0] == "drop":
            for key in message[1]:
                values.pop(key, None)
        elif message[0] == "task":
            _, task, payload, new, drops = message
            reply = _run_task(task, payload, new, drops, values)
            try:
                conn.send_bytes(reply)
            except OSError:               # the parent is gone
                return


def _watch_parent(parent_pid: int) -> None:
    """Exit this worker at once when its parent process is gone (it was re-parented)."""
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def _run_task(task: int, payload: bytes, new: list[tuple[int, bytes]], drops: list[int],
              values: dict[int, Any]) -> bytes:
    """Run one task; the pickled reply ``("done", task, ok, result or (error, traceback))``."""
    for key in drops:
        values.pop(key, None)
    try:
        for key, data in new:
            values[key] = pickle.loads(data)
        fn, batch, keys = pickle.loads(payload)
        result = fn(batch, *(values[key] for key in keys))
    except BaseException as error:  # a bug in fn (even SystemExit), reported to the parent
        return pickle.dumps(("done", task, False, _portable(error)), _PICKLE)
    try:
        return pickle.dumps(("done", task, True, result), _PICKLE)
    except Exception as error:
        return pickle.dumps(("done", task, False, _portable(error)), _PICKLE)


def _portable(error: BaseException) -> tuple[BaseException, str]:
    """The exception, or a RuntimeError standing for it if it does not survive pickling, and its traceback."""
    tb = "".join(traceback.format_exception(error))
    try:
        pickle.loads(pickle.dumps(error, _PICKLE))
    except Exception:
        error = RuntimeError(f"{type(error).__qualname__}: {error} (the exception could not be pickled)")
    return error, tb


# ---------------------------------------------------------------------- the parent's records
@dataclass(eq=False)
class _Task:
    id: int
    payload: bytes                         # pickled (fn, batch, shared keys)
    keys: tuple[int, ...]
    failures: int = 0                      # times its worker died under it
    worker: _Worker | None = None          # running there (None: queued)


@dataclass(eq=False)
class _Worker:
    process: BaseProcess
    conn: Connection
    ready: bool = False                    # it has said "ready": it is reading its pipe
    task: _Task | None = None
    held: set[int] = field(default_factory=set)     # shared keys it has received
    drops: set[int] = field(default_factory=set)    # released keys to tell it about with its next task
    early: list[bytes] = field(default_factory=list)  # messages waiting for its "ready"


@dataclass(eq=False)
class _Value:
    data: bytes                            # pickled once, by share
    users: int = 0                         # unfinished tasks that need it
    released: bool = False


class ProcessExecutor(ExecutorMixin):
    """Runs tasks on ``num_workers`` spawned worker processes (module doc)."""

    def __init__(self, num_workers: int | None = None, max_retries: int = 3, niceness: int = 0) -> None:
        super().__init__()
        if max_retries < 0:
            raise ValueError("max_retries must be >= 0")
        if niceness < 0:
            raise ValueError("niceness must be >= 0 (it lowers the workers' priority)")
        if num_workers is not None and num_workers < 1:
            raise ValueError("num_workers must be >= 1")
        self.num_workers = num_workers or os.cpu_count() or 1
        self.capacity = IN_FLIGHT_PER_WORKER * self.num_workers
        self.max_retries = max_retries
        self.niceness = niceness
        self._context = multiprocessing.get_context("spawn")
        self._lock = threading.RLock()
        self._slots: list[_Worker | None] = [None] * self.num_workers
        self._tasks: dict[int, _Task] = {}       # submitted and unfinished (queued or running)
        self._queue: deque[_Task] = deque()
        self._done: list[Done] = []              # finished, not yet returned by poll
        self._values: dict[int, _Value] = {}
        self._dying: list[BaseProcess] = []      # killed or dead, not yet reaped
        self._ids = 0
        self._closed = False
        self._wake_r, self._wake_w = self._context.Pipe(duplex=False)
        self._waiting = False                    # a poll is waiting (wake it on submit / cancel / close)

    # ------------------------------------------------------------------ the interface
    def share(self, value: Any) -> Shared:
        """Pickle ``value`` once; it goes to each worker process with the first task there that needs it."""
        data = pickle.dumps(value, _PICKLE)
        handle = Shared.new(None)
        with self._lock:
            self._values[handle.key] = _Value(data)
        return handle

    def release(self, shared: Shared) -> None:
        with self._lock:
            value = self._values.get(shared.key)
            if value is not None and not value.released:
                value.released = True
                if value.users == 0:
                    self._free(shared.key)

    def submit(self, fn: Callable[..., Any], batch: Any, *shared: Shared, again: int = 0) -> int:
        """Queue ``fn(batch, *shared values)``; start it on an idle worker if there is one. Never blocks
        (``fn`` and ``batch`` are pickled here: an unpicklable one raises here)."""
        keys = tuple(handle.key for handle in shared)
        payload = pickle.dumps((fn, batch, keys), _PICKLE)
        with self._lock:
            if self._closed:
                raise RuntimeError("the executor is closed")
            for handle in shared:
                value = self._values.get(handle.key)
                if value is None or value.released:
                    raise ValueError(f"unknown or released shared handle {handle!r}")
            for key in keys:
                self._values[key].users += 1
            self._ids += 1
            task = _Task(self._ids, payload, keys)
            self._tasks[task.id] = task
            self._queue.append(task)
            self._dispatch()
            self._wake()
            return task.id

    def poll(self, timeout: float) -> list[Done]:
        deadline = time.monotonic() + max(0.0, timeout)
        while True:
            with self._lock:
                self._reap()
                if self._done or not self._tasks:
                    done, self._done = self._done, []
                    return done
                watched: dict[Any, _Worker] = {}
                for worker in self._slots:
                    if worker is not None:
                        watched[worker.conn] = worker
                        watched[worker.process.sentinel] = worker
                self._waiting = True
            try:
                ready = wait([*watched, self._wake_r], max(0.0, deadline - time.monotonic()))
            except (OSError, ValueError):      # a pipe closed under us by cancel or close: look again
                ready = []
            with self._lock:
                self._waiting = False
                if self._wake_r in ready:
                    while self._wake_r.poll():
                        self._wake_r.recv_bytes()
                for worker in {id(watched[obj]): watched[obj] for obj in ready if obj in watched}.values():
                    if worker in self._slots:
                        self._read(worker, died=worker.process.sentinel in ready)
                self._dispatch()
                if self._done or not self._tasks or time.monotonic() >= deadline:
                    done, self._done = self._done, []
                    return done

    def cancel(self, tasks: Iterable[int]) -> None:
        """Queued: dropped. Running: its worker is SIGKILLed (a replacement starts when there is work)."""
        with self._lock:
            dropped: set[int] = set()
            for task_id in tasks:
                task = self._tasks.get(task_id)
                if task is None:
                    continue
                worker = task.worker
                if worker is not None:
                    worker.task, task.worker = None, None
                    self._remove(worker, kill=True)
                else:
                    dropped.add(task.id)
                self._finish(task, cancelled=True)
            if dropped:
                self._queue = deque(task for task in self._queue if task.id not in dropped)
            self._dispatch()
            self._wake()

    def in_flight(self) -> int:
        with self._lock:
            return len(self._tasks) + len(self._done)

    def close(self) -> None:
        """Cancel every task, stop every worker: idle ones exit on their own, the others are killed."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            for task in list(self._tasks.values()):
                task.worker = None
                self._finish(task, cancelled=True)
            self._queue.clear()
            self._values.clear()
            for worker in self._slots:
                if worker is not None:
                    busy, worker.task = worker.task is not None or not worker.ready, None
                    self._remove(worker, kill=busy)
            processes, self._dying = self._dying, []
            self._wake()
        deadline = time.monotonic() + STOP_GRACE_S
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
        for process in processes:
            if process.exitcode is None:
                process.kill()
                process.join(1.0)
            if process.exitcode is not None:
                process.close()

    def worker_pids(self) -> list[int]:
        """The pids of the worker processes running now (for tests and diagnostics)."""
        with self._lock:
            return [w.process.pid for w in self._slots if w is not None and w.process.pid is not None]

    # ------------------------------------------------------------------ internals (under the lock)
    def _dispatch(self) -> None:
        """Give queued tasks to idle workers, starting workers in empty slots."""
        while self._queue and not self._closed:
            worker = next((w for w in self._slots if w is not None and w.task is None), None)
            if worker is None:
                if None not in self._slots:
                    return
                worker = self._start_worker(self._slots.index(None))
            task = self._queue.popleft()
            task.worker, worker.task = worker, task
            new = [(key, self._values[key].data) for key in task.keys if key not in worker.held]
            worker.held.update(task.keys)
            drops, worker.drops = sorted(worker.drops), set()
            self._send(worker, ("task", task.id, task.payload, new, drops))

    def _start_worker(self, slot: int) -> _Worker:
        parent_conn, child_conn = self._context.Pipe(duplex=True)
        process = self._context.Process(
            target=_worker_main, args=(child_conn, os.getpid(), self.niceness),
            name=f"finaldrive-worker-{slot}", daemon=True,
        )
        process.start()
        child_conn.close()
        worker = _Worker(process, parent_conn)
        self._slots[slot] = worker
        return worker

    def _send(self, worker: _Worker, message: tuple[Any, ...]) -> None:
        data = pickle.dumps(message, _PICKLE)
        if worker.early or (not worker.ready and len(data) > EARLY_SEND_BYTES):
            worker.early.append(data)     # sent when it says "ready"
            return
        with contextlib.suppress(OSError):  # it died: poll sees its sentinel and retries its task
            worker.conn.send_bytes(data)

    def _read(self, worker: _Worker, died: bool) -> None:
        """Take every message the worker has sent; then, if it is gone, replace it."""
        try:
            while worker.conn.poll():
                data = worker.conn.recv_bytes()
                try:
                    message = pickle.loads(data)
                except Exception as error:     # a result that cannot be unpickled here
                    message = ("done", worker.task.id if worker.task else 0, False, (error, ""))
                self._on_message(worker, message)
        except (EOFError, OSError):
            died = True
        if died:
            task, worker.task = worker.task, None
            self._remove(worker, kill=False)
            if task is not None:
                task.worker = None
                task.failures += 1
                if task.failures > self.max_retries:
                    self._finish(task, lost=True)
                else:
                    self._queue.appendleft(task)

    def _on_message(self, worker: _Worker, message: tuple[Any, ...]) -> None:
        if message[0] == "ready":
            worker.ready = True
            early, worker.early = worker.early, []
            for data in early:
                try:
                    worker.conn.send_bytes(data)
                except OSError:
                    break
        elif message[0] == "done":
            _, task_id, ok, payload = message
            task = worker.task
            if task is None or task.id != task_id:
                return
            worker.task, task.worker = None, None
            if ok:
                self._finish(task, result=payload)
            else:
                error, tb = payload
                if tb:
                    error.__cause__ = RemoteTraceback(tb)
                self._finish(task, error=error)

    def _finish(self, task: _Task, **outcome: Any) -> None:
        del self._tasks[task.id]
        self._done.append(Done(task.id, **outcome))
        for key in task.keys:
            value = self._values.get(key)
            if value is not None:
                value.users -= 1
                if value.released and value.users == 0:
                    self._free(key)

    def _free(self, key: int) -> None:
        """Forget a released value; tell the workers holding it (idle ones now, busy ones with their next task)."""
        del self._values[key]
        for worker in self._slots:
            if worker is not None and key in worker.held:
                worker.held.discard(key)
                if worker.ready and worker.task is None and not worker.early:
                    self._send(worker, ("drop", [key]))
                else:
                    worker.drops.add(key)

    def _remove(self, worker: _Worker, *, kill: bool) -> None:
        """Take a worker out of its slot (killing it first if asked); it is reaped later."""
        if kill and worker.process.exitcode is None:
            worker.process.kill()
        self._slots[self._slots.index(worker)] = None
        worker.conn.close()
        self._dying.append(worker.process)

    def _reap(self) -> None:
        alive = []
        for process in self._dying:
            if process.exitcode is None:
                alive.append(process)
            else:
                process.close()
        self._dying = alive

    def _wake(self) -> None:
        if self._waiting:
            self._waiting = False
            self._wake_w.send_bytes(b"")
