"""A short-lived cache of GET /v1/jobs/{id} bodies.

Many clients polling one job then share a database read: an answer is at most ``ttl``
seconds old (state changes made through the API, such as cancel, invalidate it at once).
"""

from __future__ import annotations

import time

#: Entries kept before expired ones are pruned.
_PRUNE_AT = 1024


class StatusCache:
    def __init__(self, ttl: float) -> None:
        self.ttl = ttl
        self._entries: dict[int, tuple[float, bytes]] = {}

    def get(self, job_id: int) -> bytes | None:
        entry = self._entries.get(job_id)
        if entry is None or time.monotonic() - entry[0] > self.ttl:
            return None
        return entry[1]

    def put(self, job_id: int, body: bytes) -> None:
        if self.ttl <= 0:
            return
        now = time.monotonic()
        if len(self._entries) >= _PRUNE_AT:
            self._entries = {k: v for k, v in self._entries.items() if now - v[0] <= self.ttl}
        self._entries[job_id] = (now, body)

    def invalidate(self, job_id: int) -> None:
        self._entries.pop(job_id, None)
