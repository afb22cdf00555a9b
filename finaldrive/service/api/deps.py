"""Dependencies of the routes, as Annotated aliases (overridable in tests)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request

from finaldrive.service.api.event_hub import EventHub
from finaldrive.service.api.renders import RenderSlots
from finaldrive.service.services import Services


def get_services(request: Request) -> Services:
    services: Services = request.app.state.services
    return services


ServicesDep = Annotated[Services, Depends(get_services)]


def get_events(request: Request) -> EventHub:
    events: EventHub = request.app.state.events
    return events


def get_renders(request: Request) -> RenderSlots:
    renders: RenderSlots = request.app.state.renders
    return renders


EventsDep = Annotated[EventHub, Depends(get_events)]
RendersDep = Annotated[RenderSlots, Depends(get_renders)]

#: Largest row id SQLite (and a BIGINT) can hold.
MAX_ID = 2**63 - 1

JobId = Annotated[int, Path(ge=1, le=MAX_ID, description="job id")]
