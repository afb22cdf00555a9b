"""One poll of the store for every open event stream and status snapshot, fanned out to them.

Each tick (``events_poll_seconds``) reads, in one query and in a worker thread, the progress of
the jobs that are not finished plus those streams watch, and hands each stream the jobs that
changed. A stream's mailbox keeps only the latest state of each job: a slow reader skips
intermediate progress and never holds the hub up. The same tick rebuilds the GET /v1/jobs/{id}
snapshots (finaldrive.service.status_cache) of the jobs that changed. The hub runs while streams
are open or unfinished jobs' snapshots are read; the number of streams is capped in total and per
client address.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
from collections import Counter
from dataclasses import dataclass
from typing import Any

import anyio
from sqlalchemy import select
from sqlalchemy.exc import SQLAlchemyError

from finaldrive.service.api.views import job_out
from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import TERMINAL_STATES, Job, JobState
from finaldrive.service.db.repository import job_progress, roads_of
from finaldrive.service.status_cache import Snapshot, StatusCache

log = logging.getLogger(__name__)
#: Streams woken together; the hub yields to the event loop between batches, so that a request
#: arriving during a tick waits for at most one batch of streams, not for all of them.
WAKE_BATCH = 16
#: States in which a job's body changes with time alone (elapsed_s, eta_s).
_STARTED_STATES = frozenset({JobState.running.value, JobState.interrupted.value})


@dataclass(frozen=True)
class JobProgress:
    id: int
    kind: str
    state: str
    done: int
    failed: int
    total: int

    @property
    def finished(self) -> bool:
        return JobState(self.state) in TERMINAL_STATES

    def counts(self) -> dict[str, Any]:
        """The body of a job stream's events."""
        return {"state": self.state, "done": self.done, "failed": self.failed, "total": self.total}

    @functools.cached_property
    def progress_event(self) -> bytes:
        """The job stream's ``progress`` event, encoded once however many streams send it."""
        return sse_event("progress", self.counts())

    def summary(self) -> dict[str, Any]:
        """An item of the jobs stream."""
        progress = (self.done + self.failed) / self.total if self.total else 0.0
        return {"id": self.id, "kind": self.kind, **self.counts(), "progress": round(min(progress, 1.0), 4)}


def sse_event(name: str, data: Any) -> bytes:
    """A server-sent event: its name and one line of JSON."""
    return f"event: {name}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n".encode()


def read_progress(db: Database, job_ids: list[int]) -> list[JobProgress]:
    """Every unfinished job and those of ``job_ids``, in one query."""
    with db.read() as session:
        return [JobProgress(*row) for row in job_progress(session, job_ids)]


def status_snapshots(db: Database, job_ids: list[int]) -> dict[int, Snapshot]:
    """The GET /v1/jobs/{id} bodies of the jobs of ``job_ids`` that exist, serialised, from one read."""
    with db.read() as session:
        jobs = session.scalars(select(Job).where(Job.id.in_(job_ids))).all()
        roads = roads_of(session, [job.id for job in jobs])
        return {job.id: Snapshot(
            body=job_out(session, job, roads[job.id], detail=True).model_dump_json().encode(),
            version=JobProgress(job.id, job.kind, job.state, job.n_done, job.n_failed, job.total),
            final=JobState(job.state) in TERMINAL_STATES,
        ) for job in jobs}


class TooManyStreams(Exception):
    """A cap on open streams is reached; the message names it."""


class Subscriber:
    """A stream's mailbox: ``job_id`` None watches every job (the first delivery: all unfinished ones)."""

    def __init__(self, client: str, job_id: int | None) -> None:
        self.client = client
        self.job_id = job_id
        self._fresh = True
        self._pending: dict[int, JobProgress] = {}
        self._wake = asyncio.Event()

    def deliver(self, changed: list[JobProgress], known: dict[int, JobProgress]) -> None:
        """Take a tick's news (never blocks: a newer state of a job replaces one not yet read)."""
        if self._fresh:
            self._fresh = False
            items = [p for p in known.values() if not p.finished] if self.job_id is None else (
                [known[self.job_id]] if self.job_id in known else [])
        else:
            items = [p for p in changed if self.job_id in (None, p.id)]
            if not items:
                return
        self._pending.update((p.id, p) for p in items)
        self._wake.set()

    async def take(self) -> list[JobProgress]:
        """The latest state of each job that changed since the last take (the first: possibly empty)."""
        await self._wake.wait()
        self._wake.clear()
        items, self._pending = list(self._pending.values()), {}
        return items


class EventHub:
    def __init__(self, db: Database, status: StatusCache, *, poll_s: float, max_streams: int,
                 max_per_client: int) -> None:
        self.db = db
        self.status = status
        self.poll_s = poll_s
        self.max_streams = max_streams
        self.max_per_client = max_per_client
        #: store reads so far (one a tick, whatever the number of streams)
        self.reads = 0
        self._subscribers: set[Subscriber] = set()
        self._per_client: Counter[str] = Counter()
        self._known: dict[int, JobProgress] = {}
        self._task: asyncio.Task[None] | None = None

    @property
    def streams(self) -> int:
        return len(self._subscribers)

    def subscribe(self, client: str, job_id: int | None) -> Subscriber:
        """A new stream's mailbox (the hub starts with the first); :class:`TooManyStreams` above a cap."""
        if len(self._subscribers) >= self.max_streams:
            raise TooManyStreams(f"{len(self._subscribers)} event streams are open, the server's limit "
                                 f"(FINALDRIVE_MAX_STREAMS = {self.max_streams})")
        if self._per_client[client] >= self.max_per_client:
            raise TooManyStreams(f"{self._per_client[client]} event streams are open from {client}, the limit "
                                 f"per client (FINALDRIVE_MAX_STREAMS_PER_CLIENT = {self.max_per_client})")
        subscriber = Subscriber(client, job_id)
        self._subscribers.add(subscriber)
        self._per_client[client] += 1
        self.start()
        return subscriber

    def start(self) -> None:
        """Run the hub unless it runs (it stops once no stream is open and no unfinished job's snapshot is read)."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="finaldrive-event-hub")

    def unsubscribe(self, subscriber: Subscriber) -> None:
        if subscriber in self._subscribers:
            self._subscribers.discard(subscriber)
            self._per_client[subscriber.client] -= 1
            if not self._per_client[subscriber.client]:
                del self._per_client[subscriber.client]

    async def tick(self) -> None:
        """One read of the store, its news to every subscriber, and the snapshots of changed jobs rebuilt."""
        watched = {s.job_id for s in self._subscribers if s.job_id is not None}
        watched |= {p.id for p in self._known.values() if not p.finished}  # so their end is seen
        watched.update(self.status.watched())
        try:
            rows = await anyio.to_thread.run_sync(self._read, sorted(watched))
        except SQLAlchemyError as exc:  # the store is unavailable: streams wait for the next tick
            log.warning("event hub: store unavailable: %s", " ".join(str(exc).split())[:300])
            return
        changed = [p for p in rows if self._known.get(p.id) != p]
        self._known = {p.id: p for p in rows}
        for i, subscriber in enumerate(list(self._subscribers), start=1):
            subscriber.deliver(changed, self._known)
            if i % WAKE_BATCH == 0:
                await asyncio.sleep(0)  # let what else waits on the loop (an API request) run between batches
        await self._refresh_snapshots(rows)

    async def _refresh_snapshots(self, rows: list[JobProgress]) -> None:
        started = {p.id for p in rows if p.state in _STARTED_STATES}  # their elapsed_s grows
        stale = self.status.outdated(self._known, started)
        if not stale:
            return
        since = self.status.generation
        try:
            built = await anyio.to_thread.run_sync(status_snapshots, self.db, stale)
        except SQLAlchemyError as exc:  # kept until the next tick; not served once STALE_S old
            log.warning("event hub: status snapshots not rebuilt: %s", " ".join(str(exc).split())[:300])
            return
        self.status.store(built, since)

    def _read(self, job_ids: list[int]) -> list[JobProgress]:
        self.reads += 1
        return read_progress(self.db, job_ids)

    async def _run(self) -> None:
        try:
            while self._subscribers or self.status.watched():
                await self.tick()
                await anyio.sleep(self.poll_s)
        finally:
            self._task = None
            self._known = {}

    async def aclose(self) -> None:
        """Stop the hub (at shutdown)."""
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
