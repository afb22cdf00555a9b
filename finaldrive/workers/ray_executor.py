"""Ray executor: the only module that imports Ray.

Local by default (``ray.init(address="local")`` with ``num_workers`` CPUs); joins an existing
cluster when ``address`` or ``RAY_ADDRESS`` is set. If Ray is already initialised in this
process, the executor uses that session and leaves it running on ``close()`` (after cancelling
its own tasks).

The interface (``workers/base.py``): ``share`` is one ``ray.put``; ``submit`` one call of the
remote function ``_run_task``, with ``max_retries`` for worker loss and ``retry_exceptions=False``;
``poll`` takes the results that Ray's completion callbacks have queued (``ObjectRef.future()``:
O(1) a finished task, where ``ray.wait`` cost O(tasks in flight) a call); ``cancel`` is
``ray.cancel(force=True)``, which drops a queued task and kills the worker process of a running
one (Ray starts another when needed); a ``TaskCancelledError`` means cancelled, and Ray's
worker-loss errors after the retries mean ``lost``. On a cluster of more than ``base.TASK_SLOTS``
CPUs a task holds several (``task_cpus``, ``base.task_width``; its designs run on as many threads),
so that ``num_workers`` tasks run at once; ``capacity`` is 2 x that, both read again every
``CAPACITY_REFRESH_S`` by ``poll``. Ray runs its workers in process groups of their
own with SIGINT blocked (a terminal's Ctrl-C reaches only the driver), at its own worker
niceness (``RAY_worker_niceness``, 15 by default); ``niceness`` is added to that, once per worker
process (the OS caps it at 19).

What ``ray.init`` changes in this process, and what the executor does about it (Ray 2.60):

- **Token authentication.** A local start turns token authentication on (it sets
  ``RAY_AUTH_MODE=token`` in ``os.environ``) and, unless a token is found in
  ``RAY_AUTH_TOKEN``, ``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``, writes a new one to
  ``~/.ray/auth_token``. A local Ray listens on every interface, so authentication stays on,
  but the executor gives the local Ray a random token of its own in ``RAY_AUTH_TOKEN`` (this
  process and the Ray processes it starts inherit it), so nothing is written to the user's
  home. A token the user set (``RAY_AUTH_TOKEN`` or ``RAY_AUTH_TOKEN_PATH``), or
  ``RAY_AUTH_MODE=disabled``, is respected. Joining a cluster is left to Ray. ``close()``
  restores ``RAY_AUTH_MODE`` and ``RAY_AUTH_TOKEN`` so the settings do not outlive the executor.
- **Signals.** The driver's C++ core worker installs Abseil's failure-signal handler, which
  counts SIGTERM as a failure: every SIGTERM (how services are normally stopped) printed a
  ``*** SIGTERM received ...`` stack dump before the process's own handler ran. The executor
  gives SIGTERM back to the handler it had before (in the main thread: the Python handler that
  ``ray.init`` registers, which raises ``SystemExit``), and keeps Ray's handler for real
  crashes (SIGSEGV, SIGABRT, ...). ``ray.shutdown()`` resets those signals to ``SIG_DFL``;
  ``close()`` puts back what they were before ``ray.init`` (e.g. ``faulthandler``).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import importlib
import logging
import os
import secrets
import signal
import socket
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from functools import partial
from typing import Any

import ray
from ray.exceptions import (
    LocalRayletDiedError,
    NodeDiedError,
    ObjectLostError,
    OutOfMemoryError,
    TaskCancelledError,
    WorkerCrashedError,
)
from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

from finaldrive.workers.base import IN_FLIGHT_PER_WORKER, Done, ExecutorMixin, Shared, task_width
from finaldrive.workers.cluster import ClusterTaken, check_on_cluster
from finaldrive.workers.task import hold_cpus

#: How often ``poll`` reads the cluster's CPUs again (``num_workers``, ``capacity``) [s].
CAPACITY_REFRESH_S = 5.0
#: The longest single wait in ``poll`` [s] (a cancel from another thread also wakes it).
POLL_SLICE_S = 0.2

#: The named actor that marks a cluster's one finaldrive driver (``exclusive``): name, namespace.
DRIVER_ACTOR = ("finaldrive-driver", "finaldrive")
#: How often a standby looks whether the cluster's driver has gone [s] (Ray frees the name ~1-2 s
#: after the driver's process dies, measured with SIGKILL on Ray 2.60).
STANDBY_POLL_S = 1.0

#: Copies of overdue tasks (``submit(again=k)``) go to nodes that returned a result within this long [s]
#: (if any did), in order of their last result: a dead node's last is older.
ANSWERED_S = 3.0
#: For this long after a copy or a lost task, every task goes to such nodes in turn [s] (Ray's death detection of
#: a node takes ~15 s: health checks every 3 s, 5 failures).
SUSPECT_S = 20.0

#: Environment variables ``ray.init`` reads or sets for token authentication; restored on close.
_AUTH_ENV = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN")

#: Ray errors that mean the task's worker (or node, or its result) was lost after all retries.
_WORKER_LOSS = (WorkerCrashedError, NodeDiedError, OutOfMemoryError, LocalRayletDiedError, ObjectLostError)

#: Signals whose handlers Ray's failure-signal handler (Abseil) takes over in ``ray.init``.
_FAILURE_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGSEGV", "SIGILL", "SIGFPE", "SIGABRT", "SIGBUS", "SIGTRAP")
    if hasattr(signal, name)
)
_SIGACTION_BYTES = 512   # more than any libc's struct sigaction; copied as opaque bytes


def _libc() -> Any:
    if sys.platform == "win32":
        return None
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


class _Signals:
    """The process's signal handlers around Ray: no stack dump on SIGTERM, and undo ``ray.shutdown()``'s reset.

    Handlers are read and written with libc's ``sigaction`` (the struct copied as opaque bytes),
    because ``signal.signal`` works only in the main thread and the service starts Ray in
    another one. On Windows (no ``sigaction``) only the main-thread path applies.
    """

    def __init__(self) -> None:
        self._libc = _libc()
        self._main_thread = threading.current_thread() is threading.main_thread()
        self._before = self._read()                          # before ray.init
        self._python_sigterm = signal.getsignal(signal.SIGTERM)
        self._ray_python_sigterm: Any = None                 # the handler ray.init registered, if any
        self._ray_handlers: dict[int, int] = {}              # the C handlers ray.init installed
        self._init_done = False

    def _read(self) -> dict[int, Any]:
        actions = {}
        for signum in _FAILURE_SIGNALS if self._libc is not None else ():
            action = ctypes.create_string_buffer(_SIGACTION_BYTES)
            if self._libc.sigaction(int(signum), None, action) == 0:
                actions[int(signum)] = action
        return actions

    def _write(self, signum: int, action: Any) -> None:
        if action is not None:
            self._libc.sigaction(signum, action, None)

    @staticmethod
    def _handler(action: Any) -> int:
        return int(ctypes.c_void_p.from_buffer(action).value or 0)

    def after_init(self) -> None:
        """Give SIGTERM back to Python's handler; Ray keeps the crash signals (SIGSEGV, ...)."""
        sigterm = int(signal.SIGTERM)
        handler = signal.getsignal(signal.SIGTERM)
        if self._main_thread and handler is not None and handler is not self._python_sigterm:
            signal.signal(signal.SIGTERM, handler)           # ray.init's handler (SystemExit), not Abseil's
            self._ray_python_sigterm = handler
        else:
            self._write(sigterm, self._before.get(sigterm))  # ray.init left the Python handler alone
        self._ray_handlers = {
            signum: self._handler(action) for signum, action in self._read().items()
            if signum != sigterm and signum in self._before
            and self._handler(action) != self._handler(self._before[signum])
        }
        self._init_done = True

    def before_shutdown(self) -> dict[int, Any]:
        return self._read()

    def after_shutdown(self, before_shutdown: dict[int, Any]) -> None:
        """Put back what ``ray.shutdown()`` reset to ``SIG_DFL``: Ray's handlers by the earlier ones.

        After a failed ``ray.init`` (``after_init`` never ran), every handler goes back.
        """
        for signum, action in before_shutdown.items():
            by_ray = not self._init_done or self._ray_handlers.get(signum) == self._handler(action)
            self._write(signum, self._before.get(signum) if by_ray else action)
        if self._python_sigterm is None or threading.current_thread() is not threading.main_thread():
            return
        current = signal.getsignal(signal.SIGTERM)
        if self._init_done:
            by_ray = self._ray_python_sigterm is not None and current is self._ray_python_sigterm
        else:
            by_ray = current is not self._python_sigterm
        if by_ray:
            signal.signal(signal.SIGTERM, self._python_sigterm)


def _reload_auth(config: bool = True) -> None:
    """Make Ray in this process read ``RAY_AUTH_MODE`` (``config``) and the token from the environment again.

    Ray caches both: the mode in its C++ config, the token once it has loaded one. ``ray.init``
    refreshes the config itself when it turns token authentication on (``Config.initialize``),
    but not when the mode goes back, so without this a later ``ray.init`` in this process
    would still ask for a token.
    """
    raylet: Any = ray._raylet                # compiled; its stubs omit these names
    if not hasattr(raylet, "AuthenticationTokenLoader"):   # a Ray without token authentication
        return
    if config:
        raylet.Config.initialize("")
    raylet.AuthenticationTokenLoader.instance().reset_cache()


#: In a Ray worker process: the niceness ``_run_task`` has added to it (``os.nice``, once per process).
_nice_added = 0


def _outcome(future: concurrent.futures.Future[Any]) -> dict[str, Any]:
    """A finished task's outcome (``Done``'s fields): its result, or how it ended (a result comes with
    its node's id, ``_run_task``)."""
    error = future.exception()
    if error is None:
        return {"result": future.result()[1]}
    if isinstance(error, TaskCancelledError):
        return {"cancelled": True}
    if isinstance(error, _WORKER_LOSS):
        return {"lost": True}
    return {"error": error}                    # fn raised: a RayTaskError, also an instance of fn's error


class _Driver:
    """Held by a cluster's one finaldrive driver; not detached, so Ray ends it with its driver."""

    def __init__(self, who: str) -> None:
        self.who = who

    def describe(self) -> str:
        return self.who


_DRIVER: Any = ray.remote(num_cpus=0, max_restarts=0)(_Driver)


def _take_cluster(standby: threading.Event | None) -> Any:
    """The cluster's driver actor, created here; if another driver holds it: ``ClusterTaken`` at once
    (``standby`` None), else wait as a standby, logging once, until it is free (or ``standby`` is set:
    then ``ClusterTaken``)."""
    who = f"host {socket.gethostname()}, pid {os.getpid()}, since {time.strftime('%Y-%m-%d %H:%M:%S %Z')}"
    name, namespace = DRIVER_ACTOR
    told = False
    while True:
        try:
            return _DRIVER.options(name=name, namespace=namespace).remote(who)
        except ValueError:   # the name is taken (ActorAlreadyExistsError on Ray 2.60)
            pass
        try:
            actor: Any = ray.get_actor(name, namespace=namespace)
            holder = str(ray.get(actor.describe.remote(), timeout=10))
        except Exception:    # it ended meanwhile: try again
            continue
        message = (f"another finaldrive scheduler drives this Ray cluster ({holder}): one scheduler per Ray "
                   "cluster, as two evict each other's Ray workers; run more schedulers on other Ray clusters")
        if standby is None or standby.is_set():
            raise ClusterTaken(message)
        if not told:
            logging.getLogger(__name__).warning("%s; waiting as a standby, to take over when it stops", message)
            told = True
        if standby.wait(STANDBY_POLL_S):
            raise ClusterTaken(message)


def _run_task(niceness: int, cpus: int, fn: Callable[..., Any], batch: Any, *shared: Any) -> tuple[str, Any]:
    """The one remote function: lower this worker's priority to ``niceness`` (once), run ``fn`` holding
    ``cpus`` CPUs (``workers.task.task_cpus``); returns (this node's id, ``fn``'s result)."""
    global _nice_added
    if niceness > _nice_added:
        os.nice(niceness - _nice_added)
        _nice_added = niceness
    hold_cpus(cpus)
    return ray.get_runtime_context().get_node_id(), fn(batch, *shared)


_RUN: Any = ray.remote(_run_task)
#: The same, for the copies of overdue tasks (``submit(again=k)``, placed by ``RayExecutor._place``): a
#: function of its own is a scheduling class of its own, so Ray leases a copy a worker afresh rather
#: than queueing it on the worker of the task it stands in for (which may be on a dead node).
_RUN_AGAIN: Any = ray.remote(_run_task)


class RayExecutor(ExecutorMixin):
    """One Ray task per ``submit``, with ``max_retries`` for worker loss; shared values ``ray.put`` once.

    ``cancel`` uses ``ray.cancel(force=True)``: a queued task is dropped, a running one's worker
    process is killed (Ray starts another when needed). A task holds ``task_cpus`` CPUs;
    ``num_workers`` (tasks at once) and ``capacity`` (2 x that) are read again every
    ``CAPACITY_REFRESH_S`` by ``poll``, so nodes that join get work.
    """

    def __init__(
        self, num_workers: int | None = None, max_retries: int = 3, address: str | None = None, niceness: int = 0,
        exclusive: bool = False, standby: threading.Event | None = None, task_cpus: int | None = None,
    ) -> None:
        """``num_workers``: the CPUs of a local Ray, or of a cluster's to use. ``exclusive``: when
        joining a cluster, be its one finaldrive driver (:func:`_take_cluster`): raise
        ``ClusterTaken`` if another holds it, or with ``standby``, wait until it is free or
        ``standby`` is set. ``task_cpus``: CPUs each task holds (default: ``base.task_width``'s rule)."""
        super().__init__()
        if max_retries < 0:
            raise ValueError("max_retries must be >= 0")
        if niceness < 0:
            raise ValueError("niceness must be >= 0 (it lowers the workers' priority)")
        if num_workers is not None and num_workers < 1:
            raise ValueError("num_workers must be >= 1")
        if task_cpus is not None and task_cpus < 1:
            raise ValueError("task_cpus must be >= 1")
        self.max_retries = max_retries
        self.niceness = niceness
        self._started = not ray.is_initialized()
        #: Whether this executor started a Ray of its own on this machine (not a cluster's, nor the caller's).
        self.local = False
        self._env_before = {name: os.environ.get(name) for name in _AUTH_ENV}
        self._signals: _Signals | None = None
        self._driver: Any = None   # the cluster's driver actor, while this executor holds it
        if self._started:
            address = address or os.environ.get("RAY_ADDRESS") or None
            options: dict[str, Any] = {
                "include_dashboard": False, "ignore_reinit_error": True, "log_to_driver": False,
            }
            self._signals = _Signals()
            try:
                if address:
                    check_on_cluster(address)   # at once, not Ray's ConnectionError after 60 s
                    ray.init(address=address, **options)
                else:
                    self._use_own_token()
                    ray.init(address="local", num_cpus=num_workers or os.cpu_count() or 1, **options)
                    self.local = True
            except BaseException:
                self._undo_init()
                self._started = False
                raise
            self._signals.after_init()
            with contextlib.suppress(ImportError):   # ray.shutdown() imports it: take the 0.1 s now, not in close()
                importlib.import_module("ray.dag.compiled_dag_node")
            if exclusive and not self.local:
                try:
                    self._driver = _take_cluster(standby)   # after after_init: a SIGTERM meanwhile stops it cleanly
                except BaseException:
                    self._undo_init()
                    self._started = False
                    raise
        self._fixed_workers = num_workers
        self._fixed_width = task_cpus
        #: CPUs each task holds (its designs run on as many threads); ``num_workers`` tasks run at once.
        self.task_cpus = 1
        self.num_workers = self.capacity = 0
        self._task: Any = None
        try:
            self._size()
        except BaseException:   # a width no node has: leave nothing of ours behind
            if self._started:
                self._undo_init()
                self._started = False
            raise
        self._capacity_at = time.monotonic()
        self._answered: dict[str, float] = {}   # node id -> when a task of it last returned a result
        self._suspect_until = 0.0                # placing every task on answering nodes until then (_place)
        self._nodes: set[str] = set()            # the cluster's nodes with CPUs, read while suspecting
        self._turn = 0
        self._lock = threading.RLock()
        self._ids = 0
        self._refs: dict[ray.ObjectRef[Any], int] = {}     # in flight: result ref -> task id
        self._by_task: dict[int, ray.ObjectRef[Any]] = {}
        self._done: list[Done] = []
        self._arrived = threading.Condition(threading.Lock())  # guards _ready; Ray's callbacks notify it
        self._ready: deque[tuple[int, concurrent.futures.Future[Any]]] = deque()  # finished, not yet polled
        self._shared: dict[int, ray.ObjectRef[Any]] = {}   # live handles (the executor holds the only ref)
        self._closed = False

    def _size(self) -> None:
        """Task width and tasks at once from the cluster's nodes (a local Ray is one node), using
        ``num_workers`` CPUs of them if set; ``capacity`` is 2 tasks a slot."""
        if self.local:
            nodes = [self._fixed_workers or self._cluster_cpus()]
        else:
            nodes = [int(node["Resources"].get("CPU", 0)) for node in ray.nodes()  # type: ignore[no-untyped-call]
                     if node["Alive"]] or [self._cluster_cpus()]
        width, slots = task_width(nodes, self._fixed_width, cpus=self._fixed_workers)
        task = self._task if width == self.task_cpus and self._task is not None else \
            _RUN.options(max_retries=self.max_retries, retry_exceptions=False, num_cpus=width)
        self._task, self.task_cpus = task, width
        self.num_workers, self.capacity = slots, IN_FLIGHT_PER_WORKER * slots

    @staticmethod
    def _cluster_cpus() -> int:
        return max(1, int(ray.cluster_resources().get("CPU", 1)))  # type: ignore[no-untyped-call]

    def share(self, value: Any) -> Shared:
        """``ray.put`` once; the object is freed after ``release`` and the tasks using it."""
        ref = ray.put(value)
        handle = Shared.new(None)
        with self._lock:
            self._shared[handle.key] = ref
        return handle

    def release(self, shared: Shared) -> None:
        with self._lock:
            self._shared.pop(shared.key, None)   # tasks in flight keep their own references

    def submit(self, fn: Callable[..., Any], batch: Any, *shared: Shared, again: int = 0) -> int:
        with self._lock:
            if self._closed:
                raise RuntimeError("the executor is closed")
            try:
                refs = [self._shared[handle.key] for handle in shared]
            except KeyError:
                raise ValueError("unknown or released shared handle") from None
            task = self._place(again)
            ref = task.remote(self.niceness, self.task_cpus, fn, batch, *refs)
            self._ids += 1
            self._refs[ref] = self._ids
            self._by_task[self._ids] = ref
            ref.future().add_done_callback(partial(self._arrive, self._ids))
            return self._ids

    def _place(self, again: int) -> Any:
        """The remote function to call, placed. The k-th copy of an overdue task (``again``) goes to the
        node that returned a result k-th most recently among those that did within ``ANSWERED_S``;
        for ``SUSPECT_S`` after a copy or a task lost with its worker (a node may be dead: Ray still
        places tasks there until it declares it dead) every task goes to those nodes, and to those
        that joined and have not answered yet, in turn."""
        now = time.monotonic()
        if again:
            self._suspect_until = now + SUSPECT_S
        elif now >= self._suspect_until:
            return self._task
        nodes = sorted(self._answered, key=self._answered.__getitem__, reverse=True)
        nodes = [node for node in nodes if self._answered[node] >= now - ANSWERED_S] or nodes
        nodes += sorted(self._nodes.difference(self._answered))   # joined, and not yet answered
        options = {"max_retries": self.max_retries, "retry_exceptions": False, "num_cpus": self.task_cpus}
        if not nodes:
            return _RUN_AGAIN.options(**options) if again else self._task
        self._turn += 1
        node = nodes[(again - 1) % len(nodes)] if again else nodes[self._turn % len(nodes)]
        return (_RUN_AGAIN if again else _RUN).options(
            **options, scheduling_strategy=NodeAffinitySchedulingStrategy(node_id=node, soft=True))

    def _arrive(self, task: int, future: concurrent.futures.Future[Any]) -> None:
        """Ray's completion callback (its own thread, or ``submit``'s if already done): queue the task."""
        with self._arrived:
            self._ready.append((task, future))
            self._arrived.notify()

    def poll(self, timeout: float) -> list[Done]:
        """The tasks finished since the last poll (waiting up to ``timeout`` s for one, in slices of
        ``POLL_SLICE_S``): O(1) a finished task, whatever the number in flight."""
        deadline = time.monotonic() + max(0.0, timeout)
        while True:
            self._refresh_capacity()
            with self._lock:
                if self._done or not self._refs:
                    done, self._done = self._done, []
                    if not self._refs:
                        with self._arrived:  # only cancelled tasks' results can wait there: let them go
                            self._ready.clear()
                    return done
            with self._arrived:
                if not self._ready:
                    self._arrived.wait(min(POLL_SLICE_S, max(0.0, deadline - time.monotonic())))
                ready, self._ready = self._ready, deque()
            with self._lock:
                for task, future in ready:
                    ref = self._by_task.pop(task, None)
                    if ref is not None:               # else: cancelled meanwhile, and reported so
                        del self._refs[ref]
                        outcome = _outcome(future)
                        self._done.append(Done(task, **outcome))
                        if "result" in outcome:
                            self._answered[future.result()[0]] = time.monotonic()
                        elif outcome.get("lost"):   # a node may be dead (Ray 2.40 spends the retries there at once)
                            self._suspect_until = time.monotonic() + SUSPECT_S
                if self._done or not self._refs or time.monotonic() >= deadline:
                    done, self._done = self._done, []
                    return done

    def _refresh_capacity(self) -> None:
        if self._closed or time.monotonic() - self._capacity_at < CAPACITY_REFRESH_S:
            return
        self._capacity_at = time.monotonic()
        with self._lock, contextlib.suppress(ValueError):   # no node left has task_cpus: keep the last size
            self._size()                                     # (under the lock: a submit sees one width)
        if self._suspect_until > self._capacity_at:   # which nodes joined, for _place
            with contextlib.suppress(Exception):
                self._nodes = {node["NodeID"] for node in ray.nodes()  # type: ignore[no-untyped-call]
                               if node["Alive"] and node["Resources"].get("CPU", 0) > 0}

    def cancel(self, tasks: Iterable[int]) -> None:
        """``ray.cancel(force=True)``: a queued task is dropped, a running one's worker killed."""
        with self._lock:
            for task in tasks:
                ref = self._by_task.pop(task, None)
                if ref is None:
                    continue
                del self._refs[ref]
                self._cancel(ref)
                self._done.append(Done(task, cancelled=True))
        with self._arrived:
            self._arrived.notify_all()             # a poll waiting in another thread reports it now

    @staticmethod
    def _cancel(ref: ray.ObjectRef[Any]) -> None:
        with contextlib.suppress(Exception):       # finished already, or Ray is gone
            ray.cancel(ref, force=True)

    def in_flight(self) -> int:
        with self._lock:
            return len(self._refs) + len(self._done)

    def _use_own_token(self) -> None:
        """A local Ray gets a random token in ``RAY_AUTH_TOKEN``, so Ray writes none to ``~/.ray``."""
        if os.environ.get("RAY_AUTH_MODE", "").lower() == "disabled":
            return
        if os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH"):
            return                                   # the user's token
        os.environ["RAY_AUTH_TOKEN"] = secrets.token_hex(32)
        _reload_auth(config=False)                   # a token cached by an earlier session in this process

    def _undo_init(self) -> None:
        """Restore the environment and the signal handlers that ``ray.init`` changed."""
        before_shutdown = self._signals.before_shutdown() if self._signals is not None else {}
        if ray.is_initialized():
            ray.shutdown()
        if self._signals is not None:
            self._signals.after_shutdown(before_shutdown)
        if any(os.environ.get(name) != value for name, value in self._env_before.items()):
            for name, value in self._env_before.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value
            _reload_auth()

    def close(self) -> None:
        """Cancel every task in flight (their workers are killed), then shut Ray down if this
        executor started it; idempotent."""
        with self._lock:
            if not self._closed:
                self._closed = True
                self.cancel(list(self._by_task))
                self._shared.clear()
        if self._started:
            self._undo_init()
        self._started = False
