"""/v1/roads: the paper's 23 road presets."""

from __future__ import annotations

from fastapi import APIRouter

from finaldrive.engine import PRESETS
from finaldrive.service.schemas import RoadOut

router = APIRouter(prefix="/roads", tags=["roads"])


@router.get("", response_model=list[RoadOut], summary="Road presets, in the paper's table order")
def roads() -> list[RoadOut]:
    return [
        RoadOut(name=p.name, spec=p.spec, kind=p.road.kind, description=p.description, paper=p.paper)
        for p in PRESETS.values()
    ]
