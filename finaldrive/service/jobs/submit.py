"""Accepting a job: resolve the spec, enforce the size limit, honour Idempotency-Key."""

from __future__ import annotations

import hashlib
import json
from datetime import timedelta

from sqlalchemy.exc import IntegrityError

from finaldrive.engine import estimate_cost
from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import Job
from finaldrive.service.db.repository import (
    active_jobs_count,
    check_room,
    create_job,
    expire_idempotency_key,
    job_by_idempotency_key,
    profile_roads,
    utcnow,
)
from finaldrive.service.jobs.plan import PlanError, build_plan
from finaldrive.service.profiles import profile_ids, resolver
from finaldrive.service.schemas import JobSpec


class IdempotencyKeyReused(Exception):
    """The key was used before with a different request body."""


def request_hash(spec: JobSpec) -> str:
    canon = json.dumps(spec.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canon.encode()).hexdigest()


def submit_job(
    db: Database, spec: JobSpec, *, idempotency_key: str | None, max_evaluations: int, max_cpu_hours: float,
    max_active_jobs: int | None = None, key_hours: float = 24.0,
) -> tuple[Job, bool]:
    """(job, created). Raises PlanError (bad field, too many evaluations, too costly), IdempotencyKeyReused,
    or LimitReached (``max_active_jobs`` unfinished already). An Idempotency-Key replays its job for
    ``key_hours``; after that it is taken from the old job and may name a new one."""
    spec = spec.normalised()
    digest = request_hash(spec)
    if idempotency_key is not None:
        existing = _replay(db, idempotency_key, digest, key_hours)
        if existing is not None:
            return existing, False
    ids = sorted(profile_ids(spec.roads))
    with db.read() as session:
        stored = profile_roads(session, ids) if ids else {}
    plan = build_plan(spec, profiles=resolver(stored))
    total = plan.total()
    if total > max_evaluations:
        raise PlanError(
            (), f"the job needs {total} evaluations, more than the limit of {max_evaluations} "
            "(FINALDRIVE_MAX_JOB_EVALUATIONS)",
        )
    cost = estimate_cost(plan.settings, total, [r.road for r in plan.study.roads], plan.vehicle)
    if cost.cpu_s > max_cpu_hours * 3600:
        raise PlanError(
            ("settings",), f"the job is estimated at {cost} ({total} simulations of {plan.settings.duration:g} s, "
            f"method {plan.settings.method}, dt {plan.settings.dt:g} s, priced on its costliest road), more than "
            f"the limit of {max_cpu_hours:g} CPU-hours (FINALDRIVE_MAX_JOB_CPU_HOURS)",
        )
    try:
        with db.write() as session:
            if max_active_jobs is not None:
                check_room(session, "jobs unfinished", active_jobs_count(), max_active_jobs,
                           "FINALDRIVE_MAX_ACTIVE_JOBS")
            if idempotency_key is not None:
                expire_idempotency_key(session, idempotency_key, older_than=timedelta(hours=key_hours))
            job = create_job(
                session, kind=spec.kind, spec=spec.model_dump(mode="json"), request_hash=digest,
                idempotency_key=idempotency_key, total=total, cost_cpu_s=cost.cpu_s,
                roads=[(r.name, r.road.spec) for r in plan.study.roads],
            )
    except IntegrityError:  # a concurrent request with the same key won the race
        existing = _replay(db, idempotency_key or "", digest, key_hours)
        if existing is None:
            raise
        return existing, False
    return job, True


def _replay(db: Database, key: str, digest: str, key_hours: float) -> Job | None:
    """The job ``key`` names, unless the key has expired (then None: it may name a new job)."""
    with db.read() as session:
        job = job_by_idempotency_key(session, key)
        if job is not None and utcnow() - job.created_at > timedelta(hours=key_hours):
            return None
    if job is not None and job.request_hash != digest:
        raise IdempotencyKeyReused(key)
    return job

