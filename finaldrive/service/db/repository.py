"""Queries and writes of the API: jobs, their roads and evaluations, recordings.

Every function takes the session it works in. The scheduler's own path through the store is
in :mod:`finaldrive.service.db.leases` and :mod:`finaldrive.service.db.results`.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import Row, func, or_, select, text, update
from sqlalchemy.orm import Session, undefer

from finaldrive.engine import Road
from finaldrive.service.db.models import ACTIVE_STATES, Evaluation, Job, JobRoad, JobState, Recording, RoadProfile


def utcnow() -> datetime:
    """Naive UTC (what the DateTime columns store)."""
    return datetime.now(UTC).replace(tzinfo=None)


# ---------------------------------------------------------------------- jobs
def create_job(
    session: Session, *, kind: str, spec: dict[str, Any], request_hash: str,
    idempotency_key: str | None, total: int, roads: Sequence[tuple[str, str]], cost_cpu_s: float | None = None,
) -> Job:
    job = Job(
        kind=kind, state=JobState.queued.value, spec=spec, request_hash=request_hash,
        idempotency_key=idempotency_key, total=total, n_done=0, n_failed=0, n_cached=0,
        completed_at_resume=0, created_at=utcnow(), cost_cpu_s=cost_cpu_s,
    )
    session.add(job)
    session.flush()
    session.add_all(
        JobRoad(job_id=job.id, road_index=i, name=name, spec=spec_text)
        for i, (name, spec_text) in enumerate(roads)
    )
    return job


def job_by_idempotency_key(session: Session, key: str) -> Job | None:
    return session.scalars(select(Job).where(Job.idempotency_key == key)).one_or_none()


def expire_idempotency_key(session: Session, key: str, *, older_than: timedelta) -> None:
    """Take ``key`` from the job it names if that job was created more than ``older_than`` ago."""
    session.execute(update(Job).where(Job.idempotency_key == key, Job.created_at < utcnow() - older_than)
                    .values(idempotency_key=None))


def list_jobs(
    session: Session, *, state: str | None, kind: str | None, before_id: int | None, limit: int
) -> list[Job]:
    """Newest first; ``before_id`` is the cursor (the last id of the previous page)."""
    query = select(Job).order_by(Job.id.desc()).limit(limit)
    if state is not None:
        query = query.where(Job.state == state)
    if kind is not None:
        query = query.where(Job.kind == kind)
    if before_id is not None:
        query = query.where(Job.id < before_id)
    return list(session.scalars(query))


def roads_of(session: Session, job_ids: Sequence[int]) -> dict[int, list[tuple[JobRoad, Evaluation | None]]]:
    """Each job's roads, in order, with the best evaluation on each (one query)."""
    out: dict[int, list[tuple[JobRoad, Evaluation | None]]] = {i: [] for i in job_ids}
    query = (
        select(JobRoad, Evaluation)
        .outerjoin(Evaluation, Evaluation.id == JobRoad.best_evaluation_id)
        .where(JobRoad.job_id.in_(job_ids))
        .order_by(JobRoad.job_id, JobRoad.road_index)
    )
    for road, best in session.execute(query):
        out[road.job_id].append((road, best))
    return out


def cancel_job(session: Session, job_id: int) -> bool:
    """Move an active job to ``cancelled`` (its scheduler stops it at its next heartbeat);
    False if it was already finished."""
    result = session.execute(
        update(Job)
        .where(Job.id == job_id, Job.state.in_([s.value for s in ACTIVE_STATES]))
        .values(state=JobState.cancelled.value, finished_at=utcnow(), owner=None, lease_until=None)
    )
    return bool(result.rowcount)  # type: ignore[attr-defined]


class LimitReached(Exception):
    """The store holds as many of something as the service allows: 429 with the setting when room is
    made by time (jobs, recordings finish), else 507 (``lasting``: road profiles are kept)."""

    def __init__(self, detail: str, *, lasting: bool = False) -> None:
        super().__init__(detail)
        self.lasting = lasting


def check_room(session: Session, what: str, count_query: Any, limit: int, setting: str, *,
               lasting: bool = False) -> None:
    """Raise :class:`LimitReached` if ``count_query`` (a count in this transaction) is at ``limit``. On
    PostgreSQL the transaction first takes an advisory lock of its own for ``setting``, so concurrent
    requests count one after another (SQLite's write transactions are serial already)."""
    if session.get_bind().dialect.name == "postgresql":
        session.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": zlib.crc32(setting.encode())})
    count = int(session.scalar(count_query) or 0)
    if count >= limit:
        then = "raise the setting" if lasting else "retry once some have finished"
        raise LimitReached(f"{count} {what} already, the limit is {limit} ({setting}); {then}", lasting=lasting)


def active_jobs_count() -> Any:
    return select(func.count()).select_from(Job).where(Job.state.in_([s.value for s in ACTIVE_STATES]))


def pending_recordings_count() -> Any:
    return select(func.count()).select_from(Recording).where(Recording.status.in_(("queued", "running")))


def profiles_count() -> Any:
    return select(func.count()).select_from(RoadProfile)


def count_active(session: Session) -> int:
    states = [s.value for s in ACTIVE_STATES]
    return int(session.scalar(select(func.count()).select_from(Job).where(Job.state.in_(states))) or 0)


def job_progress(session: Session, job_ids: Sequence[int]) -> Sequence[Row[int, str, str, int, int, int]]:
    """(id, kind, state, n_done, n_failed, total) of every unfinished job and of ``job_ids``, in one query."""
    active = Job.state.in_([s.value for s in ACTIVE_STATES])
    query = select(Job.id, Job.kind, Job.state, Job.n_done, Job.n_failed, Job.total).order_by(Job.id)
    return session.execute(query.where(or_(active, Job.id.in_(job_ids)) if job_ids else active)).all()


# ---------------------------------------------------------------------- evaluations
def list_evaluations(
    session: Session, job_id: int, *, road_index: int | None, after_id: int | None, limit: int
) -> list[Evaluation]:
    """Oldest first; ``after_id`` is the cursor (the last id of the previous page)."""
    query = select(Evaluation).where(Evaluation.job_id == job_id).order_by(Evaluation.id).limit(limit)
    if road_index is not None:
        query = query.where(Evaluation.road_index == road_index)
    if after_id is not None:
        query = query.where(Evaluation.id > after_id)
    return list(session.scalars(query))


# ---------------------------------------------------------------------- road profiles
def profile_by_hash(session: Session, digest: str) -> RoadProfile | None:
    return session.scalars(select(RoadProfile).where(RoadProfile.content_hash == digest)).one_or_none()


def create_profile(session: Session, road: Road, *, name: str, digest: str) -> RoadProfile:
    """Store a profile road (validated by the engine); ``digest`` is its content hash."""
    profile = RoadProfile(
        name=name, content_hash=digest, n_points=len(road.xs), x_min_m=road.xs[0], x_max_m=road.xs[-1],
        y_min_m=min(road.ys), y_max_m=max(road.ys), xs=list(road.xs), ys=list(road.ys), created_at=utcnow(),
    )
    session.add(profile)
    session.flush()
    return profile


def list_profiles(session: Session, *, before_id: int | None, limit: int) -> list[RoadProfile]:
    """Newest first, without their points; ``before_id`` is the cursor."""
    query = select(RoadProfile).order_by(RoadProfile.id.desc()).limit(limit)
    if before_id is not None:
        query = query.where(RoadProfile.id < before_id)
    return list(session.scalars(query))


def profile_roads(session: Session, ids: Sequence[int]) -> dict[int, Road]:
    """The stored profiles among ``ids`` as roads named by their id (spec ``profile:ID``)."""
    rows = session.scalars(select(RoadProfile).options(undefer(RoadProfile.xs), undefer(RoadProfile.ys))
                           .where(RoadProfile.id.in_(ids)))
    return {r.id: Road.from_points(r.xs, r.ys, name=str(r.id)) for r in rows}


# ---------------------------------------------------------------------- recordings
def create_recording(session: Session, job_id: int | None, spec: dict[str, Any]) -> Recording:
    recording = Recording(job_id=job_id, spec=spec, status="queued", created_at=utcnow())
    session.add(recording)
    session.flush()
    return recording


def finish_recording(session: Session, recording_id: int, owner: str, status: str, *,
                     content: bytes | None = None, error: str | None = None) -> None:
    """A recording this scheduler produced: ``succeeded`` (with its .rrd file) or ``failed`` (the
    message is kept in ``spec["error"]``)."""
    recording = session.get(Recording, recording_id)
    if recording is None or recording.owner != owner or recording.status != "running":
        return  # its lease lapsed and another scheduler took it over
    recording.status = status
    recording.content = content
    recording.size_bytes = None if content is None else len(content)
    recording.owner = None
    recording.lease_until = None
    if error is not None:
        recording.spec = {**recording.spec, "error": error}
