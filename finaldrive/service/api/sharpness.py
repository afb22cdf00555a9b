"""The sharpness of a job's best designs: near-optimal sets computed in the database
(:mod:`finaldrive.service.db.summaries`), and sensitivities simulated by the scheduler.

The API process never simulates. Sensitivity at each road's best is a small job of kind
``designs`` (each road's 7-design finite-difference stencil, the job's settings and vehicle),
queued once per finished job (its Idempotency-Key is ``sensitivity:<job id>``) and run by a
scheduler under its usual limits; the derivatives are read from its stored evaluations.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import timedelta
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from finaldrive.engine import (
    Design,
    default_vehicle,
    finite_differences,
    load_vehicle_dict,
    sensitivity_stencil,
    spread,
    upper_limits,
)
from finaldrive.service.api.problems import ApiProblem, validation_problem
from finaldrive.service.db.models import TERMINAL_STATES, Evaluation, Generation, Job, JobRoad, JobState
from finaldrive.service.db.repository import expire_idempotency_key, job_by_idempotency_key, roads_of
from finaldrive.service.db.results import last_generations
from finaldrive.service.db.summaries import aggregate_sharpness, road_sharpness
from finaldrive.service.jobs.plan import PlanError
from finaldrive.service.jobs.submit import IdempotencyKeyReused, request_hash, submit_job
from finaldrive.service.schemas import JobSpec, PopulationOut, SharpnessOut
from finaldrive.service.services import Services

#: /best requests in flight from one client address, and from all.
PER_CLIENT = 2
IN_TOTAL = 8
#: Seconds a client is asked to wait (Retry-After) when over its limit, and while a sensitivity job runs.
RETRY_AFTER_S = 2


class InFlight:
    """Counts expensive reads in flight per client address; one over the limit is answered 429."""

    def __init__(self, per_client: int = PER_CLIENT, total: int = IN_TOTAL) -> None:
        self.per_client, self.total = per_client, total
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}

    @contextmanager
    def slot(self, client: str) -> Iterator[None]:
        with self._lock:
            mine = self._counts.get(client, 0)
            if mine >= self.per_client or sum(self._counts.values()) >= self.total:
                raise ApiProblem(429, f"too many /best requests in flight (at most {self.per_client} a client, "
                                 f"{self.total} in all); retry when one has answered", slug="too-many-requests",
                                 headers={"Retry-After": str(RETRY_AFTER_S)})
            self._counts[client] = mine + 1
        try:
            yield
        finally:
            with self._lock:
                left = self._counts[client] - 1
                if left:
                    self._counts[client] = left
                else:
                    del self._counts[client]


def job_sharpness(session: Session, job: Job, tolerance_pct: float,
                  sensitivity: dict[int, dict[str, Any]] | None = None,
                  bands: dict[int, dict[str, Any]] | None = None) -> list[SharpnessOut]:
    """Near-optimal set on each road (and by the aggregate score of a robust-de), with each road's
    ``sensitivity`` (road index -> derivatives) and ``bands`` (road index -> its best's band and ties,
    service.api.bands, and its model bands, service.api.model_bands) where given."""
    roads = [r for r, _ in roads_of(session, [job.id])[job.id]]
    generations = last_generations(session, job.id) if job.kind not in ("sweep", "designs") else {}
    out: list[SharpnessOut] = []
    for r in roads:
        near = road_sharpness(session, job.id, r.road_index, tolerance_pct)
        population = None if job.kind == "robust-de" else _population(generations.get(r.road_index))
        out.append(SharpnessOut(road=r.name, final_population=population,
                                sensitivity=(sensitivity or {}).get(r.road_index),
                                **(bands or {}).get(r.road_index, {}), **near))
    if job.kind == "robust-de" and roads:
        near = aggregate_sharpness(session, job.id, len(roads), job.spec.get("aggregate") or "mean", tolerance_pct)
        out.append(SharpnessOut(road=None, final_population=_population(generations.get(0)), **near))
    return out


def _population(generation: Generation | None) -> PopulationOut | None:
    """The spread of a DE's last stored population."""
    if generation is None:
        return None
    fitness = np.array([math.nan if f is None else float(f) for f in generation.fitness_m])
    ok = np.isfinite(fitness)
    if not ok.any():
        return None
    return PopulationOut(count=int(ok.sum()), ranges=spread(np.array(generation.population, float)[ok], fitness[ok]))


#: The Idempotency-Keys the service keeps for itself: a job's sensitivity job (clients may not use them).
SENSITIVITY_KEY_PREFIX = "sensitivity:"
#: Every prefix of the service's own keys (a job's sensitivity job, its band jobs: service.api.bands, its
#: model-band jobs: service.api.model_bands).
OWN_KEY_PREFIXES = (SENSITIVITY_KEY_PREFIX, "band:", "model-band:")


def sensitivity_key(job_id: int) -> str:
    """The Idempotency-Key of a job's sensitivity job."""
    return f"{SENSITIVITY_KEY_PREFIX}{job_id}"


def sensitivity_job(services: Services, job: Job) -> Job:
    """The job's sensitivity job, queued now unless it exists (409 while ``job`` has not finished: its
    best may still change). One that was cancelled, or that is not this job's stencil (a client may
    have used its key), gives its key up and the stencil is queued anew; a failed one is answered."""
    if job.state not in {s.value for s in TERMINAL_STATES}:
        raise ApiProblem(409, f"job {job.id} is {job.state}: ask for its sensitivity once it has finished",
                         slug="not-finished")
    with services.db.read() as session:
        bests = session.execute(
            select(JobRoad.spec, Evaluation.a2_deg, Evaluation.l2_m, Evaluation.rws_m)
            .join(Evaluation, Evaluation.id == JobRoad.best_evaluation_id)
            .where(JobRoad.job_id == job.id).order_by(JobRoad.road_index)).all()
        existing = job_by_idempotency_key(session, sensitivity_key(job.id))
    if not bests:
        raise ApiProblem(409, f"job {job.id} has no successful evaluation to differentiate at", slug="no-result")
    source = JobSpec.model_validate(job.spec)
    upper = _upper(job)
    rows = [stencil(b.a2_deg, b.l2_m, b.rws_m, upper)[0] for b in bests]
    spec = JobSpec(kind="designs", roads=[b.spec for b in bests], settings=source.settings, vehicle=source.vehicle,
                   designs=[[(math.degrees(a2), l2, rws) for a2, l2, rws in r] for r in rows])
    return own_designs_job(services, job, sensitivity_key(job.id), spec, existing, "sensitivity")


def own_designs_job(services: Services, job: Job, key: str, spec: JobSpec, existing: Job | None, what: str) -> Job:
    """The service's own ``designs`` job under ``key`` (``existing``: the job holding it now): kept if
    it is this ``spec`` and not cancelled, else the key is given up and ``spec`` queued anew."""
    if existing is not None:
        if existing.request_hash == request_hash(spec.normalised()) and existing.state != JobState.cancelled.value:
            return existing
        with services.db.write() as session:
            expire_idempotency_key(session, key, older_than=timedelta(0))
    settings = services.settings
    try:
        created, _ = submit_job(services.db, spec, idempotency_key=key,
                                max_evaluations=settings.max_job_evaluations, max_cpu_hours=settings.max_job_cpu_hours,
                                max_active_jobs=settings.max_active_jobs, key_hours=settings.idempotency_key_hours)
    except PlanError as exc:
        raise validation_problem(("query", what), f"job {job.id}'s designs cannot be simulated again: "
                                 f"{exc}") from None
    except IdempotencyKeyReused:
        raise ApiProblem(409, f"the Idempotency-Key {key} names another job", slug="idempotency-key-reused") from None
    return created


def _upper(job: Job) -> tuple[float, float]:
    """The largest L2 and R_WS [m] the job's vehicle allows (the stencil steps back from them)."""
    vehicle = job.spec.get("vehicle")
    return upper_limits(default_vehicle() if vehicle is None else load_vehicle_dict(vehicle))


def stencil(a2_deg: float, l2_m: float, rws_m: float, upper: tuple[float, float]
            ) -> tuple[np.ndarray, dict[str, str]]:
    """The finite-difference designs (rows a2 [rad], L2, R_WS) at a best design, and each variable's scheme."""
    return sensitivity_stencil(Design(math.radians(a2_deg), l2_m, rws_m), upper=upper)


def stored_sensitivities(session: Session, source: Job, designs_job: Job) -> dict[int, dict[str, Any]]:
    """Each road's derivatives (by the source job's road index) from a finished sensitivity job's
    evaluations; a road any of whose simulations failed has none."""
    bests = {r.spec: (r.road_index, best) for r, best in roads_of(session, [source.id])[source.id]}
    rows = session.execute(
        select(Evaluation.road_index, Evaluation.candidate, Evaluation.status, Evaluation.distance_m,
               Evaluation.fitness_m).where(Evaluation.job_id == designs_job.id)).all()
    values: dict[int, dict[int, tuple[float, float]]] = {}
    for r in rows:
        if r.status == "ok" and r.distance_m is not None and r.fitness_m is not None:
            values.setdefault(r.road_index, {})[r.candidate] = (r.distance_m, r.fitness_m)
    out: dict[int, dict[str, Any]] = {}
    upper = _upper(source)
    for road, _ in roads_of(session, [designs_job.id])[designs_job.id]:
        found = values.get(road.road_index, {})
        index, best = bests.get(road.spec, (None, None))
        if index is None or best is None or len(found) != len(designs_job.spec["designs"][road.road_index]):
            continue
        _, schemes = stencil(best.a2_deg, best.l2_m, best.rws_m, upper)
        d, f = zip(*(found[c] for c in sorted(found)), strict=True)
        out[index] = finite_differences(schemes, np.array(d), np.array(f))
    return out
