"""The scheduler's path through the store: what a job has stored, the result cache, and writes.

Every write of results is fenced: it happens only while the writing scheduler still owns the
job (:func:`finaldrive.service.db.leases.owns`, in the same transaction), so a scheduler that
lost its lease can never store anything. Rows are inserted in bulk, and a slot
(job, road, step, candidate) that is somehow stored already is skipped, never stored twice.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

from sqlalchemy import Table, func, insert, select
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session

from finaldrive.engine import DIAGNOSTICS
from finaldrive.service.db.leases import db_now, owns
from finaldrive.service.db.models import EvalStatus, Evaluation, Generation, Job, JobRoad

#: Rows per ``IN (...)`` query, well under SQLite's variable limit.
_IN_CHUNK = 500


class LeaseLost(Exception):
    """The scheduler no longer owns the job: nothing was written."""


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
    transient: bool = False
    diagnostics: dict[str, float | None] = field(default_factory=dict)  # finaldrive.engine.DIAGNOSTICS


_ROW_FIELDS = tuple(f.name for f in fields(EvalRow) if f.name != "diagnostics")


def stored_fitness(session: Session, job_id: int, road_index: int, step: int,
                   candidates: Iterable[int]) -> dict[int, float]:
    """Candidates of (road, step) the job has stored already, with their fitness (NaN when failed)."""
    out: dict[int, float] = {}
    wanted = sorted({int(c) for c in candidates})
    for start in range(0, len(wanted), _IN_CHUNK):
        chunk = wanted[start:start + _IN_CHUNK]
        query = select(Evaluation.candidate, Evaluation.fitness_m).where(
            Evaluation.job_id == job_id, Evaluation.road_index == road_index, Evaluation.step == step,
            Evaluation.candidate.in_(chunk))
        for candidate, fitness in session.execute(query):
            out[int(candidate)] = math.nan if fitness is None else float(fitness)
    return out


def stored_slots(session: Session, job_id: int, step: int) -> set[tuple[int, int]]:
    """(road, candidate) of the job's stored evaluations at ``step``."""
    query = select(Evaluation.road_index, Evaluation.candidate).where(Evaluation.job_id == job_id,
                                                                      Evaluation.step == step)
    return {(int(r), int(c)) for r, c in session.execute(query)}


def cached_evaluations(session: Session, keys: Iterable[str]) -> dict[str, Evaluation]:
    """The first stored evaluation for each cache key that has one (transient failures excluded)."""
    wanted = sorted(set(keys))
    out: dict[str, Evaluation] = {}
    for start in range(0, len(wanted), _IN_CHUNK):
        chunk = wanted[start:start + _IN_CHUNK]
        query = (select(Evaluation).where(Evaluation.cache_key.in_(chunk), Evaluation.transient.is_(False))
                 .order_by(Evaluation.id))
        for e in session.scalars(query):
            out.setdefault(e.cache_key, e)
    return out


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


def store_evaluations(session: Session, scheduler_id: str, job_id: int, rows: Sequence[EvalRow]) -> int:
    """Insert rows, bump the job's counters and each road's best; returns how many were new.

    Raises :class:`LeaseLost` (and writes nothing) unless the scheduler still owns the job.
    """
    if not owns(session, scheduler_id, job_id):
        raise LeaseLost(job_id)
    if not rows:
        return 0
    now = db_now(session)
    values = [{**{name: getattr(row, name) for name in _ROW_FIELDS}, **dict.fromkeys(DIAGNOSTICS),
               **row.diagnostics, "job_id": job_id, "created_at": now} for row in rows]
    dialect = session.get_bind().dialect.name
    statement: Any
    table = Evaluation.__table__  # Core, not the ORM: a bulk insert of plain rows
    assert isinstance(table, Table)
    if dialect == "sqlite":
        statement = sqlite.insert(table).on_conflict_do_nothing()
    elif dialect == "postgresql":
        statement = postgresql.insert(table).on_conflict_do_nothing()
    else:
        statement = insert(table)
    c = table.c
    returned = session.execute(statement.returning(c.id, c.road_index, c.step, c.candidate), values)
    ids = {(int(r), int(s), int(k)): int(i) for i, r, s, k in returned}
    new = [row for row in rows if (row.road_index, row.step, row.candidate) in ids]
    ok = [row for row in new if row.status == EvalStatus.ok.value]
    job = session.get(Job, job_id)
    assert job is not None
    job.n_done += len(ok)
    job.n_failed += len(new) - len(ok)
    job.n_cached += sum(row.cached for row in new)
    best: dict[int, EvalRow] = {}
    for row in ok:
        current = best.get(row.road_index)
        if current is None or _better(row.fitness_m, current.fitness_m):
            best[row.road_index] = row
    for road_index, row in best.items():
        road = session.get(JobRoad, (job_id, road_index))
        assert road is not None
        if road.best_fitness is None or _better(row.fitness_m, road.best_fitness):
            road.best_fitness = row.fitness_m
            road.best_evaluation_id = ids[(row.road_index, row.step, row.candidate)]
    return len(new)


def store_generation(session: Session, scheduler_id: str, job_id: int, *, run: int, generation: int,
                     state: dict[str, Any], population: list[list[float]], fitness: list[float | None],
                     best_f: float | None, n_evals: int) -> None:
    """Record a told DE generation (its state resumes the run); fenced like the evaluations."""
    if not owns(session, scheduler_id, job_id):
        raise LeaseLost(job_id)
    exists = session.execute(select(Generation.id).where(
        Generation.job_id == job_id, Generation.run == run, Generation.generation == generation)).first()
    if exists is None:
        session.add(Generation(job_id=job_id, run=run, generation=generation, state=state, population=population,
                               fitness=fitness, best_f=best_f, n_evals=n_evals, created_at=db_now(session)))


def _better(a: float | None, b: float | None) -> bool:
    return a is not None and math.isfinite(a) and (b is None or a > b)
