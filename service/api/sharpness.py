"""The sharpness of a job's best designs from its stored evaluations (engine study.sharpness)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from finaldrive.engine import Design, PlanError, aggregate, default_vehicle, near_optimal, sensitivities, spread
from finaldrive.service.api.problems import ApiProblem
from finaldrive.service.db.models import Generation, Job
from finaldrive.service.db.repository import list_evaluations, roads_of
from finaldrive.service.db.results import last_generations
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.schemas import JobSpec, PopulationOut, SharpnessOut

#: Evaluations a job's sharpness reads at most on each road.
MAX_ROWS = 10**6


def _num(v: float | None) -> float:
    return math.nan if v is None else float(v)


def job_sharpness(session: Session, job: Job, tolerance_pct: float, sensitivity: bool) -> list[SharpnessOut]:
    """Near-optimal set on each road (and by the aggregate score of a robust-de); with ``sensitivity``
    the finite differences at each road's best (7 simulations a road, the job's settings and vehicle)."""
    roads = [r for r, _ in roads_of(session, [job.id])[job.id]]
    try:
        plan = build_plan(JobSpec.model_validate(job.spec)) if sensitivity else None
    except (PlanError, ValueError) as exc:
        raise ApiProblem(409, f"job {job.id}: its spec cannot be simulated again ({exc})", slug="wrong-kind") from None
    generations = last_generations(session, job.id) if job.kind != "sweep" else {}
    out: list[SharpnessOut] = []
    table: dict[tuple[float, float, float], dict[int, float]] = {}
    for r in roads:
        rows = list_evaluations(session, job.id, road_index=r.road_index, after_id=None, limit=MAX_ROWS)
        designs = np.array([[math.radians(e.a2_deg), e.l2_m, e.rws_m] for e in rows], dtype=float).reshape(-1, 3)
        fitness = np.array([_num(e.fitness_m) for e in rows])
        near: dict[str, Any] = near_optimal(designs, fitness, np.array([_num(e.distance_m) for e in rows]),
                                            tolerance_pct)
        if plan is not None and near["count"]:
            best = designs[int(np.nanargmax(fitness))]
            near["sensitivity"] = sensitivities(Design(*(float(v) for v in best)),
                                                plan.study.roads[r.road_index].road, plan.settings,
                                                plan.vehicle or default_vehicle())
        population = None if job.kind == "robust-de" else _population(generations.get(r.road_index))
        out.append(SharpnessOut(road=r.name, final_population=population, **near))
        for e, f in zip(rows, fitness, strict=True):
            table.setdefault((math.radians(e.a2_deg), e.l2_m, e.rws_m), {})[r.road_index] = f
    if job.kind == "robust-de" and table:
        keys = list(table)
        scores = np.full((len(roads), len(keys)), np.nan)
        for j, key in enumerate(keys):
            for i, f in table[key].items():
                scores[i, j] = f
        score = aggregate(scores, job.spec.get("aggregate") or "mean")
        out.append(SharpnessOut(road=None, final_population=_population(generations.get(0)),
                                **near_optimal(np.array(keys, dtype=float), score, tolerance_pct=tolerance_pct)))
    return out


def _population(generation: Generation | None) -> PopulationOut | None:
    """The spread of a DE's last stored population."""
    if generation is None:
        return None
    fitness = np.array([_num(f) for f in generation.fitness_m])
    ok = np.isfinite(fitness)
    if not ok.any():
        return None
    return PopulationOut(count=int(ok.sum()), ranges=spread(np.array(generation.population, float)[ok], fitness[ok]))

