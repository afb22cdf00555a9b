"""/v1/recordings: Rerun recordings of designs, produced in the background, downloaded by id."""

from __future__ import annotations

import math
import tempfile
from datetime import UTC
from pathlib import Path as FilePath
from typing import Annotated, Any

from fastapi import APIRouter, Path, Response
from pydantic import SecretStr
from sqlalchemy.orm import undefer

from finaldrive.engine import design_label
from finaldrive.service.api.access import signed_link
from finaldrive.service.api.deps import MAX_ID, ServicesDep
from finaldrive.service.api.lookups import load_job
from finaldrive.service.api.problems import ApiProblem, documented, validation_problem
from finaldrive.service.db.models import Job, Recording
from finaldrive.service.db.repository import check_room, create_recording, pending_recordings_count, profile_roads
from finaldrive.service.profiles import profile_ids, resolver
from finaldrive.service.schemas import (
    JobOut,
    RecordingDesign,
    RecordingOut,
    RecordingRequest,
    RecordingRun,
    RecordingSeriesOut,
)
from finaldrive.service.services import Services

router = APIRouter(prefix="/recordings", tags=["recordings"])

RecordingId = Annotated[int, Path(ge=1, le=MAX_ID, description="recording id")]


def _job_best(job: JobOut, road: str | None) -> tuple[str, RecordingDesign]:
    """(road spec, best design) of a job on ``road`` (name, spec or index; default its first road)."""
    chosen = job.roads[0] if road is None else next(
        (r for r in job.roads if road in (r.name, r.spec, str(r.index))), None)
    if chosen is None:
        names = ", ".join(r.name for r in job.roads)
        raise validation_problem(("body", "road"), f"job {job.id} has no road {road!r} (its roads: {names})")
    rb = job.robust_best
    if rb is not None:
        return chosen.spec, RecordingDesign(a2_deg=rb.a2_deg, l2_m=rb.l2_m, rws_m=rb.rws_m, label=f"job {job.id} best")
    if chosen.best is None:
        raise ApiProblem(409, f"job {job.id} has no successful evaluation on road {chosen.name!r} yet",
                         slug="no-best-design")
    b = chosen.best
    return chosen.spec, RecordingDesign(a2_deg=b.a2_deg, l2_m=b.l2_m, rws_m=b.rws_m, label=f"job {job.id} best")


def _spec(request: RecordingRequest, services: Any) -> dict[str, Any]:
    """The concrete spec stored and produced: road (a measured one with its points), designs with labels,
    timing, method."""
    from finaldrive.engine import Design, DesignError, default_vehicle, load_vehicle_dict, resolve_roads

    designs = list(request.designs)
    method, dt, vehicle, road = "fast", 1.0e-3, None, request.road
    if request.job_id is not None:
        job = load_job(services, request.job_id)
        road, best = _job_best(job, request.road)
        designs.insert(0, best)
        method, dt = job.spec.settings.method, job.spec.settings.dt
        vehicle = None if job.spec.vehicle is None else job.spec.vehicle.model_dump()
    limits = default_vehicle() if vehicle is None else load_vehicle_dict(vehicle)
    for i, d in enumerate(request.designs):
        try:
            limits.check_design(Design.from_deg(d.a2_deg, d.l2_m, d.rws_m))
        except DesignError as exc:
            raise validation_problem(("body", "designs", i), str(exc)) from None
    assert road is not None
    ids = sorted(profile_ids([road]))
    with services.db.read() as session:
        stored = profile_roads(session, ids) if ids else {}
    try:
        items = resolve_roads(road, resolver(stored))
    except ValueError as exc:
        raise validation_problem(("body", "road"), str(exc)) from None
    if len(items) != 1:
        raise validation_problem(("body", "road"), f"{road!r} names {len(items)} roads; give one")
    if abs(round(1.0 / (request.fps * dt)) * request.fps * dt - 1.0) > 1e-9:
        raise validation_problem(("body", "fps"), f"fps must divide 1/dt = {1 / dt:g} Hz")
    labelled = [d.model_copy(update={"label": d.label or design_label(d.a2_deg, d.l2_m, d.rws_m)})
                for d in designs]
    profile = items[0].road if items[0].road.kind == "profile" else None
    return {"road": road, "designs": [d.model_dump() for d in labelled], "duration": request.duration,
            "fps": request.fps, "method": method, "dt": dt, "vehicle": vehicle,
            "profile": None if profile is None else [list(profile.xs), list(profile.ys)]}


def _out(r: Recording, token: SecretStr | None) -> RecordingOut:
    s = r.spec
    done = r.status == "succeeded"
    return RecordingOut(
        id=r.id, status=r.status, job_id=r.job_id, road=s["road"],
        designs=[RecordingDesign(**d) for d in s["designs"]], duration=s["duration"], fps=s["fps"],
        frames=math.ceil(s["duration"] * s["fps"] - 1e-9) + 1, error=s.get("error"),
        file=f"/v1/recordings/{r.id}/file" if done else None,
        viewer_file=signed_link(token, f"/v1/recordings/{r.id}/recording.rrd") if done else None,
        created_at=r.created_at.replace(tzinfo=UTC),
    )


def _load(services: Services, recording_id: int) -> Recording:
    with services.db.read() as session:
        row = session.get(Recording, recording_id)
    if row is None:
        raise ApiProblem(404, f"recording {recording_id} does not exist", slug="not-found")
    return row


@router.post("", status_code=202, response_model=RecordingOut,
             responses=documented(400, 401, 404, 409, 413, 422, 429),
             summary="Request a recording (produced in the background; poll GET until succeeded)")
def create(request: RecordingRequest, services: ServicesDep, response: Response) -> RecordingOut:
    spec = _spec(request, services)
    with services.db.write() as session:
        check_room(session, "recordings pending", pending_recordings_count(), services.settings.max_pending_recordings,
                   "FINALDRIVE_MAX_PENDING_RECORDINGS")
        job_id = None
        if request.job_id is not None and session.get(Job, request.job_id) is not None:
            job_id = request.job_id
        row = create_recording(session, job_id, spec)
    response.headers["Location"] = f"/v1/recordings/{row.id}"
    return _out(row, services.settings.api_token)


@router.get("/{recording_id}", response_model=RecordingOut, responses=documented(404, 422),
            summary="A recording's status")
def get(recording_id: RecordingId, services: ServicesDep) -> RecordingOut:
    return _out(_load(services, recording_id), services.settings.api_token)


_RRD: dict[int | str, dict[str, Any]] = {
    200: {"content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}},
          "description": "the .rrd file"}}


def _content(services: Services, recording_id: int) -> tuple[bytes, int]:
    """A finished recording's bytes and how many designs it holds (404 / 409 otherwise)."""
    with services.db.read() as session:
        row = session.get(Recording, recording_id, options=[undefer(Recording.content)])
        if row is None:
            raise ApiProblem(404, f"recording {recording_id} does not exist", slug="not-found")
        if row.status != "succeeded" or row.content is None:
            raise ApiProblem(409, f"recording {recording_id} is {row.status}, not ready", slug="not-ready")
        return row.content, len(row.spec["designs"])


@router.get("/{recording_id}/file", response_class=Response, responses={**_RRD, **documented(404, 409, 422)},
            summary="Download a finished recording (.rrd, open with `rerun FILE`)")
@router.get("/{recording_id}/recording.rrd", response_class=Response, responses={**_RRD, **documented(404, 409, 422)},
            summary="The same file under a name ending in .rrd (how rerun's web viewer recognises a recording URL)")
def file(recording_id: RecordingId, services: ServicesDep) -> Response:
    content, _ = _content(services, recording_id)
    return Response(content, media_type="application/octet-stream",
                    headers={"Content-Disposition": f'attachment; filename="finaldrive-recording-{recording_id}.rrd"'})


@router.get("/{recording_id}/series", response_model=RecordingSeriesOut, responses=documented(404, 409, 422),
            summary="A finished recording's Fig. 13 time series and each design's outcome, as JSON")
def series(recording_id: RecordingId, services: ServicesDep) -> RecordingSeriesOut:
    """Read back from the stored .rrd: one row per frame, the same numbers the viewer plots."""
    from finaldrive.service.media.recording import PLOTS, properties_of, run_key, scalars_of

    content, count = _content(services, recording_id)
    with tempfile.TemporaryDirectory(prefix="finaldrive-series-") as tmp:
        path = FilePath(tmp) / "recording.rrd"
        path.write_bytes(content)
        runs, t_s = [], []
        for i in range(count):
            key = run_key(i)
            props = properties_of(path, key)
            values: dict[str, list[float]] = {}
            for _, name, _ in PLOTS:
                t, v = scalars_of(path, f"/plots/{name}/{key}")
                t_s = t.tolist()
                values[name] = v.tolist()
            runs.append(RecordingRun(
                key=key, label=str(props.pop("label")), a2_deg=float(props.pop("a2_deg")),  # type: ignore[arg-type]
                l2_m=float(props.pop("l2_m")), rws_m=float(props.pop("rws_m")),  # type: ignore[arg-type]
                outcome={k: float(v) for k, v in props.items() if isinstance(v, (int, float))}, series=values,
            ))
    return RecordingSeriesOut(recording_id=recording_id, t_s=t_s, runs=runs)
