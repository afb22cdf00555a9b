"""/v1/roads: the paper's 23 road presets, and measured road profiles uploaded by users."""

from __future__ import annotations

from datetime import UTC
from typing import Annotated

import anyio
from fastapi import APIRouter, Path, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import undefer

from finaldrive.engine import PRESETS, PROFILE_MAX_POINTS, Road, RoadError
from finaldrive.service.api.deps import MAX_ID, ServicesDep
from finaldrive.service.api.lookups import parse_cursor
from finaldrive.service.api.problems import ApiProblem, documented, validation_problem
from finaldrive.service.db.models import RoadProfile
from finaldrive.service.db.repository import check_room, create_profile, list_profiles, profile_by_hash, profiles_count
from finaldrive.service.profiles import ProfileError, content_hash, road_from_csv
from finaldrive.service.schemas import RoadOut, RoadProfileDetail, RoadProfileIn, RoadProfileOut, RoadProfilePage
from finaldrive.service.services import Services

router = APIRouter(prefix="/roads", tags=["roads"])

ProfileId = Annotated[int, Path(ge=1, le=MAX_ID, description="road profile id")]

_LIMITS = (f"x strictly increasing; 2 to {PROFILE_MAX_POINTS:,} points; |x| <= 10 km, |y| <= 1 km; "
           "the body at most FINALDRIVE_MAX_BODY_BYTES (1 MiB by default)")


@router.get("", response_model=list[RoadOut], summary="Road presets, in the paper's table order")
def roads() -> list[RoadOut]:
    return [
        RoadOut(name=p.name, spec=p.spec, kind=p.road.kind, description=p.description, paper=p.paper)
        for p in PRESETS.values()
    ]


@router.post(
    "", status_code=201, response_model=RoadProfileOut,
    responses={200: {"model": RoadProfileOut, "description": "a profile with the same points exists: it is returned"},
               **documented(400, 401, 413, 415, 422, 507)},
    openapi_extra={"requestBody": {"required": True, "content": {
        "application/json": {"schema": RoadProfileIn.model_json_schema()},
        "text/csv": {"schema": {"type": "string", "description": "lines x,y [m]; an optional header line, # comments"}},
    }}},
    summary="Upload a measured road profile",
    description=(
        "A JSON body `{\"name\", \"points\": [[x, y], ...]}` or a CSV body (`Content-Type: text/csv`, the name "
        f"in `?name=`), in metres: {_LIMITS}. Answers 201 with the id (use `profile:ID` in a job's roads) "
        "and a Location header, or 200 with the existing profile of the same points. A bad profile gets 422 "
        "naming its row (`body.points.I`, 0-based) or CSV line (`body.line.N`, 1-based)."
    ),
)
async def upload(
    request: Request, services: ServicesDep, response: Response,
    name: Annotated[str, Query(max_length=64, description="CSV body: the profile's label")] = "",
) -> RoadProfileOut:
    kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if kind not in ("application/json", "text/csv", "text/plain"):
        raise ApiProblem(415, f"expected a JSON or CSV body (Content-Type application/json or text/csv), got {kind!r}")
    body = await request.body()
    road = await anyio.to_thread.run_sync(_road_from_json if kind == "application/json" else _road_from_csv,
                                          body, name)
    out, created = await anyio.to_thread.run_sync(_store, services, road)
    response.status_code = 201 if created else 200
    response.headers["Location"] = f"/v1/roads/{out.id}"
    return out


def _road_from_json(body: bytes, name: str) -> Road:
    try:
        given = RoadProfileIn.model_validate_json(body)
    except ValidationError as exc:
        raise RequestValidationError([{**e, "loc": ("body", *e["loc"])} for e in exc.errors()]) from None
    try:
        return Road.from_points([p[0] for p in given.points], [p[1] for p in given.points], name=given.name or name)
    except RoadError as exc:
        loc = ("body", "points") if exc.row is None else ("body", "points", exc.row)
        raise validation_problem(loc, exc.msg) from None


def _road_from_csv(body: bytes, name: str) -> Road:
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError:
        raise ApiProblem(400, "the CSV body is not UTF-8 text") from None
    try:
        return road_from_csv(text, name)
    except ProfileError as exc:
        raise validation_problem(("body",) if exc.line is None else ("body", "line", exc.line), exc.msg) from None


def _store(services: Services, road: Road) -> tuple[RoadProfileOut, bool]:
    """(the stored profile, whether it is new): one row per content."""
    digest = content_hash(road)
    with services.db.read() as session:
        existing = profile_by_hash(session, digest)
        if existing is not None:
            return _out(existing), False
    try:
        with services.db.write() as session:
            check_room(session, "road profiles stored", profiles_count(), services.settings.max_profiles,
                       "FINALDRIVE_MAX_PROFILES", lasting=True)
            return _out(create_profile(session, road, name=road.name, digest=digest)), True
    except IntegrityError:  # the same points uploaded concurrently
        with services.db.read() as session:
            existing = profile_by_hash(session, digest)
            if existing is None:
                raise
            return _out(existing), False


@router.get("/profiles", response_model=RoadProfilePage, responses=documented(422),
            summary="Uploaded road profiles, newest first (without their points)")
def profiles(
    services: ServicesDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    cursor: Annotated[str | None, Query(description="next_cursor of the previous page")] = None,
) -> RoadProfilePage:
    before = parse_cursor(cursor)
    with services.db.read() as session:
        rows = list_profiles(session, before_id=before, limit=limit + 1)
        items = [_out(r) for r in rows[:limit]]
    return RoadProfilePage(items=items, next_cursor=str(rows[limit - 1].id) if len(rows) > limit else None)


@router.get("/{profile_id}", response_model=RoadProfileDetail, responses=documented(404, 422),
            summary="An uploaded road profile, with its points")
def profile(profile_id: ProfileId, services: ServicesDep) -> RoadProfileDetail:
    with services.db.read() as session:
        row = session.get(RoadProfile, profile_id, options=[undefer(RoadProfile.xs), undefer(RoadProfile.ys)])
        if row is None:
            raise ApiProblem(404, f"road profile {profile_id} does not exist", slug="not-found")
        return RoadProfileDetail(**_out(row).model_dump(), points=list(zip(row.xs, row.ys, strict=True)))


def _out(row: RoadProfile) -> RoadProfileOut:
    return RoadProfileOut(
        id=row.id, spec=f"profile:{row.id}", name=row.name, content_hash=row.content_hash, n_points=row.n_points,
        x_min_m=row.x_min_m, x_max_m=row.x_max_m, y_min_m=row.y_min_m, y_max_m=row.y_max_m,
        created_at=row.created_at.replace(tzinfo=UTC),
    )
