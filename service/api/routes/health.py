"""/v1/health: liveness plus what the service runs with."""

from __future__ import annotations

from fastapi import APIRouter

from finaldrive.service.api.deps import ServicesDep
from finaldrive.service.db.repository import count_active
from finaldrive.service.schemas import HealthOut

router = APIRouter(prefix="/health", tags=["health"])


@router.get("", response_model=HealthOut, summary="Service health")
def health(services: ServicesDep) -> HealthOut:
    with services.db.read() as session:
        active = count_active(session)
    return HealthOut(
        status="ok", schema_revision=services.schema_revision, executor=services.settings.executor,
        engine_version=services.engine_version, active_jobs=active,
    )
