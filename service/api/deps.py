"""Dependencies of the routes, as Annotated aliases (overridable in tests)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request

from finaldrive.service.services import Services


def get_services(request: Request) -> Services:
    services: Services = request.app.state.services
    return services


ServicesDep = Annotated[Services, Depends(get_services)]

#: Largest row id SQLite (and a BIGINT) can hold.
MAX_ID = 2**63 - 1

JobId = Annotated[int, Path(ge=1, le=MAX_ID, description="job id")]
