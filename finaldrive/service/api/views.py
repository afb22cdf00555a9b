"""Database rows -> response bodies."""

from __future__ import annotations

import math
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session

from finaldrive.engine import VALUES
from finaldrive.service.db.models import Evaluation, Generation, Job, JobRoad, JobState
from finaldrive.service.db.repository import roads_of, utcnow
from finaldrive.service.schemas import EvaluationOut, JobOut, JobSpec, RoadProgress, RobustBest


def _aware(t: datetime | None) -> datetime | None:
    return None if t is None else t.replace(tzinfo=UTC)


def evaluation_out(e: Evaluation, road_name: str) -> EvaluationOut:
    return EvaluationOut(
        id=e.id, road_index=e.road_index, road=road_name, step=e.step, candidate=e.candidate,
        a2_deg=e.a2_deg, l2_m=e.l2_m, rws_m=e.rws_m, status=e.status, reason=e.reason, cached=e.cached,
        **{name: getattr(e, name) for name in VALUES},
    )


def road_progress(roads: list[tuple[JobRoad, Evaluation | None]]) -> list[RoadProgress]:
    return [
        RoadProgress(
            index=r.road_index, name=r.name, spec=r.spec, best=None if best is None else evaluation_out(best, r.name)
        )
        for r, best in roads
    ]


def robust_best(session: Session, job: Job) -> RobustBest | None:
    """The best design of a robust-de job by its aggregate score (latest generation)."""
    if job.kind != "robust-de":
        return None
    row = session.execute(
        select(Generation.generation, Generation.population, Generation.best_fitness_m)
        .where(Generation.job_id == job.id, Generation.run == 0)
        .order_by(Generation.generation.desc()).limit(1)
    ).first()
    if row is None or not row.population:
        return None
    a2, l2, rws = row.population[0]  # the optimiser's state: a2 in rad
    return RobustBest(
        aggregate=job.spec.get("aggregate") or "mean", score_m=row.best_fitness_m, a2_deg=math.degrees(a2),
        l2_m=l2, rws_m=rws, generation=row.generation,
    )


def job_out(
    session: Session, job: Job, roads: list[tuple[JobRoad, Evaluation | None]], *, detail: bool
) -> JobOut:
    completed = job.n_done + job.n_failed
    now = utcnow()
    elapsed = None
    if job.started_at is not None:
        elapsed = ((job.finished_at or now) - job.started_at).total_seconds()
    return JobOut(
        id=job.id, kind=job.kind,
        state=job.state,
        spec=JobSpec.model_validate(job.spec), total=job.total, done=job.n_done, failed=job.n_failed,
        cached=job.n_cached, progress=min(1.0, completed / job.total) if job.total else 1.0,
        created_at=_aware(job.created_at),
        started_at=_aware(job.started_at), finished_at=_aware(job.finished_at),
        elapsed_s=elapsed, eta_s=_eta(job, completed, now), error=job.error,
        roads=road_progress(roads), robust_best=robust_best(session, job) if detail else None,
    )


def _eta(job: Job, completed: int, now: datetime) -> float | None:
    """Remaining evaluations at the rate observed since the job last (re)started."""
    if job.state != JobState.running.value or job.resumed_at is None:
        return None
    since = completed - job.completed_at_resume
    seconds = (now - job.resumed_at).total_seconds()
    if since <= 0 or seconds <= 0:
        return None
    return max(0, job.total - completed) * seconds / since


def jobs_out(session: Session, jobs: list[Job]) -> list[JobOut]:
    roads = roads_of(session, [j.id for j in jobs])
    return [job_out(session, j, roads[j.id], detail=False) for j in jobs]
