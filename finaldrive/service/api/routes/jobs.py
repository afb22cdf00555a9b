"""/v1/jobs: submit, list, inspect and cancel jobs.

A job's status (GET /v1/jobs/{id}) is answered from its snapshot (finaldrive.service.status_cache),
kept fresh by the event hub: :class:`StatusFromSnapshot` serves it in front of the framework's
routing; the route below builds the snapshot when there is none.
"""

from __future__ import annotations

import re
from functools import partial
from typing import Annotated

import anyio
from fastapi import APIRouter, Header, Query, Request, Response
from starlette.types import ASGIApp, Receive, Scope, Send

from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.event_hub import EventHub, status_snapshots
from finaldrive.service.api.lookups import load_job, parse_cursor
from finaldrive.service.api.problems import ApiProblem, documented, validation_problem
from finaldrive.service.api.sharpness import OWN_KEY_PREFIXES
from finaldrive.service.api.views import jobs_out
from finaldrive.service.db.models import Job
from finaldrive.service.db.repository import cancel_job, list_jobs
from finaldrive.service.jobs.plan import PlanError
from finaldrive.service.jobs.submit import IdempotencyKeyReused, submit_job
from finaldrive.service.schemas import JobKind, JobOut, JobPage, JobSpec, JobStateName
from finaldrive.service.services import Services
from finaldrive.service.status_cache import Snapshot

router = APIRouter(prefix="/jobs", tags=["jobs"])


@router.post(
    "", status_code=201, response_model=JobOut,
    responses={200: {"model": JobOut, "description": "replay of an earlier request with the same Idempotency-Key"},
               **documented(400, 401, 413, 422, 429)},
    summary="Submit a job",
    description=(
        "Creates a job and answers 201 with a Location header. With an `Idempotency-Key` header, "
        "repeating the same body returns the existing job with 200 (for FINALDRIVE_IDEMPOTENCY_KEY_HOURS); "
        "reusing the key with a different body is refused with 422 (problem type "
        "`urn:finaldrive:problem:idempotency-key-reused`). 429 when FINALDRIVE_MAX_ACTIVE_JOBS jobs are unfinished."
    ),
)
def submit(
    spec: JobSpec, services: ServicesDep, response: Response,
    idempotency_key: Annotated[str | None, Header(max_length=255)] = None,
) -> JobOut:
    if idempotency_key is not None and idempotency_key.startswith(OWN_KEY_PREFIXES):
        raise validation_problem(("header", "idempotency-key"), f"keys starting with {' or '.join(OWN_KEY_PREFIXES)} "
                                 "are the service's own (a job's sensitivity and band jobs)")
    try:
        job, created = submit_job(
            services.db, spec, idempotency_key=idempotency_key,
            max_evaluations=services.settings.max_job_evaluations,
            max_cpu_hours=services.settings.max_job_cpu_hours,
            max_active_jobs=services.settings.max_active_jobs, key_hours=services.settings.idempotency_key_hours,
        )
    except PlanError as exc:
        raise validation_problem(("body", *exc.loc), exc.msg) from None
    except IdempotencyKeyReused:
        raise ApiProblem(
            422, "this Idempotency-Key was already used with a different request body",
            slug="idempotency-key-reused",
        ) from None
    response.status_code = 201 if created else 200
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    return load_job(services, job.id)


@router.get("", response_model=JobPage, responses=documented(422), summary="List jobs, newest first")
def list_(
    services: ServicesDep,
    state: JobStateName | None = None,
    kind: JobKind | None = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    cursor: Annotated[str | None, Query(description="next_cursor of the previous page")] = None,
) -> JobPage:
    before = parse_cursor(cursor)
    with services.db.read() as session:
        jobs = list_jobs(session, state=state, kind=kind, before_id=before, limit=limit + 1)
        items = jobs_out(session, jobs[:limit])
    return JobPage(items=items, next_cursor=str(jobs[limit - 1].id) if len(jobs) > limit else None)


@router.get("/{job_id}", response_model=JobOut, responses=documented(404, 422), summary="A job's state and progress")
async def get(job_id: JobId, request: Request) -> Response:
    """From the job's snapshot, built now if there is none (one build for concurrent requests); no
    dependency runs in a worker thread."""
    services: Services = request.app.state.services
    body = services.status_cache.get(job_id)
    if body is None:
        build = partial(_one_snapshot, services, job_id)
        if services.status_cache.enabled:
            snapshot = await services.status_cache.load(job_id, build)
            events: EventHub = request.app.state.events
            events.start()  # which keeps the snapshot fresh while the job runs
        else:
            snapshot = await anyio.to_thread.run_sync(build)
        if snapshot is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        body = snapshot.body
    return Response(body, media_type="application/json")


def _one_snapshot(services: Services, job_id: int) -> Snapshot | None:
    return status_snapshots(services.db, [job_id]).get(job_id)


#: GET /v1/jobs/{id} (an id has at most 19 digits: MAX_ID).
_STATUS_PATH = re.compile(r"/v1/jobs/([0-9]{1,19})")


class StatusFromSnapshot:
    """ASGI middleware: GET /v1/jobs/{id} answered with the job's snapshot when one is held, without
    the framework's routing, dependencies and response model (the route answers otherwise). It goes
    inside the access control: a request it answers has passed the Host and token checks."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] == "GET":
            match = _STATUS_PATH.fullmatch(scope["path"])
            if match is not None:
                services: Services = scope["app"].state.services
                body = services.status_cache.get(int(match[1]))
                if body is not None:
                    await send({"type": "http.response.start", "status": 200, "headers": [
                        (b"content-length", str(len(body)).encode()), (b"content-type", b"application/json")]})
                    await send({"type": "http.response.body", "body": body})
                    return
        await self.app(scope, receive, send)


@router.post(
    "/{job_id}/cancel", response_model=JobOut,
    responses=documented(401, 404, 422),
    summary="Cancel a job (idempotent: a finished job is returned unchanged)",
)
def cancel(job_id: JobId, services: ServicesDep) -> JobOut:
    with services.db.write() as session:
        if session.get(Job, job_id) is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        changed = cancel_job(session, job_id)
    if changed:  # the scheduler running it stops it at its next heartbeat
        anyio.from_thread.run_sync(services.status_cache.invalidate, job_id)  # the cache lives on the event loop
    return load_job(services, job_id)
