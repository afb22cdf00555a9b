"""Server-sent events: a job's progress until it ends, and every job's changes for the jobs page.

Both are fed by the app's :class:`~finaldrive.service.api.event_hub.EventHub` (one store read
a tick for all streams) and capped per client address and in total (429). Events are encoded once
a job and tick (:attr:`JobProgress.progress_event`) and written as bytes, with a ``: ping`` comment
after 15 s without one, so that proxies keep an idle stream open.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Depends, Request
from fastapi.responses import StreamingResponse

from finaldrive.service.api.deps import EventsDep, JobId, ServicesDep
from finaldrive.service.api.event_hub import JobProgress, Subscriber, TooManyStreams, read_progress, sse_event
from finaldrive.service.api.problems import RETRY_AFTER_S, ApiProblem, documented

router = APIRouter(tags=["jobs"])


def _subscribe(events: EventsDep, request: Request, job_id: int | None) -> Subscriber:
    try:
        return events.subscribe(request.client.host if request.client else "unknown", job_id)
    except TooManyStreams as exc:
        raise ApiProblem(429, f"{exc}; close a stream or retry later", slug="too-many-streams",
                         headers={"Retry-After": str(RETRY_AFTER_S)}) from None


async def _job_stream(job_id: JobId, request: Request, services: ServicesDep,
                      events: EventsDep) -> AsyncIterator[tuple[JobProgress, Subscriber]]:
    """The job's progress now (404 if it does not exist) and a mailbox, given back when the stream ends."""
    found = [p for p in await anyio.to_thread.run_sync(read_progress, services.db, [job_id]) if p.id == job_id]
    if not found:
        raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
    subscriber = _subscribe(events, request, job_id)
    try:
        yield found[0], subscriber
    finally:
        events.unsubscribe(subscriber)


async def _jobs_stream(request: Request, events: EventsDep) -> AsyncIterator[Subscriber]:
    subscriber = _subscribe(events, request, None)
    try:
        yield subscriber
    finally:
        events.unsubscribe(subscriber)


#: Each event of the stream (OpenAPI 3.2's itemSchema, as FastAPI documents its own SSE routes).
_EVENT = {"type": "object", "required": ["event", "data"], "properties": {
    "event": {"type": "string"}, "data": {"type": "string", "contentMediaType": "application/json"}}}
_SSE: dict[int | str, dict[str, Any]] = {
    200: {"content": {"text/event-stream": {"itemSchema": _EVENT}}, "description": "the event stream"}}
#: Sent after this long without an event [s], so that proxies keep an idle stream open.
PING_S = 15.0
KEEPALIVE = b": ping\n\n"


def _stream(events: AsyncIterator[bytes]) -> StreamingResponse:
    return StreamingResponse(events, media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})


async def _take(subscriber: Subscriber) -> list[JobProgress] | None:
    """The next news, or None after PING_S without any."""
    with anyio.move_on_after(PING_S):
        return await subscriber.take()
    return None


@router.get(
    "/jobs/{job_id}/events", response_class=StreamingResponse, responses={**_SSE, **documented(404, 422, 429)},
    summary="Progress events: `progress` on every change, then `end` when the job is finished",
)
async def events(stream: Annotated[tuple[JobProgress, Subscriber], Depends(_job_stream)]) -> StreamingResponse:
    first, subscriber = stream

    async def body() -> AsyncIterator[bytes]:
        current = first
        yield current.progress_event
        while not current.finished:
            news = await _take(subscriber)
            if news is None:
                yield KEEPALIVE
            for latest in news or ():
                if latest != current:
                    current = latest
                    yield current.progress_event
        yield sse_event("end", current.counts())

    return _stream(body())


@router.get(
    "/events", response_class=StreamingResponse, responses={**_SSE, **documented(429)},
    summary="Every job's progress for a jobs page: event `jobs`, a list of {id, kind, state, done, failed, "
            "total, progress} of the jobs that changed since the last event (the first: every unfinished job)",
)
async def jobs_events(subscriber: Annotated[Subscriber, Depends(_jobs_stream)]) -> StreamingResponse:
    async def body() -> AsyncIterator[bytes]:
        while True:
            news = await _take(subscriber)
            yield KEEPALIVE if news is None else sse_event("jobs", [p.summary() for p in news])

    return _stream(body())
