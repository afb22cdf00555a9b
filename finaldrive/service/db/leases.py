"""Ownership in the store: scheduler heartbeats and leases on jobs and recordings.

A scheduler owns a job (or a recording) while its lease lasts. Every lease and heartbeat is
judged on the database's clock, never on the scheduler's, so machines with skewed clocks agree.
A claim is a compare-and-set: ``UPDATE ... WHERE <still claimable>`` and the row count says who
won (safe under SQLite's single writer and under PostgreSQL's row locks, where the condition is
re-checked on the row a concurrent writer left). A scheduler that dies stops renewing; once its
leases expire, any scheduler (its own restart included) may claim the work and resume it from
what is stored.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import datetime, timedelta

from sqlalchemy import ColumnElement, and_, func, or_, select, text, update
from sqlalchemy.orm import Session

from finaldrive.service.db.models import Job, JobState, Recording, Scheduler as SchedulerRow

#: Job states a scheduler may claim (``running`` only once its owner's lease has expired).
_CLAIMABLE = (JobState.queued.value, JobState.interrupted.value)


def db_now(session: Session) -> datetime:
    """The database's current time, naive UTC (what the DateTime columns store)."""
    dialect = session.get_bind().dialect.name
    if dialect == "sqlite":
        value = session.execute(text("SELECT strftime('%Y-%m-%d %H:%M:%f', 'now')")).scalar_one()
        return datetime.fromisoformat(str(value))
    if dialect == "postgresql":
        value = session.execute(text("SELECT clock_timestamp() AT TIME ZONE 'UTC'")).scalar_one()
    else:
        value = session.execute(text("SELECT CURRENT_TIMESTAMP")).scalar_one()
    moment: datetime = datetime.fromisoformat(value) if isinstance(value, str) else value
    return moment.replace(tzinfo=None)


# ---------------------------------------------------------------------- schedulers
#: The longest scheduler id the store keeps (``schedulers.id``, ``jobs.owner``, ``recordings.owner``).
MAX_SCHEDULER_ID = SchedulerRow.__table__.c.id.type.length  # type: ignore[attr-defined]


def scheduler_id(name: str, suffix: str) -> str:
    """``name + suffix`` cut to fit the store: the name (a host name may be long) gives way, the suffix
    (a pid, a random tag) is kept whole."""
    return name[:max(0, MAX_SCHEDULER_ID - len(suffix))] + suffix


def register_scheduler(session: Session, scheduler_id: str, *, host: str, pid: int, executor: str,
                       capacity: int) -> str:
    """Insert (or revive, after a restart with the same id) this scheduler's row; returns its id."""
    now = db_now(session)
    row = session.get(SchedulerRow, scheduler_id)
    if row is None:
        session.add(SchedulerRow(id=scheduler_id, host=host, pid=pid, executor=executor, capacity=capacity,
                                 started_at=now, heartbeat_at=now))
    else:
        row.host, row.pid, row.executor, row.capacity = host, pid, executor, capacity
        row.started_at = row.heartbeat_at = now
        row.stopped_at = row.store_error = None  # its writer says again if results still cannot be stored
    return scheduler_id


def beat(session: Session, scheduler_id: str, *, lease_s: float, capacity: int,
         load: Mapping[str, float | int] | None = None) -> set[int]:
    """Renew this scheduler's heartbeat (with its ``load``: the schedulers table's load columns, if
    given) and the leases of its running jobs and recordings.

    Returns the ids of the jobs it still owns and that are still running: a job missing from the
    set was cancelled, finished elsewhere, or claimed by another scheduler after the lease lapsed.
    """
    now = db_now(session)
    until = now + timedelta(seconds=lease_s)
    session.execute(update(SchedulerRow).where(SchedulerRow.id == scheduler_id)
                    .values(heartbeat_at=now, capacity=capacity, stopped_at=None, **(load or {})))
    session.execute(update(Job).where(Job.owner == scheduler_id, Job.state == JobState.running.value)
                    .values(lease_until=until))
    session.execute(update(Recording).where(Recording.owner == scheduler_id, Recording.status == "running")
                    .values(lease_until=until))
    return set(session.scalars(select(Job.id).where(Job.owner == scheduler_id,
                                                    Job.state == JobState.running.value)))


def report_store_error(session: Session, scheduler_id: str, error: str | None) -> None:
    """Record why this scheduler's results could not be stored (None: they can again)."""
    session.execute(update(SchedulerRow).where(SchedulerRow.id == scheduler_id)
                    .values(store_error=None if error is None else error[:500]))


def stop_scheduler(session: Session, scheduler_id: str) -> None:
    """A scheduler that stops gives its running jobs back (``interrupted``) and records its stop."""
    now = db_now(session)
    session.execute(update(Job).where(Job.owner == scheduler_id, Job.state == JobState.running.value)
                    .values(state=JobState.interrupted.value, owner=None, lease_until=None))
    session.execute(update(Recording).where(Recording.owner == scheduler_id, Recording.status == "running")
                    .values(status="queued", owner=None, lease_until=None))
    session.execute(update(SchedulerRow).where(SchedulerRow.id == scheduler_id).values(stopped_at=now))


def schedulers(session: Session) -> list[tuple[SchedulerRow, float]]:
    """Every scheduler that has not stopped, with its heartbeat's age in seconds (database clock)."""
    now = db_now(session)
    rows = session.scalars(select(SchedulerRow).where(SchedulerRow.stopped_at.is_(None))
                           .order_by(SchedulerRow.started_at))
    return [(row, (now - row.heartbeat_at).total_seconds()) for row in rows]


def others_alive(session: Session, scheduler_id: str, *, within_s: float) -> int:
    """How many other schedulers have not stopped and beat within ``within_s`` (database clock)."""
    since = db_now(session) - timedelta(seconds=within_s)
    return session.scalar(select(func.count()).select_from(SchedulerRow).where(
        SchedulerRow.id != scheduler_id, SchedulerRow.stopped_at.is_(None), SchedulerRow.heartbeat_at >= since)) or 0


# ---------------------------------------------------------------------- jobs
def _claimable(now: datetime) -> ColumnElement[bool]:
    return or_(Job.state.in_(_CLAIMABLE),
               and_(Job.state == JobState.running.value, or_(Job.lease_until.is_(None), Job.lease_until < now)))


def newest_queued(session: Session) -> int:
    """The newest queued job's id (0 if none): one indexed read, so that a scheduler with room claims
    a new job before its next heartbeat."""
    return session.scalar(select(func.max(Job.id)).where(Job.state == JobState.queued.value)) or 0


def claim_jobs(session: Session, scheduler_id: str, *, lease_s: float, limit: int) -> list[int]:
    """Claim up to ``limit`` claimable jobs, oldest first; returns the ids this scheduler won."""
    if limit <= 0:
        return []
    now = db_now(session)
    candidates = list(session.scalars(select(Job.id).where(_claimable(now)).order_by(Job.id).limit(limit)))
    won = []
    for job_id in candidates:
        job = session.get(Job, job_id)
        assert job is not None
        result = session.execute(
            update(Job).where(Job.id == job_id, _claimable(now)).values(
                state=JobState.running.value, owner=scheduler_id, lease_until=now + timedelta(seconds=lease_s),
                started_at=job.started_at or now, resumed_at=now,
                completed_at_resume=Job.n_done + Job.n_failed,
            ).execution_options(synchronize_session=False))
        if result.rowcount == 1:  # type: ignore[attr-defined]
            won.append(job_id)
    return won


def owns(session: Session, scheduler_id: str, job_id: int) -> bool:
    """True while ``job_id`` is running under this scheduler (the fence before every write of results)."""
    query = select(Job.id).where(Job.id == job_id, Job.owner == scheduler_id, Job.state == JobState.running.value)
    if session.get_bind().dialect.name == "postgresql":
        query = query.with_for_update()
    return session.execute(query).first() is not None


def finish_job(session: Session, scheduler_id: str, job_id: int, state: JobState, *,
               error: str | None = None, total: int | None = None) -> bool:
    """Running -> ``state`` if this scheduler still owns the job; ``total``: the evaluations the job
    made, when it made fewer than planned (a DE that stopped early), checked stored by the caller."""
    values: dict[str, object] = {"state": state.value, "finished_at": db_now(session), "error": error,
                                 "owner": None, "lease_until": None}
    if total is not None:
        values["total"] = total
    result = session.execute(update(Job).where(Job.id == job_id, Job.owner == scheduler_id,
                                               Job.state == JobState.running.value).values(**values))
    return bool(result.rowcount)  # type: ignore[attr-defined]


def release_jobs(session: Session, scheduler_id: str, job_ids: Sequence[int]) -> None:
    """Give jobs back without finishing them (``interrupted``: any scheduler resumes them)."""
    session.execute(update(Job).where(Job.id.in_(job_ids), Job.owner == scheduler_id,
                                      Job.state == JobState.running.value)
                    .values(state=JobState.interrupted.value, owner=None, lease_until=None))


# ---------------------------------------------------------------------- recordings
def claim_recording(session: Session, scheduler_id: str, *, lease_s: float) -> Recording | None:
    """The oldest queued recording (or one whose producer's lease lapsed), now running here."""
    now = db_now(session)
    claimable = or_(Recording.status == "queued",
                    and_(Recording.status == "running",
                         or_(Recording.lease_until.is_(None), Recording.lease_until < now)))
    for recording_id in session.scalars(select(Recording.id).where(claimable).order_by(Recording.id).limit(4)):
        result = session.execute(
            update(Recording).where(Recording.id == recording_id, claimable)
            .values(status="running", owner=scheduler_id, lease_until=now + timedelta(seconds=lease_s))
            .execution_options(synchronize_session=False))
        if result.rowcount == 1:  # type: ignore[attr-defined]
            return session.get(Recording, recording_id)
    return None
