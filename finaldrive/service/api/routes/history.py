"""/v1/jobs/{id}/history: a DE job's best and mean fitness per generation, per run, as JSON."""

from __future__ import annotations

import math

from fastapi import APIRouter

from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.problems import ApiProblem, documented
from finaldrive.service.db.models import Job
from finaldrive.service.db.repository import roads_of
from finaldrive.service.db.results import generation_records
from finaldrive.service.schemas import GenerationRecord, HistoryOut, RunHistory

router = APIRouter(prefix="/jobs", tags=["results"])


def _finite(value: object) -> float | None:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


@router.get("/{job_id}/history", response_model=HistoryOut, responses=documented(404, 409, 422),
            summary="DE history: best and mean fitness per generation of each run (a road; robust-de: one run)")
def history(job_id: JobId, services: ServicesDep) -> HistoryOut:
    with services.db.read() as session:
        job = session.get(Job, job_id)
        if job is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        if job.kind == "sweep":
            raise ApiProblem(409, f"job {job_id} is a sweep; a history needs a de, robust-de or paper-study job",
                             slug="wrong-kind")
        names = {r.road_index: r.name for r, _ in roads_of(session, [job_id])[job_id]}
        runs = []
        for run, records in sorted(generation_records(session, job_id).items()):
            runs.append(RunHistory(
                run=run, road=None if job.kind == "robust-de" else names.get(run),
                generations=[GenerationRecord(
                    generation=r["generation"], n_evals=r["n_evals"], n_failed=r["n_failed"],
                    best_fitness_m=_finite(r["best_fitness_m"]), mean_fitness_m=_finite(r["mean_fitness_m"]),
                ) for r in records],
            ))
    return HistoryOut(job_id=job_id, kind=job.kind, runs=runs)
