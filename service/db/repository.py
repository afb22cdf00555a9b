"""Queries and writes of the results store; every function takes the session it works in."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from finaldrive.service.db.models import (
    ACTIVE_STATES,
    EvalStatus,
    Evaluation,
    Generation,
    Job,
    JobRoad,
    JobState,
    Recording,
)

#: Rows per ``IN (...)`` query, well under SQLite's variable limit.
_IN_CHUNK = 500


def utcnow() -> datetime:
    """Naive UTC (what the DateTime columns store)."""
    return datetime.now(UTC).replace(tzinfo=None)


@dataclass(frozen=True)
class EvalRow:
    """One evaluation to store (SI units; fitness None when the simulation failed)."""

    road_index: int
    step: int
    candidate: int
    a2: float
    l2: float
    rws: float
    distance_m: float | None
    squat_ratio: float | None
    slack_m: float | None
    fitness_m: float | None
    chain_length_m: float | None
    status: str
    reason: str
    wall_s: float
    cached: bool
    cache_key: str


# ---------------------------------------------------------------------- jobs
def create_job(
    session: Session, *, kind: str, spec: dict[str, Any], request_hash: str,
    idempotency_key: str | None, total: int, roads: Sequence[tuple[str, str]],
) -> Job:
    job = Job(
        kind=kind, state=JobState.queued.value, spec=spec, request_hash=request_hash,
        idempotency_key=idempotency_key, total=total, n_done=0, n_failed=0, n_cached=0,
        completed_at_resume=0, created_at=utcnow(),
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
    """Move an active job to ``cancelled``; False if it was already terminal."""
    result = session.execute(
        update(Job)
        .where(Job.id == job_id, Job.state.in_([s.value for s in ACTIVE_STATES]))
        .values(state=JobState.cancelled.value, finished_at=utcnow())
    )
    return bool(result.rowcount)  # type: ignore[attr-defined]


def interrupt_running(session: Session) -> None:
    """Jobs left ``running`` by a process that died become ``interrupted``."""
    session.execute(
        update(Job).where(Job.state == JobState.running.value).values(state=JobState.interrupted.value)
    )


def unfinished_job_ids(session: Session) -> list[int]:
    states = [JobState.queued.value, JobState.interrupted.value]
    return list(session.scalars(select(Job.id).where(Job.state.in_(states)).order_by(Job.id)))


def count_active(session: Session) -> int:
    states = [s.value for s in ACTIVE_STATES]
    return int(session.scalar(select(func.count()).select_from(Job).where(Job.state.in_(states))) or 0)


def claim_job(session: Session, job_id: int) -> Job | None:
    """Start (or resume) a queued or interrupted job; None if it is no longer runnable."""
    job = session.get(Job, job_id)
    if job is None or job.state not in (JobState.queued.value, JobState.interrupted.value):
        return None
    now = utcnow()
    job.state = JobState.running.value
    job.started_at = job.started_at or now
    job.resumed_at = now
    job.completed_at_resume = job.n_done + job.n_failed
    return job


def finish_job(session: Session, job_id: int, state: JobState, *, error: str | None = None) -> None:
    """Running -> ``state`` (a cancelled job stays cancelled). A success fixes ``total``."""
    values: dict[str, Any] = {"state": state.value, "finished_at": utcnow(), "error": error}
    if state is JobState.succeeded:
        values["total"] = Job.n_done + Job.n_failed
    session.execute(update(Job).where(Job.id == job_id, Job.state == JobState.running.value).values(**values))


def set_running_to(session: Session, job_ids: Sequence[int], state: JobState) -> None:
    session.execute(
        update(Job).where(Job.id.in_(job_ids), Job.state == JobState.running.value).values(state=state.value)
    )


# ---------------------------------------------------------------------- evaluations
def stored_slots(session: Session, job_id: int, *, step: int | None = None) -> set[tuple[int, int]]:
    """(road_index, candidate) of a sweep's stored evaluations (only those at ``step`` if given)."""
    query = select(Evaluation.road_index, Evaluation.candidate).where(Evaluation.job_id == job_id)
    if step is not None:
        query = query.where(Evaluation.step == step)
    return {(r, c) for r, c in session.execute(query)}


def cached_evaluations(session: Session, keys: Iterable[str]) -> dict[str, Evaluation]:
    """The first stored evaluation for each cache key that has one."""
    wanted = sorted(set(keys))
    out: dict[str, Evaluation] = {}
    for start in range(0, len(wanted), _IN_CHUNK):
        chunk = wanted[start:start + _IN_CHUNK]
        query = select(Evaluation).where(Evaluation.cache_key.in_(chunk)).order_by(Evaluation.id)
        for e in session.scalars(query):
            out.setdefault(e.cache_key, e)
    return out


def add_evaluations(session: Session, job_id: int, rows: Sequence[EvalRow]) -> None:
    """Insert rows, bump the job's counters and each road's best, in the caller's transaction."""
    if not rows:
        return
    now = utcnow()
    objects = [Evaluation(job_id=job_id, created_at=now, **row.__dict__) for row in rows]
    session.add_all(objects)
    session.flush()
    ok = [e for e in objects if e.status == EvalStatus.ok.value]
    job = session.get(Job, job_id)
    assert job is not None
    job.n_done += len(ok)
    job.n_failed += len(objects) - len(ok)
    job.n_cached += sum(e.cached for e in objects)
    best: dict[int, Evaluation] = {}
    for e in ok:
        current = best.get(e.road_index)
        if current is None or _better(e.fitness_m, current.fitness_m):
            best[e.road_index] = e
    for road_index, e in best.items():
        road = session.get(JobRoad, (job_id, road_index))
        assert road is not None
        if road.best_fitness is None or _better(e.fitness_m, road.best_fitness):
            road.best_fitness = e.fitness_m
            road.best_evaluation_id = e.id


def _better(a: float | None, b: float | None) -> bool:
    return a is not None and math.isfinite(a) and (b is None or a > b)


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


# ---------------------------------------------------------------------- DE generations
def add_generation(
    session: Session, job_id: int, *, run: int, generation: int, state: dict[str, Any],
    population: list[list[float]], fitness: list[float | None], best_f: float | None, n_evals: int,
) -> None:
    session.add(Generation(
        job_id=job_id, run=run, generation=generation, state=state, population=population,
        fitness=fitness, best_f=best_f, n_evals=n_evals, created_at=utcnow(),
    ))


def last_generations(session: Session, job_id: int) -> dict[int, Generation]:
    """The latest stored generation of each DE run of a job."""
    latest = (
        select(Generation.run, func.max(Generation.generation).label("g"))
        .where(Generation.job_id == job_id).group_by(Generation.run).subquery()
    )
    query = select(Generation).join(
        latest, (Generation.run == latest.c.run) & (Generation.generation == latest.c.g)
    ).where(Generation.job_id == job_id)
    return {g.run: g for g in session.scalars(query)}


# ---------------------------------------------------------------------- recordings
def create_recording(session: Session, job_id: int | None, spec: dict[str, Any]) -> Recording:
    recording = Recording(job_id=job_id, spec=spec, status="queued", created_at=utcnow())
    session.add(recording)
    session.flush()
    return recording


def set_recording(session: Session, recording_id: int, status: str, *, path: str | None = None,
                  error: str | None = None) -> None:
    """Move a recording to ``status``; a failure's message is kept in ``spec["error"]``."""
    recording = session.get(Recording, recording_id)
    assert recording is not None
    recording.status = status
    recording.path = path
    if error is not None:
        recording.spec = {**recording.spec, "error": error}


def unfinished_recording_ids(session: Session) -> list[int]:
    query = select(Recording.id).where(Recording.status.in_(["queued", "running"])).order_by(Recording.id)
    return list(session.scalars(query))

