"""The sharpness of a job's best designs from its stored evaluations (engine study.sharpness)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from finaldrive.engine import Design, aggregate, default_vehicle, near_optimal, sensitivities
from finaldrive.service.db.models import Job
from finaldrive.service.db.repository import list_evaluations, roads_of
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.schemas import JobSpec, SharpnessOut

#: Evaluations a job's sharpness reads at most on each road.
MAX_ROWS = 10**6


def _num(v: float | None) -> float:
    return math.nan if v is None else float(v)


def job_sharpness(session: Session, job: Job, tolerance_pct: float, sensitivity: bool) -> list[SharpnessOut]:
    """Near-optimal set on each road (and by the aggregate score of a robust-de); with ``sensitivity``
    the finite differences at each road's best (7 simulations a road, the job's settings and vehicle)."""
    roads = [r for r, _ in roads_of(session, [job.id])[job.id]]
    plan = build_plan(JobSpec.model_validate(job.spec)) if sensitivity else None
    out: list[SharpnessOut] = []
    table: dict[tuple[float, float, float], dict[int, float]] = {}
    for r in roads:
        rows = list_evaluations(session, job.id, road_index=r.road_index, after_id=None, limit=MAX_ROWS)
        designs = np.array([[e.a2, e.l2, e.rws] for e in rows], dtype=float).reshape(-1, 3)
        fitness = np.array([_num(e.fitness_m) for e in rows])
        near: dict[str, Any] = near_optimal(designs, fitness, np.array([_num(e.distance_m) for e in rows]),
                                            tolerance_pct)
        if plan is not None and near["size"]:
            best = designs[int(np.nanargmax(fitness))]
            near["sensitivity"] = sensitivities(Design(*(float(v) for v in best)),
                                                plan.study.roads[r.road_index].road, plan.settings,
                                                plan.vehicle or default_vehicle())
        out.append(SharpnessOut(road=r.name, **near))
        for e, f in zip(rows, fitness, strict=True):
            table.setdefault((e.a2, e.l2, e.rws), {})[r.road_index] = f
    if job.kind == "robust-de" and table:
        keys = list(table)
        scores = np.full((len(roads), len(keys)), np.nan)
        for j, key in enumerate(keys):
            for i, f in table[key].items():
                scores[i, j] = f
        score = aggregate(scores, job.spec.get("aggregate") or "mean")
        out.append(SharpnessOut(road=None, **near_optimal(np.array(keys, dtype=float), score,
                                                           tolerance_pct=tolerance_pct)))
    return out

