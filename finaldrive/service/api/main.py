"""The /v1 router: one include per resource."""

from __future__ import annotations

from fastapi import APIRouter

from finaldrive.service.api.routes import (
    events,
    geometry,
    health,
    history,
    jobs,
    plots,
    points,
    recordings,
    results,
    roads,
)

api_router = APIRouter(prefix="/v1")
for module in (jobs, results, history, points, events, roads, geometry, health, recordings, plots):
    api_router.include_router(module.router)
