"""/v1/jobs/{id}/evaluations and /best: stored results, paginated, as JSON or CSV; the best designs' summary."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response, StreamingResponse

from finaldrive.engine import DEFAULT_TOLERANCE_PCT, MAX_TOLERANCE_PCT
from finaldrive.service.api.bands import band_jobs, stored_bands
from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.lookups import find_road, load_job, parse_cursor
from finaldrive.service.api.model_bands import model_band_jobs, stored_model_bands
from finaldrive.service.api.problems import ApiProblem, documented, validation_problem
from finaldrive.service.api.sharpness import (
    RETRY_AFTER_S,
    InFlight,
    job_sharpness,
    sensitivity_job,
    stored_sensitivities,
)
from finaldrive.service.api.views import evaluation_out
from finaldrive.service.db.columns import page_end, row_chunks
from finaldrive.service.db.models import TERMINAL_STATES, Job, JobState
from finaldrive.service.db.repository import list_evaluations, roads_of
from finaldrive.service.schemas import BestOut, EvaluationOut, EvaluationPage

router = APIRouter(prefix="/jobs", tags=["results"])

CSV_COLUMNS = tuple(EvaluationOut.model_fields)


#: Largest JSON page (its rows are built as objects); CSV pages stream, up to the query's limit.
JSON_PAGE_MAX = 10_000


@router.get(
    "/{job_id}/evaluations", response_model=EvaluationPage,
    responses={200: {"content": {"text/csv": {"schema": {"type": "string"}}},
                     "description": "a page of evaluations (CSV: streamed; next cursor in the X-Next-Cursor header)"},
               **documented(404, 422)},
    summary="A job's evaluations, in storage order (JSON pages up to 10,000; CSV pages, streamed, up to 100,000)",
)
def evaluations(
    job_id: JobId, services: ServicesDep,
    road: Annotated[str | None, Query(description="road name, spec or index")] = None,
    cursor: Annotated[str | None, Query(description="next_cursor of the previous page")] = None,
    limit: Annotated[int, Query(ge=1, le=100_000, description="page size (JSON: at most 10,000)")] = 1000,
    format: Literal["json", "csv"] = "json",
) -> EvaluationPage | Response:
    after = parse_cursor(cursor)
    if format == "json" and limit > JSON_PAGE_MAX:
        raise validation_problem(("query", "limit"), f"at most {JSON_PAGE_MAX} for format=json "
                                 "(format=csv streams pages of up to 100000)")
    with services.db.read() as session:
        if session.get(Job, job_id) is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        roads = [road for road, _ in roads_of(session, [job_id])[job_id]]
        road_index = None if road is None else find_road(road, roads)
        if format == "csv":
            until, more = page_end(session, job_id, road_index, after, limit)
        else:
            rows = list_evaluations(session, job_id, road_index=road_index, after_id=after, limit=limit + 1)
    names = {r.road_index: r.name for r in roads}
    if format == "csv":
        chunks = row_chunks(services.db, job_id, road_index, STORED_COLUMNS, after_id=after, until_id=until)
        return StreamingResponse(_csv(chunks, names), media_type="text/csv",
                                 headers={"X-Next-Cursor": str(until) if more else ""})
    items = [evaluation_out(e, names[e.road_index]) for e in rows[:limit]]
    return EvaluationPage(items=items, next_cursor=str(rows[limit - 1].id) if len(rows) > limit else None)


#: The stored columns of the CSV, in its order (its ``road`` column is the name of ``road_index``).
STORED_COLUMNS = tuple(c for c in CSV_COLUMNS if c != "road")


def _csv(chunks: Iterator[list[tuple[Any, ...]]], names: dict[int, str]) -> Iterator[str]:
    """The header, then each chunk of rows as CSV text (None as an empty field)."""
    yield ",".join(CSV_COLUMNS) + "\n"
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    road = STORED_COLUMNS.index("road_index")
    insert_at = CSV_COLUMNS.index("road")
    for rows in chunks:
        for row in rows:
            values: list[Any] = ["" if v is None else v for v in row]
            values.insert(insert_at, names[row[road]])
            writer.writerow(values)
        yield out.getvalue()
        out.seek(0)
        out.truncate()


#: /best requests in flight, per client address.
IN_FLIGHT = InFlight()


@router.get(
    "/{job_id}/best", response_model=BestOut, responses={202: {"model": BestOut, "description": (
        "sensitivity=true, band=true or model_band=true: their jobs are queued or running (sensitivity_job, "
        "band_jobs, model_band_jobs name them); ask again after Retry-After")},
        **documented(404, 409, 422, 429)},
    summary="Best design per road (and by aggregate score for robust-de), with how sharp each optimum is",
    description=(
        "Computed in the database (bounded memory whatever the job's size); at most 2 requests in flight a "
        "client (else 429 with Retry-After). With sensitivity=true on a finished job, the finite differences "
        "are simulated by a scheduler as a small job of kind `designs`, queued once per job: 202 with "
        "Retry-After until it has finished, then 200 with each road's sensitivity. With band=true, likewise "
        "two such jobs re-simulate each road's best designs (100x tighter; the reference method): then 200 "
        "with each road's band and ties. With model_band=true, one such job an applicable modelling alternative "
        "simulates them (docs/optimisation.md#model-bands): then 200 with each road's model bands."),
)
def best(
    job_id: JobId, services: ServicesDep, request: Request, response: Response,
    tolerance_pct: Annotated[float, Query(gt=0, le=MAX_TOLERANCE_PCT, description="near-optimal set: evaluated "
                                          "designs within this % of the best fitness")] = DEFAULT_TOLERANCE_PCT,
    sensitivity: Annotated[bool, Query(description="also finite differences of distance and fitness at each "
                                       "road's best (7 simulations a road, the job's settings), run by a "
                                       "scheduler: 202 until they are stored")] = False,
    band: Annotated[bool, Query(description="also the numerical band of each road's best and next best designs "
                                "(up to 5 a road, re-simulated 100x tighter and with the reference method by a "
                                "scheduler), with which tie with the best: 202 until they are stored")] = False,
    model_band: Annotated[bool, Query(description="also each road's best designs under each documented modelling "
                                      "alternative (tyre load range, drive, front wheel, elastic chain, road phase), "
                                      "simulated by a scheduler, with the rank correlation of each against the "
                                      "job's own: 202 until they are stored")] = False,
) -> BestOut:
    with IN_FLIGHT.slot(request.client.host if request.client else ""):
        job = load_job(services, job_id)
        with services.db.read() as session:
            row = session.get(Job, job_id)
            if row is None:
                raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        designs = sensitivity_job(services, row) if sensitivity else None
        re_runs = band_jobs(services, row) if band else {}
        alternatives, skipped = model_band_jobs(services, row) if model_band else ({}, {})
        with services.db.read() as session:
            ready = designs is not None and designs.state == JobState.succeeded.value
            derivatives = stored_sensitivities(session, row, designs) if ready and designs is not None else None
            banded = (stored_bands(session, row, re_runs)
                      if re_runs and all(j.state == JobState.succeeded.value for j in re_runs.values()) else None)
            ranked = (stored_model_bands(session, row, alternatives, skipped)
                      if model_band and all(j.state in TERMINAL for j in alternatives.values()) else None)
            sharp = job_sharpness(session, row, tolerance_pct, derivatives, _merged(banded, ranked))
    running = [j for j in [designs, *re_runs.values(), *alternatives.values()]
               if j is not None and j.state not in TERMINAL]
    if running:
        response.status_code = 202
        response.headers["Retry-After"] = str(RETRY_AFTER_S)
        response.headers["Location"] = f"/v1/jobs/{running[0].id}"
    return BestOut(job_id=job.id, roads=job.roads, robust_best=job.robust_best, sharpness=sharp,
                   sensitivity_job=None if designs is None else designs.id,
                   sensitivity_state=None if designs is None else designs.state,
                   band_jobs={label: j.id for label, j in re_runs.items()} or None,
                   band_state=_least_finished([j.state for j in re_runs.values()]),
                   model_band_jobs={name: j.id for name, j in alternatives.items()} or None,
                   model_band_state=_least_finished([j.state for j in alternatives.values()]))


def _merged(*per_road: dict[int, dict[str, Any]] | None) -> dict[int, dict[str, Any]] | None:
    """Road index -> the fields several road-wise results add to its sharpness, together."""
    out: dict[int, dict[str, Any]] = {}
    for results in per_road:
        for index, fields in (results or {}).items():
            out.setdefault(index, {}).update(fields)
    return out or None


#: Terminal job states, and the order in which a set of jobs' state is told (the least finished first).
TERMINAL = {s.value for s in TERMINAL_STATES}
_PROGRESS = ("queued", "interrupted", "running", "cancelled", "failed", "succeeded")


def _least_finished(states: list[str]) -> str | None:
    return min(states, key=lambda s: _PROGRESS.index(s) if s in _PROGRESS else -1) if states else None
