"""Lookups the routes share: a job by id, a page cursor, a road of a job."""

from __future__ import annotations

from sqlalchemy.orm import Session

from finaldrive.engine import Vehicle, default_vehicle, load_vehicle_dict
from finaldrive.service.api.deps import MAX_ID, ServicesDep
from finaldrive.service.api.problems import ApiProblem, validation_problem
from finaldrive.service.api.views import job_out
from finaldrive.service.db.models import Job, JobRoad
from finaldrive.service.db.repository import roads_of
from finaldrive.service.schemas import JobOut

#: The most digits a cursor (a row id, at most MAX_ID) has.
CURSOR_DIGITS = len(str(MAX_ID))


def parse_cursor(cursor: str | None) -> int | None:
    """A page cursor (a row id) from the query; 422 naming ``cursor`` unless it is 1 to 19 ASCII digits
    within MAX_ID (checked before ``int()``, which refuses more than 4,300 digits with a ValueError)."""
    if cursor is None:
        return None
    if not (0 < len(cursor) <= CURSOR_DIGITS and cursor.isascii() and cursor.isdigit()) or int(cursor) > MAX_ID:
        raise validation_problem(("query", "cursor"), "not a cursor returned by this API")
    return int(cursor)


def load_job(services: ServicesDep, job_id: int) -> JobOut:
    with services.db.read() as session:
        job = session.get(Job, job_id)
        if job is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        return job_out(session, job, roads_of(session, [job_id])[job_id], detail=True)


def job_vehicle(services: ServicesDep, job_id: int | None) -> Vehicle:
    """The job's vehicle (its spec's, as its simulations used), else the paper's; 404 without the job."""
    spec = None if job_id is None else load_job(services, job_id).spec.vehicle
    return default_vehicle() if spec is None else load_vehicle_dict(spec.model_dump())


def job_version(services: ServicesDep, job_id: int) -> tuple[str, int, int]:
    """What a job's results depend on (state, successful and failed evaluations): a render cache key;
    404 without the job."""
    with services.db.read() as session:
        job = session.get(Job, job_id)
        if job is None:
            raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
        return job.state, job.n_done, job.n_failed


def job_road(session: Session, job_id: int, road: str | None) -> tuple[Job, JobRoad]:
    """A job and one of its roads by name, spec or index (default: the first); 404 without the job."""
    job = session.get(Job, job_id)
    if job is None:
        raise ApiProblem(404, f"job {job_id} does not exist", slug="not-found")
    roads = [r for r, _ in roads_of(session, [job_id])[job_id]]
    return job, roads[find_road(road, roads) if road is not None else 0]


def find_road(road: str, roads: list[JobRoad]) -> int:
    """The index of a job's road given by name, spec or index; 422 naming the roads otherwise."""
    for r in roads:
        if road in (r.name, r.spec, str(r.road_index)):
            return r.road_index
    names = ", ".join(r.name for r in roads)
    raise validation_problem(("query", "road"), f"the job has no road {road!r} (its roads: {names})")
