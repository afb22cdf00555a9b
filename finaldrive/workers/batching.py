"""Adaptive batch size: keep per-task overhead under 2 % while every worker has work.

The rule (docs/workers.md, "Batching"):

1. **Probe.** Until a batch has come back, batches hold ``probe_size`` designs (1), so the
   first wave gives every worker a small task. A source that starts where others have run
   (:meth:`BatchSizer.after`) skips the probe: it starts from their per-task overhead and, weighted
   as :data:`PRIOR_DESIGNS` designs, their per-design time, which its own results soon outweigh
   (a DE job arriving at a warm 256-CPU cluster would otherwise hand out its first round one
   design a task: 368 tasks of the driver's ~1 ms for the 23 paper roads, docs/performance-log.md).
2. **Measure.** For each finished batch of ``n`` designs: ``compute`` is the time ``fn`` ran
   in the worker, ``busy`` adds the one-off warm-up, ``round_trip`` runs from handing the
   batch to the executor to receiving its result, and ``idle`` is the worker's time from its
   previous task's end to this one's start. Per-design time ``c`` is total compute over total
   designs; per-task overhead ``o`` is the *smallest* ``round_trip - busy`` seen (the
   least-queued task; cold-start tasks only overestimate it, and later tasks lower it), or the
   median ``idle`` of the last :data:`IDLE_SAMPLES` tasks if larger: with work queued, a worker
   waits that long between tasks (the result's way back and the next task's way out; 6-10 ms
   on 2 loaded cores against ~4 ms for the smallest round trip, docs/performance-log.md).
3. **Size.** Overhead fraction ``o / (b c) <= 0.02`` needs ``b >= o / (0.02 c)``; take the
   smallest such ``b``, but at most ``remaining // (num_workers * 4)`` (at least 1), so at
   least four waves remain: every worker gets work, the tail balances, and progress streams;
   at most ``ceil(first / num_workers)``, so the work that starts first (``first``: the designs
   of the requests that go before or with this one, e.g. the DE generations waiting beside a
   sweep) spreads over every worker in one wave rather than queueing behind itself; and at most
   ``MAX_TASK_S / c`` (at least 1), so no task runs much longer than half a second: a cancel
   waits for little, a DE generation is not held by one long task, and a queueing delay
   mistaken for overhead cannot grow batches without bound. When the rules cannot all hold,
   giving every worker work wins.
4. **Keep up.** The thread that dispatches spends ``d`` seconds of its own on each task
   (submitting it, taking its result, handing it on: measured by the dispatcher as its time spent
   starting tasks and handling results, over finished tasks). ``N`` workers finishing a task every
   ``b c`` seconds keep it busy ``N d / (b c)`` of the time; batches hold at least ``N d / (DRIVER_SHARE c)``
   designs so that stays under ``DRIVER_SHARE``. On a big cluster with short simulations the
   dispatcher, not the workers, would otherwise set the pace, and no number of waves helps then:
   this rule overrides rule 3's waves, not its longest task.
5. **Waited-on work.** A request its source waits for before it can ask for more (a DE
   generation) is latency, not throughput: its ``first`` designs (the waited-on ones queued or
   running: the round of generations under way) are done soonest in tasks of
   ``b* = sqrt(first d / c)`` designs, the balance between the driver handing out ``first / b``
   tasks one after another (``d`` each) and a task's ``b`` designs running in series (``b c``).
   Such a task holds ``min(size, max(ceil(first / N), b*))`` designs, ``size`` from rules 1-4:
   on a cluster wide for the work (256 CPUs, 23 generations of 50 designs) rule 4's batches of
   100+ designs would run a generation in one task; on a small one, one wave of ``first``
   designs already fits. ``d`` is rule 4's measured driver time a task (the per-task overhead of
   rule 2 until it is measured).
6. **Whole rounds.** A wide task runs its designs on ``threads`` threads, each taking the next
   (workers/evaluate.py), so a task of ``k threads + r`` designs ends with a round of ``r`` designs
   while the other threads wait. A size above ``threads`` (short of what remains) is cut to a multiple
   of it. Not for waited-on work: a DE generation is not split for it. On the big plan of
   bench/bench_scheduler.py (tasks of 16 CPUs, 4 ms a design) the efficiency went from 0.910-0.933 to
   0.924-0.945 in six runs of each, alternated (issue 27, docs/performance-log.md).
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass, field

#: overhead / compute per task (was 0.05; with the faster engine of issue 13 the paper study on 2
#: workers then lost 7-8 % between simulations: 1.118x its engine time against 1.101x at 0.02)
TARGET_OVERHEAD = 0.02
MIN_WAVES = 4            # batches per worker that must remain
PROBE_SIZE = 1           # designs per batch before any measurement
MAX_TASK_S = 0.5         # longest task aimed for [s]
#: largest share of the dispatching thread's time its task traffic may take: the thread also takes each design
#: through the intake (cache keys and lookup), the DE and the hand-over to the writer. At 0.5 it was saturated
#: while the DE ran beside the sweep of the big plan (256 virtual CPUs at 4 ms: efficiency 0.79-0.80; 0.25:
#: 0.84-0.85; 0.125: 0.86-0.88; the paper plan unchanged; bench/bench_scheduler.py, docs/performance-log.md)
DRIVER_SHARE = 0.125
IDLE_SAMPLES = 64        # recent tasks whose workers' idle gaps give the overhead (rule 2)
PRIOR_DESIGNS = 16       # weight, in designs, of earlier sources' per-design time in a new source's (rule 1)


def batch_size(
    *,
    remaining: int,
    num_workers: int,
    per_design_s: float,
    overhead_s: float,
    driver_s: float = 0.0,
    first: int | None = None,
    waited: bool = False,
    target: float = TARGET_OVERHEAD,
    min_waves: int = MIN_WAVES,
    threads: int = 1,
) -> int:
    """Designs for the next batch (>= 1 while ``remaining`` > 0; 0 when nothing remains);
    ``driver_s``: the dispatching thread's own time a task (rule 4); ``first``: the designs that
    start before or with this batch's request (rule 3's spread; default ``remaining``); ``waited``:
    the request is waited on (rule 5; ``first`` then counts the waited-on designs queued or running);
    ``threads``: the threads a task's designs run on (rule 6)."""
    if remaining <= 0:
        return 0
    workers = max(1, num_workers)
    waves = max(1, remaining // (workers * min_waves))
    spread = math.ceil((remaining if first is None else first) / workers)
    if per_design_s <= 0.0:
        return min(waves, spread)
    longest = max(1, int(MAX_TASK_S / per_design_s))
    needed = math.ceil(max(0.0, overhead_s) / (target * per_design_s))
    keep_up = math.ceil(workers * max(0.0, driver_s) / (DRIVER_SHARE * per_design_s))
    size = max(1, min(needed, waves, longest, spread), min(keep_up, longest))
    if waited:
        per_task = driver_s if driver_s > 0.0 else max(0.0, overhead_s)
        balance = math.ceil(math.sqrt((remaining if first is None else first) * per_task / per_design_s))
        size = min(size, max(1, spread, balance))
    elif threads < size < remaining:
        size -= size % threads
    return min(size, remaining)


@dataclass
class BatchSizer:
    """Running estimates of per-design compute and per-task overhead (rule in the module doc)."""

    num_workers: int
    probe_size: int = PROBE_SIZE
    designs_done: int = 0
    compute_s: float = 0.0
    round_trip_s: float = math.inf  # the smallest round trip - busy seen
    idle_s: deque[float] = field(default_factory=lambda: deque(maxlen=IDLE_SAMPLES))

    @classmethod
    def after(cls, earlier: BatchSizer) -> BatchSizer:
        """A new source's sizer on the executor ``earlier`` measured (rule 1): its overhead, and its
        per-design time weighted as :data:`PRIOR_DESIGNS` designs."""
        sizer = cls(earlier.num_workers, round_trip_s=earlier.round_trip_s, idle_s=earlier.idle_s.copy())
        if earlier.designs_done:
            sizer.designs_done = min(earlier.designs_done, PRIOR_DESIGNS)
            sizer.compute_s = earlier.per_design_s * sizer.designs_done
        return sizer

    def observe(self, n_designs: int, round_trip_s: float, busy_s: float, compute_s: float,
                idle_s: float | None = None) -> None:
        """Record one finished batch (``idle_s``: its worker's wait before it, if it had a task before)."""
        self.designs_done += n_designs
        self.compute_s += compute_s
        self.round_trip_s = min(self.round_trip_s, max(0.0, round_trip_s - busy_s))
        if idle_s is not None:
            self.idle_s.append(idle_s)

    @property
    def per_design_s(self) -> float:
        """The measured compute time a design (rule 1); only once designs were done."""
        return self.compute_s / self.designs_done

    @property
    def overhead_s(self) -> float:
        """Per-task overhead (rule 2): the smallest round trip, or the workers' median idle gap if larger."""
        if not self.idle_s:
            return self.round_trip_s
        return max(self.round_trip_s, float(statistics.median(self.idle_s)))

    def next_size(self, remaining: int, driver_s: float = 0.0, first: int | None = None,
                  waited: bool = False, threads: int = 1) -> int:
        """Designs for the next batch; ``driver_s``: the dispatcher's own time a task; ``first``:
        the designs that start before or with the batch's request (waited-on ones, ``waited``);
        ``threads``: the threads a task's designs run on."""
        if self.designs_done == 0:
            return min(self.probe_size, max(0, remaining))
        return batch_size(
            remaining=remaining,
            num_workers=self.num_workers,
            per_design_s=self.per_design_s,
            overhead_s=self.overhead_s,
            driver_s=driver_s,
            first=first,
            waited=waited,
            threads=threads,
        )
