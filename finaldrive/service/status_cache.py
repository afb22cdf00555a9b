"""Snapshots of GET /v1/jobs/{id}: each job's body serialised once, kept fresh by the event hub.

Many clients polling a job then cost no store read and no serialisation each. A job's snapshot is
built on its first GET (one build however many requests wait for it) and from then on rebuilt by
the event hub (finaldrive.service.api.event_hub) at its ticks: when the job's progress (state and
counts) changed, and while it runs at least every ``max_age`` seconds (its clocks, elapsed_s and
eta_s). A finished job's body no longer changes. An API write (cancel) invalidates the job's
snapshot at once, and a build that began before an invalidation is not kept. A snapshot of an
unfinished job that the hub has not confirmed for :data:`STALE_S` (the store unavailable) is not
served; one unread for :data:`IDLE_S` is dropped; at most :data:`MAX_ENTRIES` are kept.
``max_age`` 0 turns snapshots off: every GET reads the store.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field

import anyio

#: Snapshots kept (the least recently read go first).
MAX_ENTRIES = 1024
#: An unfinished job's snapshot unread this long is dropped, and the hub stops refreshing it [s].
IDLE_S = 60.0
#: An unfinished job's snapshot the hub has not confirmed for this long is not served [s].
STALE_S = 10.0


@dataclass
class Snapshot:
    """A job's body and what it was built from: ``version`` (compared with the hub's reads) and
    ``final`` (the job had finished: the body is final)."""

    body: bytes
    version: object
    final: bool
    built: float = field(default_factory=time.monotonic)
    checked: float = field(default_factory=time.monotonic)
    read: float = field(default_factory=time.monotonic)


class StatusCache:
    """The snapshots; used from the event loop's thread only (a route running in a worker thread
    invalidates through ``anyio.from_thread``)."""

    def __init__(self, max_age: float) -> None:
        self.max_age = max_age
        self._entries: dict[int, Snapshot] = {}
        self._loading: dict[int, asyncio.Task[Snapshot | None]] = {}
        #: incremented by every invalidation: a build begun before one is not kept
        self._generation = 0

    @property
    def enabled(self) -> bool:
        return self.max_age > 0

    @property
    def generation(self) -> int:
        return self._generation

    def get(self, job_id: int) -> bytes | None:
        """The job's body, if a fresh snapshot of it is held (the hot path: a dict look-up)."""
        entry = self._entries.get(job_id)
        if entry is None:
            return None
        now = time.monotonic()
        if not entry.final and now - entry.checked > STALE_S:
            return None
        entry.read = now
        return entry.body

    async def load(self, job_id: int, build: Callable[[], Snapshot | None]) -> Snapshot | None:
        """Build the job's snapshot in a worker thread (None: no such job) and keep it; concurrent
        loads of one job share a build. The build goes on for the others if a caller leaves."""
        task = self._loading.get(job_id)
        if task is None:
            task = asyncio.get_running_loop().create_task(self._load(job_id, build))
            self._loading[job_id] = task
        return await asyncio.shield(task)

    async def _load(self, job_id: int, build: Callable[[], Snapshot | None]) -> Snapshot | None:
        since = self._generation
        try:
            snapshot = await anyio.to_thread.run_sync(build)
        finally:
            if self._loading.get(job_id) is asyncio.current_task():
                del self._loading[job_id]
        if snapshot is not None:
            self.store({job_id: snapshot}, since)
        return snapshot

    def store(self, snapshots: Mapping[int, Snapshot], since: int) -> None:
        """Keep snapshots built from reads begun at generation ``since`` (none if anything was
        invalidated since then)."""
        if not self.enabled or since != self._generation:
            return
        for job_id, snapshot in snapshots.items():
            old = self._entries.get(job_id)
            if old is not None:
                snapshot.read = old.read
            self._entries[job_id] = snapshot
        if len(self._entries) > MAX_ENTRIES:  # keep the 90 % most recently read
            recent = sorted(self._entries.items(), key=lambda item: item[1].read)[-(MAX_ENTRIES * 9 // 10):]
            self._entries = dict(recent)

    def invalidate(self, job_id: int) -> None:
        """The job changed through the API: its next GET reads the store (and waits for no build begun
        before now)."""
        self._generation += 1
        self._entries.pop(job_id, None)
        self._loading.pop(job_id, None)

    def watched(self) -> list[int]:
        """The unfinished jobs whose snapshots the hub keeps fresh (those unread for IDLE_S are dropped)."""
        now = time.monotonic()
        idle = [i for i, e in self._entries.items() if not e.final and now - e.read > IDLE_S]
        for job_id in idle:
            del self._entries[job_id]
        return [i for i, e in self._entries.items() if not e.final]

    def outdated(self, current: Mapping[int, object], running: Collection[int]) -> list[int]:
        """Unfinished jobs whose snapshot is behind ``current`` (each job's version as the hub read it
        now) or, among the ``running`` (started, not finished: their clocks move), older than
        ``max_age``; the others are confirmed fresh."""
        now = time.monotonic()
        stale = []
        for job_id, entry in self._entries.items():
            if entry.final or job_id not in current:
                continue
            if entry.version != current[job_id] or (job_id in running and now - entry.built >= self.max_age):
                stale.append(job_id)
            else:
                entry.checked = now
        return stale
