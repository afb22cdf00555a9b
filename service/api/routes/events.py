"""Server-sent events: a job's progress until it ends, and every job's changes for the jobs page.

Both are fed by the app's :class:`~finaldrive.service.api.event_hub.EventHub` (one store read
a tick for all streams) and capped per client address and in total (429). FastAPI sends a
``: ping`` comment after 15 s without an event, so proxies keep an idle stream open.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, Request
from fastapi.sse import EventSourceResponse, ServerSentEvent

from finaldrive.service.api.deps import EventsDep, JobId, ServicesDep
from finaldrive.service.api.event_hub import JobProgress, Subscriber, TooManyStreams, read_progress
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


@router.get(
    "/jobs/{job_id}/events", response_class=EventSourceResponse, responses=documented(404, 422, 429),
    summary="Progress events: `progress` on every change, then `end` when the job is finished",
)
async def events(
    stream: Annotated[tuple[JobProgress, Subscriber], Depends(_job_stream)],
) -> AsyncIterator[ServerSentEvent]:
    current, subscriber = stream
    yield ServerSentEvent(event="progress", data=current.counts())
    while not current.finished:
        for latest in await subscriber.take():
            if latest != current:
                current = latest
                yield ServerSentEvent(event="progress", data=current.counts())
    yield ServerSentEvent(event="end", data=current.counts())


@router.get(
    "/events", response_class=EventSourceResponse, responses=documented(429),
    summary="Every job's progress for a jobs page: event `jobs`, a list of {id, kind, state, done, failed, "
            "total, progress} of the jobs that changed since the last event (the first: every unfinished job)",
)
async def jobs_events(subscriber: Annotated[Subscriber, Depends(_jobs_stream)]) -> AsyncIterator[ServerSentEvent]:
    while True:
        yield ServerSentEvent(event="jobs", data=[p.summary() for p in await subscriber.take()])
