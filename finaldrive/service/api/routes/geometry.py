"""/v1/geometry: a design's static quantities and its kinematics over the rear travel (the paper's vehicle, or a
job's)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Query
from fastapi.responses import Response

from finaldrive.engine import (
    MAX_TRAVEL_POINTS,
    TRAVEL_POINTS,
    Design,
    Vehicle,
    static_geometry,
    travel_kinematics,
)
from finaldrive.service.api.deps import MAX_ID, ServicesDep
from finaldrive.service.api.lookups import job_vehicle
from finaldrive.service.api.problems import ApiProblem, documented
from finaldrive.service.schemas import GeometryOut

router = APIRouter(prefix="/geometry", tags=["geometry"])

A2 = Annotated[float, Query(ge=-360.0, le=720.0, description="engine sprocket angle a2 [deg]")]
L2 = Annotated[float, Query(ge=0.0, le=0.5, description="pivot to engine sprocket axis L2 [m]")]
RWS = Annotated[float, Query(ge=0.01, le=0.25, description="wheel sprocket pitch radius R_WS [m] (a 9-tooth "
                             "sprocket of a 520 chain is 23 mm; the paper's tyre is 300 mm)")]
Points = Annotated[int, Query(ge=2, le=MAX_TRAVEL_POINTS, description="points of the travel curve")]
JobVehicle = Annotated[int | None, Query(ge=1, le=MAX_ID, description="take the vehicle of this job (default: the "
                                         "paper's)")]


def _design(a2_deg: float, l2_m: float, rws_m: float) -> Design:
    try:
        return Design.from_deg(a2_deg, l2_m, rws_m)
    except ValueError as exc:
        raise ApiProblem(422, str(exc), slug="invalid-design") from None


def _travel(design: Design, vehicle: Vehicle, points: int) -> dict[str, Any]:
    try:
        return travel_kinematics(design, vehicle, points)
    except (ValueError, ArithmeticError) as exc:
        raise ApiProblem(422, str(exc), slug="invalid-design") from None


@router.get("", response_model=GeometryOut, responses=documented(404, 422),
            summary="A design's squat ratio, chain length, swingarm angle at static sag and (travel=true) "
                    "kinematics over the rear travel")
def geometry(a2_deg: A2, l2_m: L2, rws_m: RWS, services: ServicesDep, travel: Annotated[bool, Query(
                 description="add SR, anti-squat, chain growth and the sprocket-pivot geometry over the rear travel")]
             = False, points: Points = TRAVEL_POINTS, job: JobVehicle = None) -> GeometryOut:
    design = _design(a2_deg, l2_m, rws_m)
    vehicle = job_vehicle(services, job)
    try:
        g = static_geometry(design, vehicle)
    except (ValueError, ArithmeticError) as exc:
        raise ApiProblem(422, str(exc), slug="invalid-design") from None
    return GeometryOut(a2_deg=a2_deg, l2_m=l2_m, rws_m=rws_m, res_m=g["res_m"], squat_ratio=g["squat_ratio"],
                       chain_length_m=g["chain_length_m"], taut_length_m=g["taut_length_m"],
                       engine_sprocket_x_m=g["engine_sprocket_x_m"], engine_sprocket_y_m=g["engine_sprocket_y_m"],
                       swingarm_angle_deg=g["swingarm_angle_deg"],
                       travel_curve=_travel(design, vehicle, points) if travel else None)


@router.get("/travel.png", response_class=Response, responses={
    200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}, "description": "the plot"},
    **documented(404, 422)}, summary="SR, anti-squat and chain growth over the rear travel, as PNG")
def travel_png(a2_deg: A2, l2_m: L2, rws_m: RWS, services: ServicesDep, points: Points = TRAVEL_POINTS,
               job: JobVehicle = None) -> Response:
    from finaldrive.service.media.plots import travel_png as draw

    design = _design(a2_deg, l2_m, rws_m)
    t = _travel(design, job_vehicle(services, job), points)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "travel.png"
        draw(path, t, title=f"a2 = {a2_deg:g} deg, L2 = {l2_m:g} m, R_WS = {rws_m:g} m")
        body = path.read_bytes()
    return Response(body, media_type="image/png")
