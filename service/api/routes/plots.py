"""/v1/jobs/{id}/plots/{name}.png: a job's results as PNG (sweep map per road, DE history)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, Query
from fastapi.responses import Response

from finaldrive.engine import history_record
from finaldrive.service.api.deps import JobId, ServicesDep
from finaldrive.service.api.lookups import find_road
from finaldrive.service.api.problems import ApiProblem, documented
from finaldrive.service.db.models import Job, JobRoad
from finaldrive.service.db.repository import list_evaluations, roads_of
from finaldrive.service.db.results import last_generations

router = APIRouter(prefix="/jobs", tags=["results"])

PlotName = Literal["sweep-map", "de-history"]
_PNG: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}, "description": "the plot"}}


def _png(draw: object, *args: object, **kwargs: object) -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plot.png"
        draw(path, *args, **kwargs)  # type: ignore[operator]
        return path.read_bytes()


@router.get("/{job_id}/plots/{name}.png", response_class=Response, responses={**_PNG, **documented(404, 409, 422)},
            summary="A plot of a job's results (sweep-map: values over a2/L2 per road; de-history)")
def plot(
    job_id: JobId, name: PlotName, services: ServicesDep,
    road: Annotated[str | None, Query(description="road name, spec or index (default: the first)")] = None,
    value: Annotated[Literal["fitness", "distance"], Query(description="sweep-map colour")] = "fitness",
) -> Response:
    from finaldrive.service import plots

    with services.db.read() as session:
        job = session.get(Job, job_id)
        if job is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        roads = [r for r, _ in roads_of(session, [job_id])[job_id]]
        index = find_road(road, roads) if road is not None else 0
        chosen: JobRoad = roads[index]
        if name == "sweep-map":
            rows = list_evaluations(session, job_id, road_index=index, after_id=None, limit=10**7)
            designs = np.array([[math.radians(e.a2_deg), e.l2_m, e.rws_m] for e in rows]).reshape(-1, 3)
            column = "fitness_m" if value == "fitness" else "distance_m"
            values = np.array([math.nan if getattr(e, column) is None else getattr(e, column) for e in rows])
            generation = None
        else:
            if job.kind == "sweep":
                raise ApiProblem(409, f"job {job_id} is a sweep; de-history needs a de or robust-de job",
                                 slug="wrong-kind")
            generation = last_generations(session, job_id).get(0 if job.kind == "robust-de" else index)
    if name == "sweep-map":
        if not np.isfinite(values).any():
            raise ApiProblem(409, f"job {job_id} has no successful evaluation on road {chosen.name!r} yet",
                             slug="no-results")
        b = int(np.nanargmax(values))
        title = f"job {job_id} ({job.kind}) on {chosen.name}: {value} over the engine sprocket position"
        body = _png(plots.sweep_map_png, designs, values, title=title, value_label=f"{value} [m]",
                    best=(designs[b, 0], designs[b, 1]))
    else:
        if generation is None:
            raise ApiProblem(409, f"job {job_id} has no stored DE generation yet", slug="no-results")
        fitness = [math.nan if f is None else f for f in generation.fitness_m]
        population = np.column_stack([np.array(generation.population, float), fitness])
        history = [{k: (math.nan if v is None else v) for k, v in history_record(h).items()}
                   for h in generation.state["history"]]
        where = "all roads" if job.kind == "robust-de" else chosen.name
        body = _png(plots.de_history_png, history, population, title=f"job {job_id} ({job.kind}) on {where}")
    return Response(body, media_type="image/png")
