"""Numerical bands of a finished job's best designs, with their ties (engine.study.band).

The API process never simulates. For each road, the job's best distinct designs (at most
``TIE_CANDIDATES``, the best first) are re-simulated by a scheduler as small jobs of kind
``designs``, one a re-run of :func:`~finaldrive.engine.band_settings` (100x tighter; the reference
method, where the job's vehicle allows it: :func:`~finaldrive.engine.reference_refusal`), each queued
once per finished job (Idempotency-Key ``band:<re-run>:<job id>``). Their
stored evaluations, beside the job's own (the production run), give each design's band, and which
designs tie with the best.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from finaldrive.engine import (
    SimSettings,
    band_of,
    band_settings,
    best_distinct,
    load_vehicle_dict,
    reference_refusal,
    tie_flags,
)
from finaldrive.service.api.problems import ApiProblem
from finaldrive.service.api.sharpness import own_designs_job
from finaldrive.service.db.engine import marker
from finaldrive.service.db.levels import LEVELS
from finaldrive.service.db.models import TERMINAL_STATES, EvalStatus, Evaluation, Job, JobRoad
from finaldrive.service.db.repository import job_by_idempotency_key
from finaldrive.service.db.summaries import by_fitness
from finaldrive.service.schemas import JobSpec, SimulationSpec
from finaldrive.service.services import Services

#: The labels of a band's re-runs (engine.band_settings): tight, reference.
RE_RUNS = tuple(band_settings(SimSettings()))
#: Best evaluations read a road to find its distinct best designs (a converged DE holds many copies of its
#: best within a micrometre; a study's whole DE on a road is 2,550).
_SCAN = 3000

Top = list[tuple[float, float, float, float, float]]   # (a2 [deg], L2 [m], R_WS [m], fitness [m], distance [m])


def band_key(job_id: int, label: str) -> str:
    """The Idempotency-Key of a job's band re-run ``label``."""
    return f"band:{label}:{job_id}"


def top_designs(session: Session, job: Job) -> list[tuple[JobRoad, Top]]:
    """Each road's best successful designs, best first, each distinct from the better ones
    (engine.best_distinct: 1 deg of a2 or 1 mm of L2 or R_WS), among its :data:`_SCAN` best evaluations."""
    connection = session.connection()
    m = marker(connection)
    levels = " UNION ALL ".join(  # each level's best, then the best of all: a range of each, not a sort of all
        f"SELECT * FROM (SELECT e.a2_deg, e.l2_m, e.rws_m, e.fitness_m, e.distance_m, e.id {by_fitness(m, str(level))} "
        f"ORDER BY f.fitness_m DESC, e.id LIMIT {_SCAN}) AS t{level}" for level in range(LEVELS))
    out = []
    for road in session.scalars(select(JobRoad).where(JobRoad.job_id == job.id).order_by(JobRoad.road_index)):
        rows = connection.exec_driver_sql(
            f"SELECT a2_deg, l2_m, rws_m, fitness_m, distance_m FROM ({levels}) AS u ORDER BY fitness_m DESC, id "
            f"LIMIT {_SCAN}", (job.id, road.road_index) * LEVELS).all()
        values = np.array([[math.radians(r[0]), r[1], r[2], r[3]] for r in rows]).reshape(-1, 4)
        top: Top = [(rows[i][0], rows[i][1], rows[i][2], number_or_nan(rows[i][3]), number_or_nan(rows[i][4]))
                    for i in best_distinct(values[:, :3], values[:, 3])]
        out.append((road, top))
    return out


def refused_re_runs(job: Job) -> dict[str, str]:
    """The band's re-runs the job's vehicle does not allow: label -> why (engine.reference_refusal)."""
    source = JobSpec.model_validate(job.spec)
    vehicle = load_vehicle_dict(source.vehicle.model_dump()) if source.vehicle is not None else None
    refusal = reference_refusal(vehicle)
    return {} if refusal is None else {"reference": refusal}


def band_jobs(services: Services, job: Job) -> dict[str, Job]:
    """The job's band re-runs (label -> its ``designs`` job), queued now unless they exist (409 while
    ``job`` has not finished, or when it has no successful evaluation)."""
    if job.state not in {s.value for s in TERMINAL_STATES}:
        raise ApiProblem(409, f"job {job.id} is {job.state}: ask for its bands once it has finished",
                         slug="not-finished")
    with services.db.read() as session:
        roads = [(road, top) for road, top in top_designs(session, job) if top]
        existing = {label: job_by_idempotency_key(session, band_key(job.id, label)) for label in RE_RUNS}
    if not roads:
        raise ApiProblem(409, f"job {job.id} has no successful evaluation to band", slug="no-result")
    source = JobSpec.model_validate(job.spec)
    refused = refused_re_runs(job)
    out = {}
    for label in (label for label in RE_RUNS if label not in refused):
        spec = JobSpec(kind="designs", roads=[road.spec for road, _ in roads], settings=re_run(source.settings, label),
                       vehicle=source.vehicle, designs=[[row[:3] for row in top] for _, top in roads])
        out[label] = own_designs_job(services, job, band_key(job.id, label), spec, existing[label], "band")
    return out


def re_run(settings: SimulationSpec, label: str) -> SimulationSpec:
    """A job's settings for the band's re-run ``label``: engine.band_settings's, in the spec's fields."""
    engine = band_settings(SimSettings(duration=settings.duration, dt=settings.dt, method=settings.method,
                                       fast_tolerance=settings.fast_tolerance))[label]
    return settings.model_copy(update={"method": engine.method, "fast_tolerance": engine.fast_tolerance})


def stored_bands(session: Session, job: Job, jobs: dict[str, Job]) -> dict[int, dict[str, Any]]:
    """Each road's band of its best and its ties (by the job's road index) from the finished band
    jobs' evaluations: ``{"numerical_band": {...}, "ties": [{design, band, tie}, ...]}``."""
    runs: dict[str, dict[tuple[str, int], Any]] = {}
    for label, designs_job in jobs.items():
        roads = {r.road_index: r.spec for r in session.scalars(select(JobRoad).where(JobRoad.job_id == designs_job.id))}
        runs[label] = {(roads[index], candidate): r for (index, candidate), r in designs_results(session, designs_job)}
    out = {}
    refused = refused_re_runs(job)
    for road, top in top_designs(session, job):
        bands = []
        for candidate, (_, _, _, fitness, distance) in enumerate(top):
            values, failed = {"production": (fitness, distance)}, {}
            for label in RE_RUNS:
                row = runs.get(label, {}).get((road.spec, candidate))
                if label in refused:
                    failed[label] = refused[label]
                elif row is None:
                    failed[label] = "not simulated"
                elif row.status == EvalStatus.ok.value and row.fitness_m is not None:
                    values[label] = (row.fitness_m, number_or_nan(row.distance_m))
                else:
                    failed[label] = row.reason or "failed"
            bands.append(band_of(values, failed))
        if bands:
            ties = [{"a2_deg": a2, "l2_m": l2, "rws_m": rws, **band, "tie": tie}
                    for (a2, l2, rws, _, _), band, tie in zip(top, bands, tie_flags(bands), strict=True)]
            out[road.road_index] = {"numerical_band": bands[0], "ties": ties}
    return out


def designs_results(session: Session, designs_job: Job) -> list[tuple[tuple[int, int], Any]]:
    """A designs job's results, each ((road index, candidate), its row: status, reason, fitness_m, distance_m)."""
    return [((r.road_index, r.candidate), r) for r in session.execute(
        select(Evaluation.road_index, Evaluation.candidate, Evaluation.status, Evaluation.reason, Evaluation.fitness_m,
               Evaluation.distance_m).where(Evaluation.job_id == designs_job.id))]


def number_or_nan(value: float | None) -> float:
    """A stored number, NaN for none."""
    return math.nan if value is None else float(value)
