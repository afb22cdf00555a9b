"""/v1/jobs/{id}/points: a road's evaluations as columns, for interactive maps and scatter plots."""

from __future__ import annotations

import json
import math
from typing import Annotated, Any

import anyio
import numpy as np
from fastapi import APIRouter, Query
from fastapi.responses import Response
from pydantic import BaseModel, Field

from finaldrive.service.api.deps import JobId, RendersDep, ServicesDep
from finaldrive.service.api.lookups import job_road, job_version
from finaldrive.service.api.problems import documented
from finaldrive.service.db.columns import POINT_COLUMNS, road_points
from finaldrive.service.services import Services

router = APIRouter(prefix="/jobs", tags=["results"])


class PointsOut(BaseModel):
    """Column i of every list is evaluation i, in storage order; null where a failed simulation has no value."""

    road: str = Field(description="the road's name")
    id: list[int] = Field(description="evaluation ids (as in /evaluations)")
    step: list[int] = Field(description="DE generation (0 = initial population); 0 for sweeps, -1 for a "
                            "paper-study's sweep")
    a2_deg: list[float]
    l2_m: list[float]
    rws_m: list[float]
    distance_m: list[float | None]
    fitness_m: list[float | None]
    squat_ratio: list[float | None]
    slack_m: list[float | None]
    status: list[str] = Field(description="ok or failed")


@router.get(
    "/{job_id}/points", response_model=PointsOut, responses=documented(404, 422),
    summary="Every evaluation of a road as columns (id, step, design, distance, fitness, squat ratio, slack, "
            "status), "
            "for interactive maps; built without row objects, at most FINALDRIVE_MAX_CONCURRENT_RENDERS at once",
)
async def points(
    job_id: JobId, services: ServicesDep, renders: RendersDep,
    road: Annotated[str | None, Query(description="road name, spec or index (default: the first)")] = None,
) -> Response:
    version = await anyio.to_thread.run_sync(job_version, services, job_id)
    body = await renders.run(("points", job_id, version, road), _points_json, services, job_id, road)
    return Response(body, media_type="application/json")


def _points_json(services: Services, job_id: int, road: str | None) -> bytes:
    with services.db.read() as session:
        _, chosen = job_road(session, job_id, road)
        columns = road_points(session, job_id, chosen.road_index)
    parts = [f'{{"road":{json.dumps(chosen.name)}']
    parts += [f',"{name}":{_json_list(columns[name])}' for name in POINT_COLUMNS]
    parts.append(f',"status":{json.dumps(np.where(columns["ok"], "ok", "failed").tolist())}}}')
    return "".join(parts).encode()


def _json_list(values: np.ndarray) -> str:
    """A JSON array of a column, NaN as null."""
    items: list[Any] = values.tolist()
    if values.dtype.kind == "f":
        items = [None if math.isnan(v) else v for v in items]
    return json.dumps(items, separators=(",", ":"))
