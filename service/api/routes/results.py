"""/v1/jobs/{id}/evaluations and /best: stored results, paginated, as JSON or CSV."""

from __future__ import annotations

import csv
import io
from typing import Annotated, Literal

from fastapi import APIRouter, Query
from fastapi.responses import Response

from finaldrive.engine import DEFAULT_TOLERANCE_PCT, MAX_TOLERANCE_PCT
from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.lookups import find_road, load_job, parse_cursor
from finaldrive.service.api.problems import ApiProblem, documented
from finaldrive.service.api.sharpness import job_sharpness
from finaldrive.service.api.views import evaluation_out
from finaldrive.service.db.models import Job
from finaldrive.service.db.repository import list_evaluations, roads_of
from finaldrive.service.schemas import BestOut, EvaluationOut, EvaluationPage

router = APIRouter(prefix="/jobs", tags=["results"])

CSV_COLUMNS = tuple(EvaluationOut.model_fields)


@router.get(
    "/{job_id}/evaluations", response_model=EvaluationPage,
    responses={200: {"content": {"text/csv": {"schema": {"type": "string"}}},
                     "description": "a page of evaluations (CSV: next cursor in the X-Next-Cursor header)"},
               **documented(404, 422)},
    summary="A job's evaluations, in storage order",
)
def evaluations(
    job_id: JobId, services: ServicesDep,
    road: Annotated[str | None, Query(description="road name, spec or index")] = None,
    cursor: Annotated[str | None, Query(description="next_cursor of the previous page")] = None,
    limit: Annotated[int, Query(ge=1, le=100_000)] = 1000,
    format: Literal["json", "csv"] = "json",
) -> EvaluationPage | Response:
    after = parse_cursor(cursor)
    with services.db.read() as session:
        if session.get(Job, job_id) is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        roads = [road for road, _ in roads_of(session, [job_id])[job_id]]
        road_index = None if road is None else find_road(road, roads)
        rows = list_evaluations(session, job_id, road_index=road_index, after_id=after, limit=limit + 1)
    names = {r.road_index: r.name for r in roads}
    items = [evaluation_out(e, names[e.road_index]) for e in rows[:limit]]
    next_cursor = str(rows[limit - 1].id) if len(rows) > limit else None
    if format == "json":
        return EvaluationPage(items=items, next_cursor=next_cursor)
    return Response(_csv(items), media_type="text/csv", headers={"X-Next-Cursor": next_cursor or ""})


def _csv(items: list[EvaluationOut]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for item in items:
        values = item.model_dump()
        writer.writerow("" if values[c] is None else values[c] for c in CSV_COLUMNS)
    return out.getvalue()


@router.get("/{job_id}/best", response_model=BestOut, responses=documented(404, 422),
            summary="Best design per road (and by aggregate score for robust-de), with how sharp each optimum is")
def best(
    job_id: JobId, services: ServicesDep,
    tolerance_pct: Annotated[float, Query(gt=0, le=MAX_TOLERANCE_PCT, description="near-optimal set: evaluated "
                                          "designs within this % of the best fitness")] = DEFAULT_TOLERANCE_PCT,
    sensitivity: Annotated[bool, Query(description="also finite differences of distance and fitness at each "
                                       "road's best (7 simulations a road, the job's settings)")] = False,
) -> BestOut:
    job = load_job(services, job_id)
    with services.db.read() as session:
        row = session.get(Job, job_id)
        if row is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        sharp = job_sharpness(session, row, tolerance_pct, sensitivity)
    return BestOut(job_id=job.id, roads=job.roads, robust_best=job.robust_best, sharpness=sharp)
