"""/v1/jobs/{id}/events: progress as server-sent events until the job ends."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends
from fastapi.sse import EventSourceResponse, ServerSentEvent

from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.problems import ApiProblem, documented
from finaldrive.service.db.models import TERMINAL_STATES, Job, JobState

router = APIRouter(prefix="/jobs", tags=["jobs"])


def _progress(services: ServicesDep, job_id: int) -> dict[str, object] | None:
    with services.db.read() as session:
        job = session.get(Job, job_id)
        if job is None:
            return None
        return {"state": job.state, "done": job.n_done, "failed": job.n_failed, "total": job.total}


async def _first_progress(job_id: JobId, services: ServicesDep) -> dict[str, object]:
    progress = await anyio.to_thread.run_sync(_progress, services, job_id)
    if progress is None:
        raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
    return progress


@router.get(
    "/{job_id}/events", response_class=EventSourceResponse, responses=documented(404, 422),
    summary="Progress events: `progress` on every change, then `end` when the job is finished",
)
async def events(
    job_id: JobId, services: ServicesDep, first: Annotated[dict[str, object], Depends(_first_progress)]
) -> AsyncIterator[ServerSentEvent]:
    current, last = first, None
    while True:
        if current != last:
            yield ServerSentEvent(event="progress", data=current)
            last = current
        if JobState(str(current["state"])) in TERMINAL_STATES:
            yield ServerSentEvent(event="end", data=current)
            return
        await anyio.sleep(services.settings.events_poll_seconds)
        latest: dict[str, object] | None = await anyio.to_thread.run_sync(_progress, services, job_id)
        current = latest or current
