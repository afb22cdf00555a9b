"""The scheduler: claims jobs from the store under leases and keeps the executor full with them.

One process (``finaldrive scheduler``, or the one ``finaldrive serve`` starts beside the API)
runs :meth:`Scheduler.run` in its main thread. Several schedulers, on several machines, may
serve one database: a job belongs to the scheduler holding its lease (finaldrive.service.db.leases).

Each turn of the loop: renew the heartbeat and leases (and learn of cancelled or lost jobs),
claim new jobs, move every run's ready requests past the store (slots already stored, the
result cache) into the dispatcher, let the dispatcher keep the executor full and deliver results,
and write results in bulk. A DE generation is told to its optimiser when its last result arrives
and stored after its evaluations, so a resumed job continues from its last stored generation
with any stored evaluations of the next one reused.

Faults: a database error (locked past the busy timeout, disk full, connection lost) never stops
the scheduler and never finishes a job: the failed operation is retried with back-off while the
results wait in memory (dispatching pauses when too many wait). Messages stored in jobs never
carry SQL; the details go to the log.
"""

from __future__ import annotations

import gc
import logging
import math
import os
import signal
import socket
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any

import numpy as np

from finaldrive.engine import (
    ENGINE_VERSION,
    PAPER_SWEEP_STEP,
    BatchResult,
    DERun,
    PlanError,
    Request,
    Road,
    Run,
    fitness_values,
    with_population,
    without_population,
)
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database, in_memory
from finaldrive.service.db.leases import (
    MAX_SCHEDULER_ID,
    beat,
    claim_jobs,
    finish_job,
    newest_queued,
    others_alive,
    register_scheduler,
    scheduler_id as fit_id,
    stop_scheduler,
)
from finaldrive.service.db.models import Job, JobState
from finaldrive.service.db.repository import profile_roads
from finaldrive.service.db.results import (
    FITNESS,
    cached_evaluations,
    finish_if_complete,
    last_generations,
    stored_fitness,
    stored_slots,
)
from finaldrive.service.jobs.budget import Budget, spent_s
from finaldrive.service.jobs.cache import context_digest, design_keys
from finaldrive.service.jobs.plan import JobPlan, build_plan
from finaldrive.service.jobs.recordings import RecordingProducer
from finaldrive.service.jobs.rows import block_from_results, nullable, row_from_cache
from finaldrive.service.jobs.writer import Guard, Writer, Writes
from finaldrive.service.jobs.writer_pool import WriterPool
from finaldrive.service.jobs.writer_process import WriterProcess, start_fork_server
from finaldrive.service.profiles import profile_ids, resolver
from finaldrive.service.schemas import JobSpec
from finaldrive.workers import Executor
from finaldrive.workers.dispatch import Dispatcher, Task, Work
from finaldrive.workers.evaluate import run_engine_on_roads, warm_up_engine

log = logging.getLogger(__name__)

#: A scheduler's transactions wait this long for a lock, then retry later (the loop keeps dispatching).
SCHEDULER_LOCK_TIMEOUT_S = 2.0
#: The cyclic garbage collector's thresholds in a scheduler's process (Python's are 700, 10, 10). The loop
#: makes a few container objects a design (requests, the slots' keys, results, rows' parts): on the big plan
#: of bench/bench_scheduler.py Python's ran ~2,400 collections, 0.86 s of the driver's 9.6 s, the full ones
#: 45-78 ms each with the loop held; these ran 16, 0.10 s, and the driver used 8.2-8.7 s (issue 27).
GC_THRESHOLDS = (50_000, 20, 20)
#: Designs of a job looked up in the store a turn (the rest wait for the next turns).
_INTAKE_DESIGNS = 4096
#: An idle loop waits this long per turn: with jobs (a result may be on its way to the store), without.
_IDLE_WAIT_S, _IDLE_POLL_S = 0.02, 0.2
#: Between heartbeats, a scheduler with room for a job looks this often for a newly queued one (a
#: read) and claims it at once rather than at the next heartbeat [s].
_LOOK_S = 0.2
#: The heartbeat thread renews the leases while the loop is busy in one turn, for at most this long [s]
#: (a cold compile of the engine took 281 s on a loaded machine); beyond it the loop is taken as stuck.
_STUCK_S = 600.0
#: Times a job found with a hole in the store is given back to resume, by one scheduler, before it is failed.
_MAX_REOPEN = 2
#: Beside other live schedulers, a scheduler claims one job a heartbeat (so a job's load shows before
#: the next claim, and the others get their share), and none while its workers were busier than this
#: over its last heartbeat interval (they are left to schedulers with room). Alone, a scheduler
#: claims up to max_jobs at once.
CLAIM_BELOW_BUSY = 0.9


@dataclass(frozen=True)
class SchedulerConfig:
    """How a scheduler paces itself (its FINALDRIVE_* settings: docs/service.md)."""

    lease_s: float = 15.0          # a job's lease, renewed every heartbeat
    heartbeat_s: float = 1.0       # also how fast a cancel is obeyed
    max_jobs: int = 32             # jobs run at once by this scheduler
    flush_s: float = 0.25          # results are written at most this long after they arrive (at once to an idle writer)
    max_backlog_rows: int = 50_000  # results waiting for the store before dispatching pauses
    writers: int = 1               # writer processes storing at once on PostgreSQL (SQLite: one)
    batch_size: int | None = None  # designs per task (None: adaptive)
    max_simulation_s: float | None = 60.0  # wall-time limit of one simulation (reason "time limit ...")
    max_job_cpu_s: float = 100.0 * 3600  # a job's budget of simulation time: failed beyond it (budget.py)
    recordings: bool = True        # also produce queued recordings


class ActiveJob:
    """A job this scheduler owns: its runs, what waits to be stored, and its dispatcher work."""

    def __init__(self, job_id: int, plan: JobPlan, runs: list[Run], engine_version: str, resumed: bool) -> None:
        self.id = job_id
        self.plan = plan
        self.runs = {run.index: run for run in runs}
        self.resumed = resumed
        self.intake: deque[Request] = deque()
        self.writes = Writes()
        self.copies: dict[tuple[int, int, int], list[int]] = {}   # (road, step, first candidate) -> duplicates
        self.keys: dict[tuple[int, int, int], str] = {}           # dispatched (road, step, candidate) -> key
        self.contexts = [context_digest(r.road, plan.settings, plan.vehicle, engine_version)  # each road's keys' digits
                         for r in plan.study.roads]
        self.work: Work | None = None
        self.budget = Budget()

    def done(self) -> bool:
        """Every run is complete and nothing waits to be dispatched (tasks may still be in flight)."""
        return (not self.intake and self.work is not None and not self.work.queue
                and all(run.done for run in self.runs.values()))

    def take_writes(self) -> Writes | None:
        """What waits to be stored (its rows are built by the writer), or None."""
        if not self.writes:
            return None
        writes, self.writes = self.writes, Writes()
        return writes


class Scheduler:
    """Claims jobs, dispatches their simulations, stores results (one thread drives it)."""

    def __init__(self, db: Database, executor: Executor, *, config: SchedulerConfig = SchedulerConfig(),
                 task: Task = run_engine_on_roads, warmup: Callable[..., None] | None = warm_up_engine,
                 scheduler_id: str | None = None, executor_kind: str = "?",
                 engine_version: str = ENGINE_VERSION) -> None:
        self.db = db
        self.executor = executor
        self.config = config
        self.id = scheduler_id or fit_id(socket.gethostname(), f":{os.getpid()}:{uuid.uuid4().hex[:8]}")
        if len(self.id) > MAX_SCHEDULER_ID:
            raise ValueError(f"a scheduler id has at most {MAX_SCHEDULER_ID} characters, not {len(self.id)}")
        self.executor_kind = executor_kind
        self.engine_version = engine_version
        self.dispatcher = Dispatcher(executor, task, warmup=warmup, batch_size=config.batch_size)
        self.jobs: dict[int, ActiveJob] = {}
        self.recordings = RecordingProducer(db, self.id, lease_s=config.lease_s) if config.recordings else None
        self._db = Guard(db, f"scheduler {self.id}")
        self.writer = _writer(db, self.id, config.writers)
        self._registered = False
        self._next_beat = 0.0
        self._next_look = 0.0
        self._newest_seen = 0   # the newest queued job's id at the last look
        self._next_flush = 0.0
        self._reopened: dict[int, int] = {}   # job -> times re-opened for a hole in the store
        self._beaten = 0.0                    # when the last heartbeat was stored (monotonic)
        self._load: dict[str, float | int] | None = None   # the dispatcher's Load at the last heartbeat
        self._turned = time.monotonic()       # when the loop last began a turn

    @property
    def registered(self) -> bool:
        """Whether this scheduler's row is in the store (the API's health then counts it)."""
        return self._registered

    # ------------------------------------------------------------------ the loop
    def run(self, stop: threading.Event) -> None:
        """Serve until ``stop`` is set; then give the jobs back and release the workers."""
        log.info("scheduler %s starting (executor %s, capacity %d tasks, %d CPUs a task)", self.id,
                 self.executor_kind, self.executor.capacity, self.executor.task_cpus)
        if self.recordings is not None:
            self.recordings.start()
        done = threading.Event()
        keeper = threading.Thread(target=self._keep_alive, args=(done,), name="finaldrive-heartbeat", daemon=True)
        if not in_memory(self.db.url):  # an in-memory database is one connection's: no second thread sees it
            keeper.start()
        try:
            while not stop.is_set():
                self.cycle(stop)
        finally:
            done.set()
            if keeper.is_alive():
                keeper.join()
            self.shutdown()

    def _keep_alive(self, done: threading.Event) -> None:
        """Renew the heartbeat and leases whenever the loop is late with them: a task the loop runs
        itself (the serial executor: the engine's warm-up, a long simulation) or a slow store must
        not cost the scheduler its jobs. A thread of its own, with a store guard of its own."""
        guard = Guard(self.db, f"scheduler {self.id} (heartbeat)")
        while not done.wait(self.config.heartbeat_s / 2):
            now = time.monotonic()
            if now - self._turned > _STUCK_S:  # a loop silent this long is stuck: its leases lapse, others resume
                continue
            late = self._registered and now > self._beaten + 1.5 * self.config.heartbeat_s
            if late and guard(lambda s: beat(s, self.id, lease_s=self.config.lease_s, capacity=self.executor.capacity,
                                             load=self._load), "heartbeat") is not None:
                self._beaten = time.monotonic()

    def cycle(self, stop: threading.Event) -> int:
        """One turn as :meth:`run` takes them, and as the benches drive a scheduler; returns how many
        tasks finished. When nothing ran nor came back, executors answer at once, so it waits rather
        than spin (an idle loop holds a core and the GIL that the recordings' thread, the writer and
        the workers need). While the writer has results to store, the wait ends with its next
        transaction: a job paused behind its backlog, or done and waiting for its last results, goes
        on at once, not after a fixed pause (issue 27: with the pause, and results handed over only
        every ``flush_s``, the paper plan through a local Ray stored 37,400-40,900 evaluations a
        second against 41,800-44,500, alternated)."""
        finished = self.turn(0.05 if self.dispatcher.in_flight() else 0.2)
        if not finished and not self.dispatcher.in_flight():
            if self.writer.busy():
                self.writer.wait(_IDLE_WAIT_S)
            else:
                stop.wait(_IDLE_WAIT_S if self.jobs else _IDLE_POLL_S)
        return finished

    def turn(self, timeout: float) -> int:
        """One turn of the loop (tests drive it step by step); returns how many tasks finished."""
        now = self._turned = time.monotonic()
        if now < self._next_beat and now >= self._next_look and len(self.jobs) < self.config.max_jobs:
            self._next_look = now + _LOOK_S
            if self._new_job_queued():
                self._next_beat = now
        # the heartbeat is a write transaction: taken while the writer is idle, it does not wait behind
        # the writer's (which held the loop ~50 ms a beat on SQLite), unless it is half a beat late
        if now >= self._next_beat and (not self.writer.busy() or now >= self._next_beat + self.config.heartbeat_s / 2):
            self._next_beat = now + self.config.heartbeat_s
            self._maintain()
        self._intake()
        finished = self.dispatcher.step(timeout)
        self._finish_ready()
        if time.monotonic() >= self._next_flush or not self.writer.busy():  # an idle writer gets them now
            self._flush()
        return finished

    def shutdown(self) -> None:
        """Cancel what runs, store what arrived, give the jobs back (``interrupted``)."""
        self.dispatcher.close()
        if self.recordings is not None:
            self.recordings.stop()
        self._flush()
        self.writer.drain(2.0)
        self.writer.close()
        self.jobs.clear()
        self._db(lambda s: stop_scheduler(s, self.id), "give the jobs back")
        log.info("scheduler %s stopped", self.id)

    def _maintain(self) -> None:
        # the jobs seen by the last look count as seen only if this beat claims all it may (below):
        # else (the store failed, or room ran out) a later look tries them again
        seen, self._newest_seen = self._newest_seen, 0
        if not self._registered:
            done = self._db(partial(register_scheduler, scheduler_id=self.id, host=socket.gethostname(),
                                    pid=os.getpid(), executor=self.executor_kind, capacity=self.executor.capacity),
                            "register")
            self._registered = done is not None
            if not self._registered:
                return
        load = self.dispatcher.load()
        self._load = {name: round(value, 4) if isinstance(value, float) else value
                      for name, value in asdict(load).items()}
        beaten = self._db(lambda s: (beat(s, self.id, lease_s=self.config.lease_s, capacity=self.executor.capacity,
                                          load=self._load),
                                     others_alive(s, self.id, within_s=self.config.lease_s)),
                          "heartbeat")
        if beaten is None:
            return
        owned, others = beaten
        self._beaten = time.monotonic()
        for job_id in [j for j in self.jobs if j not in owned]:
            log.info("scheduler %s: job %s is no longer ours (cancelled or taken over); stopping it", self.id, job_id)
            self._drop(job_id)
        room = self.config.max_jobs - len(owned)
        if others and room > 0:   # claim by free capacity (CLAIM_BELOW_BUSY)
            room = 1 if not self.jobs or load.busy_share < CLAIM_BELOW_BUSY else 0
            self._newest_seen = seen   # the next heartbeat claims again, not the next look: the load shows first
        claimed = self._db(lambda s: claim_jobs(s, self.id, lease_s=self.config.lease_s, limit=room), "claim jobs")
        if claimed is not None and len(claimed) < room:
            self._newest_seen = seen   # every claimable job was taken, by us or by others
        for job_id in sorted(owned.union(claimed or [])):  # owned but not open: a restart, or an open that failed
            if job_id not in self.jobs:
                self._open(job_id)

    def _new_job_queued(self) -> bool:
        """Whether a job was queued since the last look: each new job brings the heartbeat (and its
        claim) forward once, so a job another scheduler won costs no more writes; one left queued for
        want of room is looked at again once the scheduler has room (_maintain)."""
        newest = self._db(newest_queued, "look for new jobs", write=False)
        if newest is None or newest <= self._newest_seen:
            return False
        self._newest_seen = newest
        return True

    # ------------------------------------------------------------------ jobs
    def _open(self, job_id: int) -> None:
        loaded = self._db(lambda s: _load(s, job_id), f"open job {job_id}", write=False)
        if loaded is None:
            return  # retried at the next heartbeat: the job stays claimed by us
        spec, profiles, resumed, sweep_done, de_states = loaded
        try:
            plan = build_plan(JobSpec.model_validate(spec), profiles=resolver(profiles),
                              max_simulation_s=self.config.max_simulation_s)
        except (PlanError, ValueError) as exc:
            message = f"invalid job: {exc}"
            self._db(lambda s: finish_job(s, self.id, job_id, JobState.failed, error=message), f"fail job {job_id}")
            return
        job = ActiveJob(job_id, plan, plan.study.runs(sweep_done=sweep_done, de_states=de_states),
                        self.engine_version, resumed)
        job.work = Work(
            key=job_id, shared=(tuple(r.road for r in plan.study.roads), plan.settings, plan.vehicle),
            on_result=partial(self._on_result, job),
            on_failure=partial(self._on_failure, job),
        )
        spent = self._db(partial(spent_s, job_id=job_id), f"job {job_id}'s cost", write=False) if resumed else 0.0
        if spent is None:
            return  # retried at the next heartbeat
        job.budget = Budget(self.config.max_job_cpu_s, spent)
        job.work.on_result = job.budget.metered(job.work.on_result)
        self.dispatcher.add(job.work)
        self.jobs[job_id] = job
        log.info("scheduler %s: job %s %s", self.id, job_id, "resumed" if resumed else "started")

    def _drop(self, job_id: int) -> None:
        self.writer.forget(job_id)
        job = self.jobs.pop(job_id, None)
        if job is not None and job.work is not None:
            self.dispatcher.remove(job.work.key)

    def _intake(self) -> None:
        """Every run's ready requests: slots already stored and cache hits are taken from the store,
        the rest (each distinct design once) goes to the dispatcher. The smallest requests first and
        about :data:`_INTAKE_DESIGNS` designs a job a turn, so a DE generation is not held behind the
        lookups of a whole sweep."""
        for job in list(self.jobs.values()):
            for run in job.runs.values():
                if not run.done:
                    job.intake.extend(run.take())
            if job.intake:
                requests = _first_designs(job.intake, _INTAKE_DESIGNS)
                found = self._db(partial(_lookup, job=job, requests=requests), f"job {job.id}", write=False)
                if found is not None:  # else the store is unavailable: keep the requests, retry next turn
                    taken = {id(request) for request in requests}
                    job.intake = deque(request for request in job.intake if id(request) not in taken)
                    hits = found[1]
                    for request, (stored, keys) in zip(requests, found[0], strict=True):
                        self._admit(job, request, stored, keys, hits)
            assert job.work is not None
            job.work.paused = len(job.writes) + self.writer.pending(job.id) > self.config.max_backlog_rows

    def _admit(self, job: ActiveJob, request: Request, stored: dict[int, float], keys: list[str],
               hits: dict[str, dict[str, Any]]) -> None:
        """Tell what is known, queue the rest: each distinct design once (duplicates are copied)."""
        if stored:
            keep = np.array([c not in stored for c in request.candidates.tolist()], dtype=bool)
            known = request.part(np.flatnonzero(~keep))
            self._tell(job, known, np.array([stored[c] for c in known.candidates.tolist()]))
            request = request.part(np.flatnonzero(keep))
        candidates = request.candidates.tolist()
        if not candidates:
            return
        if not hits and len(set(keys)) == len(keys):  # the common case: nothing known, no duplicate
            job.keys.update(zip(((request.road, request.step, c) for c in candidates), keys, strict=True))
            assert job.work is not None
            job.work.queue.append(request)
            return
        firsts: dict[str, int] = {}
        todo, hit = [], []
        for i, key in enumerate(keys):
            slot = (request.road, request.step, candidates[i])
            if key in hits:
                hit.append(i)
            elif key in firsts:
                job.copies.setdefault((request.road, request.step, candidates[firsts[key]]), []).append(slot[2])
            else:
                firsts[key] = i
                todo.append(i)
                job.keys[slot] = key
        if hit:
            part = request.part(np.array(hit))
            rows = [row_from_cache(hits[keys[i]], part.road, part.step, int(part.candidates[j]), part.designs[j],
                                    keys[i]) for j, i in enumerate(hit)]
            job.writes.rows += rows
            self._tell(job, part, np.array([math.nan if r[FITNESS] is None else r[FITNESS] for r in rows]))
        if todo:
            assert job.work is not None
            job.work.queue.append(request.part(np.array(todo)))

    def _on_result(self, job: ActiveJob, part: Request, batch: BatchResult, *, transient: bool = False) -> None:
        if job.id not in self.jobs:
            return
        fitness = fitness_values(batch)
        candidates = part.candidates.tolist()
        keys = [job.keys.pop((part.road, part.step, c)) for c in candidates]
        copies = [job.copies.pop((part.road, part.step, c), None) for c in candidates] if job.copies else []
        if not any(copies):
            job.writes.finish((part, batch, fitness, keys, transient))
            self._tell(job, part, fitness)
            return
        # designs that were duplicates of one in this part: the same result, told and stored as cached
        block = block_from_results([(part, batch, fitness, keys, transient)])
        rows = [j for j, duplicates in enumerate(copies) for _ in duplicates or ()]
        candidates = [copy for duplicates in copies for copy in duplicates or ()]
        job.writes.add(block)
        job.writes.add(block.copied(rows, candidates))
        self._tell(job, Request(part.run, part.step, part.road, np.concatenate([part.candidates, candidates]),
                                np.concatenate([part.designs, part.designs[rows]])),
                   np.concatenate([fitness, fitness[rows]]))

    def _on_failure(self, job: ActiveJob, part: Request, reason: str) -> None:
        """A part that could not be evaluated: failed evaluations with the reason, never reused."""
        log.warning("scheduler %s: job %s: %d designs failed: %s", self.id, job.id, len(part), reason)
        self._on_result(job, part, BatchResult.failed(part.designs, reason), transient=True)

    def _tell(self, job: ActiveJob, part: Request, fitness: np.ndarray) -> None:
        if len(part) == 0:
            return
        run = job.runs[part.run]
        if run.tell(part.road, part.step, part.candidates, fitness) and isinstance(run, DERun):
            de = run.optimiser
            record = de.history[-1]
            de.history.clear()  # the rows hold the history: the optimiser here stays O(NP)
            job.writes.generations.append({  # the state without its history: each row holds its own record;
                "run": run.index, "generation": run.generation,  # arrays, made JSON in the writer (off this thread)
                "state": without_population(de.state(history=False, arrays=True)),  # the next two hold those
                "population": de.population, "fitness_m": de.fitness,
                "best_fitness_m": nullable([de.best_f])[0], "mean_fitness_m": nullable([record["mean_f"]])[0],
                "n_evals": de.n_evals, "n_failed": record["n_failed"],
            })

    def _finish_ready(self) -> None:
        for job in list(self.jobs.values()):
            if job.budget.exceeded and not job.done():
                self._stop_at_budget(job)
                continue
            if not job.done() or self.dispatcher.in_flight(job.id):
                continue
            writes = job.take_writes()  # its last results: to the writer now rather than at the next flush
            if writes is not None:
                self.writer.put(job.id, writes)
            if self.writer.pending(job.id):
                continue
            self._finish(job)

    def _stop_at_budget(self, job: ActiveJob) -> None:
        """A job over its CPU budget: cancel its simulations, store what arrived, then fail it."""
        self.dispatcher.remove(job.id)
        job.intake.clear()
        writes = job.take_writes()
        if writes is not None:
            self.writer.put(job.id, writes)
        if self.writer.pending(job.id):
            return
        error = job.budget.error()
        if self._db(lambda s: finish_job(s, self.id, job.id, JobState.failed, error=error),
                    f"fail job {job.id}") is not None:
            log.warning("scheduler %s: job %s %s", self.id, job.id, error)
            self._drop(job.id)

    def _finish(self, job: ActiveJob) -> None:
        """Succeed a job whose runs are done, once the store is seen to hold all they made; a hole
        (results the store acknowledged and then lost) re-opens it to resume, twice at most, then
        fails it saying so: never a success over a hole."""
        runs = job.runs.values()
        evaluations, generations = sum(r.evaluations for r in runs), sum(r.generations for r in runs)
        if self._reopened.get(job.id, 0) >= _MAX_REOPEN:
            message = (f"the store lost results it had acknowledged, and still lacks some after {_MAX_REOPEN} "
                       "resumes: see the scheduler's log")
            if self._db(lambda s: finish_job(s, self.id, job.id, JobState.failed, error=message),
                        f"fail job {job.id}") is not None:
                self._drop(job.id)
            return
        finished = self._db(partial(finish_if_complete, scheduler_id=self.id, job_id=job.id, evaluations=evaluations,
                                    generations=generations, planned=job.plan.total()), f"finish job {job.id}")
        if finished == "lost":
            self._drop(job.id)  # no longer ours: cancelled or taken over
        elif finished == "finished":
            log.info("scheduler %s: job %s succeeded", self.id, job.id)
            self._reopened.pop(job.id, None)
            self._drop(job.id)
        elif finished == "reopened":
            self._reopened[job.id] = self._reopened.get(job.id, 0) + 1
            log.error("scheduler %s: job %s: the store lacks results it had acknowledged (expected %d evaluations "
                      "and %d generations); the job is given back to resume and recompute them",
                      self.id, job.id, evaluations, generations)
            self._drop(job.id)

    def _flush(self) -> None:
        """Hand each job's new results to the writer; drop the jobs it found lost."""
        self._next_flush = time.monotonic() + self.config.flush_s
        for job in self.jobs.values():
            writes = job.take_writes()
            if writes is not None:
                self.writer.put(job.id, writes)
        for job_id in self.writer.lost():
            self._drop(job_id)


def _writer(db: Database, scheduler_id: str, writers: int) -> Writer | WriterProcess | WriterPool:
    """The scheduler's writer: in a process of its own, unless the store is an in-memory SQLite
    database (which only this process sees); ``writers`` of them on PostgreSQL."""
    if in_memory(db.url):
        return Writer(db, scheduler_id)
    if writers > 1 and db.engine.dialect.name == "postgresql":
        return WriterPool(db, scheduler_id, writers)
    return WriterProcess(db, scheduler_id)


def _first_designs(requests: deque[Request], designs: int) -> list[Request]:
    """The smallest requests, while they hold no more than ``designs`` designs together. A sweep's request
    (a road's whole grid) that does not fit is split in ``requests``: its first designs that fit are taken,
    the rest stays (its keys hashed and looked up at once stopped the loop for ~1.5 s a road of the big plan,
    nothing dispatched meanwhile). A DE generation is taken whole (at least one request)."""
    out: list[Request] = []
    room = designs
    for request in sorted(requests, key=len):
        if len(request) > room and not request.waited and room > 0:
            head, rest = request.split(room)
            at = next(i for i, r in enumerate(requests) if r is request)
            requests[at] = rest
            requests.insert(at, head)
            request = head
        elif out and len(request) > room:
            break
        out.append(request)
        room -= len(request)
    return out


def _load(session: Any, job_id: int
          ) -> tuple[dict[str, Any], dict[int, Road], bool, set[tuple[int, int]], dict[int, Any]]:
    """A claimed job's spec, the stored road profiles it names and, when it has stored results, what
    it needs to resume."""
    job = session.get(Job, job_id)
    assert job is not None
    ids = sorted(profile_ids(job.spec.get("roads", [])))
    profiles = profile_roads(session, ids) if ids else {}
    resumed = job.n_done + job.n_failed > 0
    if not resumed:
        return dict(job.spec), profiles, False, set(), {}
    sweep_step = PAPER_SWEEP_STEP if job.kind == "paper-study" else 0
    de_states = {i: (with_population(g.state, g.population, g.fitness_m), g.generation)
                 for i, g in last_generations(session, job_id).items()}
    return dict(job.spec), profiles, True, stored_slots(session, job_id, sweep_step), de_states


def _lookup(session: Any, job: ActiveJob, requests: list[Request]
            ) -> tuple[list[tuple[dict[int, float], list[str]]], dict[str, dict[str, Any]]]:
    """What the store knows of requests: for each, its stored slots (a resumed job) and the cache
    keys of the rest; and the result-cache hits among all those keys (one query)."""
    out = []
    for request in requests:
        stored = (stored_fitness(session, job.id, request.road, request.step, request.candidates)
                  if job.resumed else {})
        rest = request.part(np.array([i for i, c in enumerate(request.candidates) if int(c) not in stored],
                                     dtype=int))
        out.append((stored, design_keys(job.contexts[request.road], rest.designs)))
    return out, cached_evaluations(session, [key for _, keys in out for key in keys])


def run_scheduler(settings: Settings, stop: threading.Event, *, scheduler_id: str | None = None,
                  handle_signals: bool = False) -> None:
    """A scheduler on ``settings.db_url`` with the configured executor, until ``stop`` is set
    (or, with ``handle_signals``, SIGTERM or SIGINT arrives: installed once the executor, which may
    start Ray, is up, so they are ours)."""
    from finaldrive.service.services import open_database
    from finaldrive.workers import make_executor

    gc.set_threshold(*GC_THRESHOLDS)
    db = open_database(settings)
    db.lock_timeout_s = SCHEDULER_LOCK_TIMEOUT_S
    if not in_memory(db.url):
        start_fork_server()   # the writer's, while Ray starts and the engine compiles
    # on a Ray cluster, one scheduler drives it; another waits as its standby until ``stop``
    executor = make_executor(settings.executor, num_workers=settings.num_workers, address=settings.ray_address,
                             niceness=settings.niceness, standby=stop, task_cpus=settings.task_cpus)
    config = SchedulerConfig(lease_s=settings.lease_seconds, heartbeat_s=settings.heartbeat_seconds,
                             max_jobs=settings.max_jobs, max_backlog_rows=settings.max_backlog_rows,
                             batch_size=settings.batch_size, writers=settings.writers,
                             max_simulation_s=settings.max_simulation_seconds,
                             max_job_cpu_s=settings.max_job_cpu_hours * 3600)
    if handle_signals:
        for signum in (signal.SIGTERM, signal.SIGINT):
            signal.signal(signum, lambda *_: stop.set())
    try:
        Scheduler(db, executor, config=config, scheduler_id=scheduler_id, executor_kind=settings.executor).run(stop)
    finally:
        executor.close()
        db.dispose()
