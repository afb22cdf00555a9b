"""/v1/jobs: submit, list, inspect and cancel jobs."""

from __future__ import annotations

from typing import Annotated

import anyio
from fastapi import APIRouter, Header, Query, Response

from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.lookups import load_job, parse_cursor
from finaldrive.service.api.problems import ApiProblem, documented, validation_problem
from finaldrive.service.api.views import jobs_out
from finaldrive.service.db.models import Job
from finaldrive.service.db.repository import cancel_job, list_jobs
from finaldrive.service.jobs.plan import PlanError
from finaldrive.service.jobs.submit import IdempotencyKeyReused, submit_job
from finaldrive.service.schemas import JobKind, JobOut, JobPage, JobSpec, JobStateName

router = APIRouter(prefix="/jobs", tags=["jobs"])


@router.post(
    "", status_code=201, response_model=JobOut,
    responses={200: {"model": JobOut, "description": "replay of an earlier request with the same Idempotency-Key"},
               **documented(400, 401, 413, 422)},
    summary="Submit a job",
    description=(
        "Creates a job and answers 201 with a Location header. With an `Idempotency-Key` header, "
        "repeating the same body returns the existing job with 200; reusing the key with a different "
        "body is refused with 422 (problem type `urn:finaldrive:problem:idempotency-key-reused`)."
    ),
)
def submit(
    spec: JobSpec, services: ServicesDep, response: Response,
    idempotency_key: Annotated[str | None, Header(max_length=255)] = None,
) -> JobOut:
    try:
        job, created = submit_job(
            services.db, spec, idempotency_key=idempotency_key,
            max_evaluations=services.settings.max_job_evaluations,
            max_cpu_hours=services.settings.max_job_cpu_hours,
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
async def get(job_id: JobId, services: ServicesDep) -> Response:
    """Answers from the status cache when a fresh enough copy exists (see StatusCache)."""
    body = services.status_cache.get(job_id)
    if body is None:
        body = (await anyio.to_thread.run_sync(load_job, services, job_id)).model_dump_json().encode()
        services.status_cache.put(job_id, body)
    return Response(body, media_type="application/json")


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
        services.status_cache.invalidate(job_id)
    return load_job(services, job_id)
