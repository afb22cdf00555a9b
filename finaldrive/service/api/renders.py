"""A bound on the heavy answers built at once (plots, /points): memory stays flat under a burst.

A request waits for one of ``slots`` (without holding a worker thread) at most ``wait_s``, then
gets 503 with Retry-After; the work itself runs in a worker thread. Answers are kept by key (the
caller puts in it what they depend on, e.g. the job's state and counts) in a cache of at most
:data:`CACHE_BYTES`, and requests for an answer being built wait for that one build: ten tabs
opening the same map cost one render.
"""

from __future__ import annotations

import asyncio
from collections import OrderedDict
from collections.abc import Callable, Hashable

import anyio

from finaldrive.service.api.problems import RETRY_AFTER_S, ApiProblem

#: Bytes of answers kept for repeated requests (least recently used first out).
CACHE_BYTES = 64 * 2**20


class RenderSlots:
    def __init__(self, slots: int, wait_s: float, cache_bytes: int = CACHE_BYTES) -> None:
        self.slots = slots
        self.wait_s = wait_s
        self.cache_bytes = cache_bytes
        #: answers built so far (the cache and shared builds spare the others)
        self.builds = 0
        self._semaphore = asyncio.Semaphore(slots)
        self._cache: OrderedDict[Hashable, bytes] = OrderedDict()
        self._building: dict[Hashable, asyncio.Future[bytes]] = {}

    async def run(self, key: Hashable, work: Callable[..., bytes], *args: object) -> bytes:
        """The answer for ``key``: from the cache, from a build under way, or ``work(*args)`` in a
        worker thread once a slot is free."""
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        if key in self._building:
            return await asyncio.shield(self._building[key])
        future: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()
        self._building[key] = future
        try:
            body = await self._build(work, *args)
        except BaseException as exc:
            future.set_exception(exc)
            future.exception()  # retrieved: no "never retrieved" warning when no one else waited
            raise
        finally:
            del self._building[key]
        future.set_result(body)
        self._keep(key, body)
        return body

    def _keep(self, key: Hashable, body: bytes) -> None:
        if len(body) > self.cache_bytes:
            return
        self._cache[key] = body
        while sum(len(b) for b in self._cache.values()) > self.cache_bytes:
            self._cache.popitem(last=False)

    async def _build(self, work: Callable[..., bytes], *args: object) -> bytes:
        try:
            await asyncio.wait_for(self._semaphore.acquire(), self.wait_s)
        except TimeoutError:
            raise ApiProblem(503, f"the server is busy rendering ({self.slots} at once, "
                             f"FINALDRIVE_MAX_CONCURRENT_RENDERS); retry later", slug="busy",
                             headers={"Retry-After": str(RETRY_AFTER_S)}) from None
        try:
            self.builds += 1
            return await anyio.to_thread.run_sync(lambda: work(*args))
        finally:
            self._semaphore.release()
