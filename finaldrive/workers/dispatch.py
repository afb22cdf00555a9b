"""Keeping an executor full: the independent work of many sources, in batches, shared fairly.

A source of work (:class:`Work`: a job of the service, or a study run from the command line)
holds requests that are ready to simulate, each designs on one road (the study layer's
:class:`~finaldrive.engine.Request`). The :class:`Dispatcher` cuts them into batches and keeps
the executor full, taking one batch from each source with ready work in turn, so concurrent jobs
share the executor fairly and none waits for another's request to end. Results go back to their
source as each batch completes, in any order.

Latency where it matters: within a source the **smallest request goes first**. A DE generation
(tens of designs, the next one waits for it) thus overtakes a sweep's road (thousands, which
nothing waits for), and the sweep fills the CPUs the generations leave idle. For the same reason
only about 50 ms of work beyond one task a worker is kept in flight (:func:`in_flight_limit`):
executors start tasks first-in first-out, and a deep queue of long tasks would hold every
generation behind it.

Batch sizes adapt per source (:mod:`finaldrive.workers.batching`): a source's estimates of
per-design time and per-task overhead last as long as the source, not one request. A request
smaller than the batch size shares its task with the next smallest ones that fit whole (a few DE
generations in one task rather than a task each).

A batch whose task raised, or whose worker was lost for good, is tried again one design a
task, so only the design at fault fails (``on_failure``), never its neighbours in the batch.

A task that runs far longer than its designs should take is run again as a copy, and again if
that copy is overdue too, up to :data:`MAX_COPIES` copies a task (first copies: as many a worker in
flight): whichever returns first is delivered, the others' results are dropped. A node that died
(SIGKILLed: Ray takes ~15 s to declare it dead and retry its tasks) or one still compiling the
engine then holds no DE generation for longer than that (issue 30). Overdue means: running (its
clock starts once as many tasks have returned as were queued ahead of it: executors start tasks
first in, first out) for longer than :data:`HEDGE_AFTER` times its designs' expected time (the
source's measured time a design), at least :data:`HEDGE_MIN_S`, with the expected time scaled by
the *pace* of the tasks that started after it and have finished (their time on the workers' own
clock over their expected time; the slowest of them). A machine or cluster slowed down as a whole
(an API under load beside the workers) slows those tasks too, and is not doubled; a dead node's
tasks stay overdue against the live nodes' pace. While no such task has finished, nothing says the
others are faster, and a task is overdue only past :data:`HEDGE_UNSEEN` times its expected time.
"""

from __future__ import annotations

import bisect
import itertools
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from finaldrive.workers.base import Executor
from finaldrive.workers.batching import BatchSizer
from finaldrive.workers.task import Timed, call_timed

if TYPE_CHECKING:
    from finaldrive.engine import BatchResult, Request

#: What a worker runs: ``task(rows, *shared)`` with rows (road index, a2, L2, R_WS) -> [(road, BatchResult)].
Task = Callable[..., list[tuple[int, "BatchResult"]]]


@dataclass(eq=False)
class Work:
    """One source of work: its ready requests, the values its tasks share, and where results go.

    ``on_result(part, results)``: a finished part of a request and its results, rows in order;
    ``on_failure(part, reason)``: the part could not be evaluated (its worker was lost, or the
    task raised); the source decides what that means (the service stores failed evaluations).
    ``paused``: while True, none of the source's requests are started (back-pressure).
    """

    key: Hashable
    shared: tuple[Any, ...]
    on_result: Callable[[Request, BatchResult], None]
    on_failure: Callable[[Request, str], None]
    queue: deque[Request] = field(default_factory=deque)
    paused: bool = False
    sizer: BatchSizer | None = None
    #: single designs of a failed batch, tried again alone (before the queue)
    alone: deque[Request] = field(default_factory=deque)
    #: the source's tasks started and not yet returned (kept by the dispatcher)
    in_flight: int = 0
    #: designs of waited-on requests in those tasks (batching rule 5 counts them with the queued ones)
    waited_in_flight: int = 0

    def next_request(self) -> tuple[int, int, int]:
        """Position in ``queue`` of the request to start next, the smallest (the first of equals);
        the designs queued that go before or with it (its requests' sizes and ``alone``; for a
        waited-on request, the waited-on ones: batching rule 5); and all designs waiting to be started."""
        sizes = [len(q) for q in self.queue]
        at = self.smallest()
        if self.queue[at].waited:  # the round: waited-on designs queued or running
            first = sum(n for n, q in zip(sizes, self.queue, strict=True) if q.waited) + self.waited_in_flight
        else:
            first = sum(n for n in sizes if n <= sizes[at]) + len(self.alone)
        return at, first, sum(sizes) + len(self.alone)

    def smallest(self) -> int:
        """Position in ``queue`` of its smallest request (the first of equals)."""
        return min(range(len(self.queue)), key=lambda i: len(self.queue[i]))


log = logging.getLogger(__name__)

#: A task is run again (a copy) once its latest copy has run this many times its designs' expected time,
#: scaled by the pace of the tasks started after it and finished ...
HEDGE_AFTER = 4.0
#: ... or, while none has, this many times ...
HEDGE_UNSEEN = 16.0
#: ... and at least this long [s] (a loaded machine's pauses stay below it), looked at this often [s] ...
HEDGE_MIN_S, HEDGE_CHECK_S = 0.5, 0.1
#: ... up to this many copies besides the first.
MAX_COPIES = 2
#: The paces of this many tasks finished last are kept (the slowest of those started after a task scales its own).
PACES_KEPT = 64

#: Work queued in the executor beyond one task a worker, in seconds of the cluster's time.
QUEUE_S = 0.05


def in_flight_limit(num_workers: int, capacity: int, task_s: float | None = None) -> int:
    """Tasks the dispatcher keeps in flight: one a worker, plus a queue of about :data:`QUEUE_S`
    of the cluster's work (``task_s``: a task's typical duration; unknown: an eighth of the
    workers), at least two, within the executor's capacity.

    The queue lets workers go on while the driver is busy elsewhere (storing, looking up, telling
    a DE) for up to ~50 ms; kept that short, a new DE generation waits behind at most ~50 ms of
    queued work, since executors start tasks first in, first out."""
    queued = math.ceil(num_workers / 8) if not task_s else math.ceil(num_workers * QUEUE_S / task_s)
    return max(1, min(capacity, num_workers + max(2, queued)))


@dataclass(frozen=True)
class Load:
    """What the dispatcher did over an interval (:meth:`Dispatcher.load`): tasks and designs finished a
    second, the time-weighted share of the executor's workers with a task in flight (0-1), and now:
    tasks in flight and designs waiting to be started."""

    tasks_per_s: float
    evaluations_per_s: float
    busy_share: float
    in_flight_tasks: int
    backlog_designs: int


@dataclass
class _Task:
    work: Work
    parts: tuple[Request, ...]  # consecutive in the task's rows
    handed_at: float
    start_after: int   # a worker could take it once the executor has returned this many tasks (first in, first out)
    started_at: float | None   # ... which it had by then (None: not yet)


class Dispatcher:
    """Feeds an executor from many :class:`Work` sources; one thread drives it (``step``)."""

    def __init__(self, executor: Executor, task: Task, *, warmup: Callable[..., None] | None = None,
                 batch_size: int | None = None) -> None:
        """``task`` runs in the workers (``warmup(*shared)`` once per worker process first);
        ``batch_size`` fixes the designs per task instead of adapting it."""
        self.executor = executor
        self._fn = executor.share(partial(call_timed, task, warmup))  # sent to each worker once, not per task
        self._batch_size = batch_size
        self._works: dict[Hashable, tuple[Work, tuple[Any, ...]]] = {}
        self._tasks: dict[int, _Task] = {}
        self._turn: deque[Hashable] = deque()
        self.limit = in_flight_limit(executor.num_workers, executor.capacity)
        self._task_s = 0.0  # running mean of a task's time in its worker [s]
        self._measured: BatchSizer | None = None  # the sizer that measured a task last (a new source starts from it)
        # the driving thread's own time a finished task (batching rule 4), from windows of >= 1 s
        self.driver_s = 0.0
        self._window_start = time.perf_counter()
        self._window_busy_s = 0.0
        self._window_tasks = 0
        # since the last load(): its start, tasks and designs finished, and the integral of the busy share
        self._load_start = self._busy_at = time.perf_counter()
        self._load_tasks = self._load_designs = 0
        self._busy_integral = 0.0
        self._copies: dict[int, list[int]] = {}   # a hedged task's id (and each copy's) -> all copies, in order
        self._freed = 0   # tasks the executor has returned (each freed a worker), since the start
        # the tasks finished lately: (when they started, their time on the workers over their expected time)
        self._paces: deque[tuple[float, float]] = deque(maxlen=PACES_KEPT)
        self._next_hedge = 0.0
        #: copies of overdue tasks started (HEDGE_AFTER), since the start
        self.hedged = 0

    # ------------------------------------------------------------------ sources
    def add(self, work: Work) -> None:
        if work.key in self._works:
            raise ValueError(f"work {work.key!r} is already dispatched")
        if work.sizer is None:  # from what earlier sources measured, if any (batching rule 1)
            earlier = self._measured
            work.sizer = BatchSizer.after(earlier) if earlier is not None else BatchSizer(self.executor.num_workers)
        handles = tuple(self.executor.share(value) for value in work.shared)
        self._works[work.key] = (work, handles)
        self._turn.append(work.key)

    def remove(self, key: Hashable) -> None:
        """Stop a source: its queued requests are dropped, its running tasks cancelled."""
        entry = self._works.pop(key, None)
        if entry is None:
            return
        work, handles = entry
        work.queue.clear()
        work.alone.clear()
        ids = [task_id for task_id, t in self._tasks.items() if t.work is work]
        self.executor.cancel(ids)
        for task_id in ids:
            del self._tasks[task_id]
            self._copies.pop(task_id, None)   # its copies are the same source's, so cancelled here too
        work.in_flight = 0
        work.waited_in_flight = 0
        for handle in handles:
            self.executor.release(handle)
        self._turn.remove(key)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._works

    def in_flight(self, key: Hashable | None = None) -> int:
        """Tasks started and not yet returned (of one source, or all)."""
        if key is None:
            return len(self._tasks)
        entry = self._works.get(key)
        return entry[0].in_flight if entry is not None else 0

    # ------------------------------------------------------------------ driving
    def step(self, timeout: float) -> int:
        """Start what fits, then wait up to ``timeout`` s for results and deliver them; returns
        how many tasks finished."""
        self.fill()
        self._busy()
        finished = self.collect(timeout)
        self._busy()
        self._hedge()
        self.fill()
        return finished

    def _hedge(self) -> None:
        """Start a copy of each task whose latest copy is overdue (module doc), up to ``MAX_COPIES``
        a task; first copies up to ``MAX_COPIES`` a worker in flight. A first copy may land on the dead
        node too (on CI all of a generation's four first copies did, and the cap then kept their second
        copies back for 15 s), so a task's second copy is never held back."""
        now = time.perf_counter()
        if now < self._next_hedge:
            return
        self._next_hedge = now + HEDGE_CHECK_S
        paces = sorted(self._paces)
        started = [at for at, _ in paces]
        slowest = list(itertools.accumulate(reversed([pace for _, pace in paces]), max))[::-1]   # from each on
        for task_id, task in list(self._tasks.items()):
            if task.started_at is None and self._freed >= task.start_after:
                task.started_at = now
            if task.started_at is None or now - task.started_at <= HEDGE_MIN_S:
                continue   # (most tasks: nothing more to look at)
            sizer = task.work.sizer
            copies = self._copies.get(task_id, [task_id])
            if copies[-1] != task_id or len(copies) > MAX_COPIES or sizer is None or not sizer.designs_done:
                continue
            extra = len(self._copies) - len({id(c) for c in self._copies.values()})   # copies in flight
            if extra >= MAX_COPIES * self.executor.num_workers and len(copies) == 1:
                continue   # the cap holds back first copies; a second goes on (its first may be on the dead node)
            designs = sum(len(part) for part in task.parts)
            overhead = sizer.overhead_s if math.isfinite(sizer.overhead_s) else 0.0
            expected = designs * sizer.per_design_s + overhead
            # the first finished task started after it (its clock is read every HEDGE_CHECK_S: one started in the
            # same look may have started before it)
            after_it = bisect.bisect_right(started, task.started_at)
            pace = slowest[after_it] if after_it < len(slowest) else None
            after = HEDGE_AFTER * pace if pace is not None else HEDGE_UNSEEN
            if now - task.started_at > max(HEDGE_MIN_S, after * expected):
                log.info("a task of %d designs has run %.1f s (expected %.3f s; the slowest pace of the tasks "
                         "started after it: %s): running it again", designs, now - task.started_at, expected,
                         "none finished" if pace is None else f"{pace:.1f}x")
                copy = self._submit(task.work, self._works[task.work.key][1], list(task.parts), again=len(copies))
                copies = [*copies, copy]
                for member in copies:
                    self._copies[member] = copies
                self.hedged += 1

    def _busy(self) -> None:
        """Add the time since the last call at the share of workers the tasks in flight then kept busy."""
        now = time.perf_counter()
        self._busy_integral += (now - self._busy_at) * min(1.0, len(self._tasks) / max(1, self.executor.num_workers))
        self._busy_at = now

    def load(self) -> Load:
        """The :class:`Load` since the last call (or the start); starts the next interval."""
        self._busy()
        elapsed = max(1e-9, self._busy_at - self._load_start)
        backlog = sum(len(q) for work, _ in self._works.values() for q in (*work.queue, *work.alone))
        out = Load(tasks_per_s=self._load_tasks / elapsed, evaluations_per_s=self._load_designs / elapsed,
                   busy_share=min(1.0, self._busy_integral / elapsed), in_flight_tasks=len(self._tasks),
                   backlog_designs=backlog)
        self._load_start, self._load_tasks, self._load_designs, self._busy_integral = self._busy_at, 0, 0, 0.0
        return out

    def fill(self) -> int:
        """Start batches, one source at a time in turn, until :attr:`limit` are in flight; returns how many."""
        begun = time.perf_counter()
        started = 0
        idle = 0
        while self._turn and len(self._tasks) < self.limit and idle < len(self._turn):
            key = self._turn[0]
            self._turn.rotate(-1)
            work, handles = self._works[key]
            if work.paused or not (work.queue or work.alone):
                idle += 1
                continue
            idle = 0
            self._start(work, handles)
            started += 1
        self._window_busy_s += time.perf_counter() - begun
        return started

    def _start(self, work: Work, handles: tuple[Any, ...]) -> None:
        self._submit(work, handles, [work.alone.popleft()] if work.alone else self._take(work))

    def _submit(self, work: Work, handles: tuple[Any, ...], parts: list[Request], again: int = 0) -> int:
        rows = np.concatenate([np.column_stack([np.full(len(part), float(part.road)), part.designs])
                               for part in parts])
        # tasks ahead of it to return before a worker takes it; a copy starts at once (Ray gives copies
        # workers of their own, Executor.submit)
        ahead = max(0, len(self._tasks) - self.executor.num_workers + 1) if not again else 0
        task_id = self.executor.submit(_apply, rows, self._fn, *handles, again=again)
        now = time.perf_counter()
        self._tasks[task_id] = _Task(work, tuple(parts), now, self._freed + ahead, None if ahead else now)
        work.in_flight += 1
        work.waited_in_flight += sum(len(part) for part in parts if part.waited)
        return task_id

    def _forget(self, task_id: int) -> _Task | None:
        """A task that came back, or is no longer wanted, out of the books (None: not there)."""
        task = self._tasks.pop(task_id, None)
        if task is not None:
            task.work.in_flight -= 1
            task.work.waited_in_flight -= sum(len(part) for part in task.parts if part.waited)
        return task

    def _take(self, work: Work) -> list[Request]:
        """A task's requests: the smallest, cut to the batch size; then, while the size leaves room,
        the next smallest whole (a few DE generations of different runs in one task rather than a
        task each, where the per-task cost would weigh on each; rule 3's spread keeps them apart on
        a big cluster)."""
        at, ahead, queued = work.next_request()
        assert work.sizer is not None
        room = self._batch_size or work.sizer.next_size(queued, self.driver_s, first=ahead,
                                                        waited=work.queue[at].waited, threads=self.executor.task_cpus)
        parts: list[Request] = []
        while True:
            request = work.queue[at]
            if room < len(request):
                if not parts:
                    part, work.queue[at] = request.split(room)
                    parts.append(part)
                return parts
            parts.append(request)
            del work.queue[at]
            room -= len(request)
            if not work.queue or not room:
                return parts
            at = work.smallest()

    def collect(self, timeout: float) -> int:
        """Deliver the results of finished tasks (waiting up to ``timeout`` s for the first)."""
        begun = time.perf_counter()
        done = self.executor.poll(0.0)  # what has finished: handling it is the driver's work
        if not done and self._tasks:
            self._window_busy_s += time.perf_counter() - begun
            done = self.executor.poll(timeout)  # waiting for results is not
            begun = time.perf_counter()
        self._freed += len(done)
        for d in done:
            task = self._forget(d.task)
            if task is None:
                continue  # its source was removed, or a copy of it came back first
            copies = self._copies.pop(d.task, None)
            if copies is not None:
                copies.remove(d.task)
                if not d.ok and any(c in self._tasks for c in copies):
                    continue  # the other copies carry on
                for other in copies:   # left to run (Ray's cancel would kill its worker); their results dropped
                    self._copies.pop(other, None)
                    self._forget(other)
            if d.cancelled:
                continue
            work, parts = task.work, task.parts
            designs = sum(len(part) for part in parts)
            if (d.lost or d.error is not None) and designs > 1:  # find the one at fault
                work.alone.extend(part.part(np.array([i])) for part in parts for i in range(len(part)))
            elif d.lost:
                work.on_failure(parts[0], "worker lost: its process died repeatedly while simulating")
            elif d.error is not None:
                work.on_failure(parts[0], f"error in the worker: {type(d.error).__name__}: {d.error}")
            else:
                timed: Timed = d.result
                assert work.sizer is not None
                if work.sizer.designs_done:   # its pace, against what the source's designs took so far; its
                    start = task.handed_at if task.started_at is None else task.started_at   # start, or the earliest
                    self._paces.append((start, timed.compute_s / max(1e-9, designs * work.sizer.per_design_s)))
                work.sizer.observe(designs, time.perf_counter() - task.handed_at, timed.busy_s, timed.compute_s,
                                   timed.idle_s)
                self._measured = work.sizer
                self._task_s += 0.02 * (timed.busy_s - self._task_s) if self._task_s else timed.busy_s
                self._load_tasks += 1
                self._load_designs += designs
                _deliver(work, parts, timed.result)
        now = time.perf_counter()
        self._window_busy_s += now - begun
        self._measure(len(done), now)
        return len(done)

    def _measure(self, finished: int, now: float) -> None:
        """Batching rule 4's driver time a task: the time spent starting tasks and handling their
        results (not waiting for them, nor the source's own work between steps) over the tasks that
        finished, once a window of at least a second holds tasks (before the first such window: the
        first tasks' figure, taken once: a serial executor's tasks run in the driver, and an estimate
        retaken from ever bigger tasks would grow them without bound)."""
        self._window_tasks += finished
        if not self._window_tasks:
            return
        if now - self._window_start >= 1.0:
            self.driver_s = self._window_busy_s / self._window_tasks
            self.limit = in_flight_limit(self.executor.num_workers, self.executor.capacity, self._task_s)
            self._window_start, self._window_busy_s, self._window_tasks = now, 0.0, 0
        elif self.driver_s == 0.0:  # until a whole window has closed: the first tasks' (a DE of a second
            self.driver_s = self._window_busy_s / self._window_tasks  # would otherwise run on none)

    def close(self) -> None:
        """Remove every source (cancelling what runs) and release the task function; the executor stays open."""
        for key in list(self._works):
            self.remove(key)
        self.executor.release(self._fn)


def _deliver(work: Work, parts: tuple[Request, ...], results: list[tuple[int, BatchResult]]) -> None:
    """Each part's results to its source: a task's results come one batch a run of rows on one
    road, so a batch holds one part or several consecutive parts on its road."""
    queue = iter(parts)
    for _, batch in results:
        start = 0
        while start < len(batch):
            part = next(queue)
            work.on_result(part, batch if len(part) == len(batch) else batch.rows(slice(start, start + len(part))))
            start += len(part)


def _apply(rows: np.ndarray, fn: Callable[..., Timed], *shared: Any) -> Timed:
    """What every task runs: the dispatcher's shared task function on the batch."""
    return fn(rows, *shared)
