"""A bound on the heavy answers built at once (plots, /points): memory stays flat under a burst.

A request waits for one of ``slots`` (without holding a worker thread) at most ``wait_s``, then
gets 503 with Retry-After; the work itself runs in a worker thread.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import TypeVar

import anyio

from finaldrive.service.api.problems import RETRY_AFTER_S, ApiProblem

T = TypeVar("T")


class RenderSlots:
    def __init__(self, slots: int, wait_s: float) -> None:
        self.slots = slots
        self.wait_s = wait_s
        self._semaphore = asyncio.Semaphore(slots)

    async def run(self, work: Callable[..., T], *args: object) -> T:
        """``work(*args)`` in a worker thread, once a slot is free."""
        try:
            await asyncio.wait_for(self._semaphore.acquire(), self.wait_s)
        except TimeoutError:
            raise ApiProblem(503, f"the server is busy rendering ({self.slots} at once, "
                             f"FINALDRIVE_MAX_CONCURRENT_RENDERS); retry later", slug="busy",
                             headers={"Retry-After": str(RETRY_AFTER_S)}) from None
        try:
            return await anyio.to_thread.run_sync(lambda: work(*args))
        finally:
            self._semaphore.release()
