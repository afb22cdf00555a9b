"""SQLAlchemy 2 tables of the results store.

``evaluations`` is also the result cache: a row with the same ``cache_key`` (design, road,
vehicle, settings, engine version) is reused instead of simulating again.
"""

from __future__ import annotations

import enum
from datetime import datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    PrimaryKeyConstraint,
    SmallInteger,
    String,
    Text,
    UniqueConstraint,
    false,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from finaldrive.engine import DIAGNOSTICS


class JobState(enum.StrEnum):
    """Life cycle of a job; the last four are terminal except ``interrupted``."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"
    interrupted = "interrupted"


TERMINAL_STATES = frozenset({JobState.succeeded, JobState.failed, JobState.cancelled})
ACTIVE_STATES = frozenset({JobState.queued, JobState.running, JobState.interrupted})


class EvalStatus(enum.StrEnum):
    ok = "ok"
    failed = "failed"


class Base(DeclarativeBase):
    pass


class Job(Base):
    """One submitted job: its spec, state and progress counters."""

    __tablename__ = "jobs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    state: Mapped[str] = mapped_column(String(16), default=JobState.queued.value)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    request_hash: Mapped[str] = mapped_column(String(64))
    idempotency_key: Mapped[str | None] = mapped_column(String(255), unique=True)
    total: Mapped[int] = mapped_column(Integer)
    n_done: Mapped[int] = mapped_column(Integer, default=0)
    n_failed: Mapped[int] = mapped_column(Integer, default=0)
    n_cached: Mapped[int] = mapped_column(Integer, default=0)
    error: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime)
    started_at: Mapped[datetime | None] = mapped_column(DateTime)
    resumed_at: Mapped[datetime | None] = mapped_column(DateTime)
    completed_at_resume: Mapped[int] = mapped_column(Integer, default=0)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime)
    cost_cpu_s: Mapped[float | None] = mapped_column(Float)        # estimated at submission
    owner: Mapped[str | None] = mapped_column(String(64))          # the scheduler holding the lease
    lease_until: Mapped[datetime | None] = mapped_column(DateTime)  # on the database's clock

    __table_args__ = (
        Index("ix_jobs_state_id", "state", "id"),
        Index("ix_jobs_kind_id", "kind", "id"),
        Index("ix_jobs_owner", "owner"),
    )


class JobRoad(Base):
    """A road of a job, in the job's order, with the best evaluation on it so far."""

    __tablename__ = "job_roads"

    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True)
    road_index: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64))
    spec: Mapped[str] = mapped_column(String(255))
    best_fitness_m: Mapped[float | None] = mapped_column(Float)
    best_evaluation_id: Mapped[int | None] = mapped_column(Integer)


class RoadExplored(Base):
    """What a job has explored on a road, kept by the writer with each store: its successful
    evaluations grouped by a2 in 1 deg buckets of the circle (``bucket`` -1: the designs on the
    pivot), each group's count and ranges (a2 as an angle in [0, 360) deg). /best reads the explored
    ranges here, not from the evaluations (finaldrive.service.db.summaries)."""

    __tablename__ = "road_explored"

    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True)
    road_index: Mapped[int] = mapped_column(Integer, primary_key=True)
    bucket: Mapped[int] = mapped_column(Integer, primary_key=True)
    n: Mapped[int] = mapped_column(Integer)
    a2_lo_deg: Mapped[float] = mapped_column(Float)
    a2_hi_deg: Mapped[float] = mapped_column(Float)
    l2_lo_m: Mapped[float] = mapped_column(Float)
    l2_hi_m: Mapped[float] = mapped_column(Float)
    rws_lo_m: Mapped[float] = mapped_column(Float)
    rws_hi_m: Mapped[float] = mapped_column(Float)
    fitness_lo_m: Mapped[float] = mapped_column(Float)
    fitness_hi_m: Mapped[float] = mapped_column(Float)


class Evaluation(Base):
    """One simulation result of a job: a design on a road and its result record (finaldrive.engine.VALUES,
    names with units, docs/fields.md), the diagnostics' columns added below the class.

    ``step`` is the DE generation (0 = initial population; always 0 for sweeps) and
    ``candidate`` the row within the sweep grid or the generation.
    """

    __tablename__ = "evaluations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"))
    road_index: Mapped[int] = mapped_column(Integer)
    step: Mapped[int] = mapped_column(Integer)
    candidate: Mapped[int] = mapped_column(Integer)
    a2_deg: Mapped[float] = mapped_column(Float)
    l2_m: Mapped[float] = mapped_column(Float)
    rws_m: Mapped[float] = mapped_column(Float)
    distance_m: Mapped[float | None] = mapped_column(Float)
    squat_ratio: Mapped[float | None] = mapped_column(Float)
    slack_m: Mapped[float | None] = mapped_column(Float)
    fitness_m: Mapped[float | None] = mapped_column(Float)
    chain_length_m: Mapped[float | None] = mapped_column(Float)
    status: Mapped[str] = mapped_column(String(8))
    reason: Mapped[str] = mapped_column(Text, default="")
    wall_s: Mapped[float] = mapped_column(Float)
    cached: Mapped[bool] = mapped_column(Boolean, default=False)
    cache_key: Mapped[str] = mapped_column(String(64))
    #: the key's 60-bit hash (finaldrive.service.db.results.key_hashes), indexed in ``cache_index``; lookups
    #: compare the whole key
    cache_hash: Mapped[int] = mapped_column(BigInteger)
    #: the failure may not recur (a time limit, a lost worker): never reused from the result cache
    transient: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    created_at: Mapped[datetime] = mapped_column(DateTime)

    __table_args__ = (
        UniqueConstraint("job_id", "road_index", "step", "candidate", name="uq_evaluations_slot"),
        Index("ix_evaluations_job_id", "job_id", "id"),
        Index("ix_evaluations_job_road_id", "job_id", "road_index", "id"),
    )


for _name in DIAGNOSTICS:  # the run's extremes and energy ledger, one column each (unit in the name)
    setattr(Evaluation, _name, mapped_column(_name, Float, nullable=True))


class _IndexEntry:
    """An entry of an index table of levels (finaldrive.service.db.levels): its level, its key
    (each table's own columns) and its evaluation's slot."""

    level: Mapped[int] = mapped_column(SmallInteger)
    job_id: Mapped[int] = mapped_column(Integer)
    road_index: Mapped[int] = mapped_column(Integer)
    step: Mapped[int] = mapped_column(Integer)
    candidate: Mapped[int] = mapped_column(Integer)


def _entries_of(*key: str) -> tuple[Any, ...]:
    """An index table's arguments: its primary key (the level, ``key``, the rest of the slot); no rowid."""
    slot = [c for c in ("job_id", "road_index", "step", "candidate") if c not in key]
    return PrimaryKeyConstraint("level", *key, *slot), {"sqlite_with_rowid": False}


class CacheIndex(_IndexEntry, Base):
    """The result cache's index: each evaluation by its ``cache_hash``."""

    __tablename__ = "cache_index"
    __table_args__ = _entries_of("cache_hash")

    cache_hash: Mapped[int] = mapped_column(BigInteger)


class FitnessIndex(_IndexEntry, Base):
    """Each road's successful evaluations by fitness (/best: the best, the near-optimal set, the best designs)."""

    __tablename__ = "fitness_index"
    __table_args__ = _entries_of("job_id", "road_index", "fitness_m")

    fitness_m: Mapped[float] = mapped_column(Float)


class IndexLevel(Base):
    """How many entries a level (1 on) of an index table holds: changed by each move between levels
    (finaldrive.service.db.levels), so that a full level is found without counting it."""

    __tablename__ = "index_levels"

    index_table: Mapped[str] = mapped_column(String(32), primary_key=True)
    level: Mapped[int] = mapped_column(SmallInteger, primary_key=True)
    entries: Mapped[int] = mapped_column(BigInteger)


class Generation(Base):
    """One told DE generation of a run (run = road index for ``de``, 0 for ``robust-de``).

    ``generation`` counts tells: 1 is the initial population. ``state`` resumes the run (the
    optimiser's state without its history). Each row holds its own generation's record: the
    population's best and mean fitness, the evaluations so far, and that generation's failures.
    """

    __tablename__ = "generations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"))
    run: Mapped[int] = mapped_column(Integer)
    generation: Mapped[int] = mapped_column(Integer)
    population: Mapped[list[list[float]]] = mapped_column(JSON)
    fitness_m: Mapped[list[float | None]] = mapped_column(JSON)
    state: Mapped[dict[str, Any]] = mapped_column(JSON)
    best_fitness_m: Mapped[float | None] = mapped_column(Float)
    mean_fitness_m: Mapped[float | None] = mapped_column(Float, nullable=True)
    n_evals: Mapped[int] = mapped_column(Integer)
    n_failed: Mapped[int] = mapped_column(Integer, server_default="0")
    created_at: Mapped[datetime] = mapped_column(DateTime)

    __table_args__ = (UniqueConstraint("job_id", "run", "generation", name="uq_generations_step"),)


class RoadProfile(Base):
    """A measured road uploaded to the service (POST /v1/roads), named ``profile:ID`` in job specs.

    Stored once per content (``content_hash``, the sha256 of its points, also its part of the
    result-cache key); the points are loaded only when asked for.
    """

    __tablename__ = "road_profiles"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64))
    content_hash: Mapped[str] = mapped_column(String(64), unique=True)
    n_points: Mapped[int] = mapped_column(Integer)
    x_min_m: Mapped[float] = mapped_column(Float)
    x_max_m: Mapped[float] = mapped_column(Float)
    y_min_m: Mapped[float] = mapped_column(Float)
    y_max_m: Mapped[float] = mapped_column(Float)
    xs: Mapped[list[float]] = mapped_column(JSON, deferred=True)
    ys: Mapped[list[float]] = mapped_column(JSON, deferred=True)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class Recording(Base):
    """A requested animation file of designs (produced by a scheduler, under a lease like a job)."""

    __tablename__ = "recordings"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id", ondelete="SET NULL"), index=True)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    status: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[datetime] = mapped_column(DateTime)
    #: the .rrd file, once produced (loaded only when asked for)
    content: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    size_bytes: Mapped[int | None] = mapped_column(Integer)
    owner: Mapped[str | None] = mapped_column(String(64))
    lease_until: Mapped[datetime | None] = mapped_column(DateTime)


class Scheduler(Base):
    """A scheduler process: what it runs on and its heartbeat (on the database's clock)."""

    __tablename__ = "schedulers"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    host: Mapped[str] = mapped_column(String(255))
    pid: Mapped[int] = mapped_column(Integer)
    executor: Mapped[str] = mapped_column(String(16))
    capacity: Mapped[int] = mapped_column(Integer)
    started_at: Mapped[datetime] = mapped_column(DateTime)
    heartbeat_at: Mapped[datetime] = mapped_column(DateTime)
    stopped_at: Mapped[datetime | None] = mapped_column(DateTime)
    store_error: Mapped[str | None] = mapped_column(String(500))   # why its last result write failed, if it did
    # its load (workers/dispatch.py, Load): over its last heartbeat interval, and in flight / waiting at it
    tasks_per_s: Mapped[float | None] = mapped_column(Float)
    evaluations_per_s: Mapped[float | None] = mapped_column(Float)
    busy_share: Mapped[float | None] = mapped_column(Float)
    in_flight_tasks: Mapped[int | None] = mapped_column(Integer)
    backlog_designs: Mapped[int | None] = mapped_column(Integer)
