"""RenderSlots: a burst of the same heavy answer is built once, kept, and errors are not kept."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from finaldrive.service.api.problems import ApiProblem
from finaldrive.service.api.renders import RenderSlots


def _slow(body: bytes, started: list[float]) -> bytes:
    started.append(time.monotonic())
    time.sleep(0.2)
    return body


def test_a_burst_of_one_answer_builds_it_once() -> None:
    async def main() -> tuple[list[bytes], RenderSlots, list[float]]:
        slots, started = RenderSlots(2, wait_s=5), []
        bodies = await asyncio.gather(*(slots.run(("map", 1), _slow, b"png", started) for _ in range(10)))
        again = await slots.run(("map", 1), _slow, b"other", started)  # kept: not rebuilt
        return [*bodies, again], slots, started

    bodies, slots, started = asyncio.run(main())
    assert bodies == [b"png"] * 11 and slots.builds == 1 and len(started) == 1


def test_a_new_key_rebuilds_and_the_cache_keeps_its_bound() -> None:
    async def main() -> RenderSlots:
        slots = RenderSlots(2, wait_s=5, cache_bytes=10)
        for version in range(4):
            assert await slots.run(("map", 1, version), lambda v=version: bytes([v]) * 4) == bytes([version]) * 4
        assert await slots.run(("map", 1, 3), lambda: b"stale") == b"\x03" * 4  # the newest is kept
        assert await slots.run(("map", 1, 0), lambda: b"again") == b"again"  # the oldest went
        return slots

    assert asyncio.run(main()).builds == 5


def test_errors_reach_every_waiter_and_are_not_kept() -> None:
    calls = threading.Semaphore(0)

    def fail() -> bytes:
        calls.release()
        time.sleep(0.1)
        raise ApiProblem(409, "no results yet", slug="no-results")

    async def main() -> list[object]:
        slots = RenderSlots(1, wait_s=5)
        outcomes = await asyncio.gather(*(slots.run("k", fail) for _ in range(3)), return_exceptions=True)
        outcomes.append(await slots.run("k", lambda: b"ok"))
        return outcomes

    outcomes = asyncio.run(main())
    assert all(isinstance(o, ApiProblem) for o in outcomes[:3]) and outcomes[3] == b"ok"
    assert calls.acquire(blocking=False) and not calls.acquire(blocking=False)  # built once


def test_a_full_queue_answers_503() -> None:
    async def main() -> None:
        slots = RenderSlots(1, wait_s=0.05)
        first = asyncio.ensure_future(slots.run("a", lambda: time.sleep(0.3) or b"a"))
        await asyncio.sleep(0.01)
        with pytest.raises(ApiProblem) as refused:
            await slots.run("b", lambda: b"")
        assert refused.value.status == 503 and refused.value.headers == {"Retry-After": "5"}
        await first

    asyncio.run(main())
