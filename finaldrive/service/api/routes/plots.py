"""/v1/jobs/{id}/plots/{name}.png: a job's results as PNG (sweep map per road, DE history)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from typing import Annotated, Any, Literal

import anyio
import numpy as np
from fastapi import APIRouter, Query
from fastapi.responses import Response

from finaldrive.engine import DEFAULT_TOLERANCE_PCT, MAX_TOLERANCE_PCT, Design, near_mask
from finaldrive.service.api.deps import JobId, RendersDep, ServicesDep
from finaldrive.service.api.lookups import job_road, job_vehicle, job_version
from finaldrive.service.api.problems import ApiProblem, documented
from finaldrive.service.db.columns import road_points
from finaldrive.service.db.results import generation_records, last_generations
from finaldrive.service.services import Services

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
async def plot(
    job_id: JobId, name: PlotName, services: ServicesDep, renders: RendersDep,
    road: Annotated[str | None, Query(description="road name, spec or index (default: the first)")] = None,
    value: Annotated[Literal["fitness", "distance"], Query(description="sweep-map colour")] = "fitness",
    tolerance_pct: Annotated[float, Query(gt=0, le=MAX_TOLERANCE_PCT, description="sweep-map: outline the designs "
                                          "whose fitness is within this % of the best")] = DEFAULT_TOLERANCE_PCT,
) -> Response:
    """Rendered in a worker thread, at most FINALDRIVE_MAX_CONCURRENT_RENDERS at once (others wait)."""
    draw = _sweep_map if name == "sweep-map" else _de_history
    version = await anyio.to_thread.run_sync(job_version, services, job_id)
    key = (name, job_id, version, road, value, tolerance_pct)
    body = await renders.run(key, draw, services, job_id, road, value, tolerance_pct)
    return Response(body, media_type="image/png")


def _sweep_map(services: Services, job_id: int, road: str | None, value: str, tolerance_pct: float) -> bytes:
    from finaldrive.service.media import plots

    with services.db.read() as session:
        job, chosen = job_road(session, job_id, road)
        points = road_points(session, job_id, chosen.road_index)
    designs = np.column_stack([np.radians(points["a2_deg"]), points["l2_m"], points["rws_m"]])
    values = points["fitness_m" if value == "fitness" else "distance_m"]
    if not np.isfinite(values).any():
        raise ApiProblem(409, f"job {job_id} has no successful evaluation on road {chosen.name!r} yet",
                         slug="no-results")
    near = near_mask(points["fitness_m"], tolerance_pct)[0]
    b = int(np.nanargmax(values))
    title = f"job {job_id} ({job.kind}) on {chosen.name}: {value} over the engine sprocket position"
    swingarm = plots.swingarm_at_sag_deg(job_vehicle(services, job_id), Design(*designs[b]))  # as the dashboard
    return _png(plots.sweep_map_png, designs, values, title=title, value_label=f"{value} [m]",
                best=(designs[b, 0], designs[b, 1]), near=near, swingarm_deg=swingarm,
                near_label=f"fitness within {tolerance_pct:g} % of the best ({int(near.sum())} designs)")


def _de_history(services: Services, job_id: int, road: str | None, value: str, tolerance_pct: float) -> bytes:
    from finaldrive.service.media import plots

    with services.db.read() as session:
        job, chosen = job_road(session, job_id, road)
        if job.kind == "sweep":
            raise ApiProblem(409, f"job {job_id} is a sweep; de-history needs a de or robust-de job", slug="wrong-kind")
        run = 0 if job.kind == "robust-de" else chosen.road_index
        generation = last_generations(session, job_id).get(run)
        records = generation_records(session, job_id, run).get(run, [])
    if generation is None:
        raise ApiProblem(409, f"job {job_id} has no stored DE generation yet", slug="no-results")
    fitness = [math.nan if f is None else f for f in generation.fitness_m]
    population = np.column_stack([np.array(generation.population, float), fitness])
    history = [{k: (math.nan if v is None else v) for k, v in r.items()}  # up to the population drawn
               for r in records if r["generation"] < generation.generation]
    where = "all roads" if job.kind == "robust-de" else chosen.name
    best = population[int(np.nanargmax(population[:, 3]))] if np.isfinite(population[:, 3]).any() else population[0]
    swingarm = plots.swingarm_at_sag_deg(job_vehicle(services, job_id), Design(*best[:3]))
    return _png(plots.de_history_png, history, population, title=f"job {job_id} ({job.kind}) on {where}",
                swingarm_deg=swingarm)
