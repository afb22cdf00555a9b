"""The ASGI app: ``create_app(settings=None)``; everything stateful starts in the lifespan."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from functools import partial
from typing import Any

import anyio
from fastapi import FastAPI

from finaldrive.service import web
from finaldrive.service.api import access, access_log, problems
from finaldrive.service.api.access import AccessControl
from finaldrive.service.api.event_hub import EventHub
from finaldrive.service.api.limits import BodySizeLimit
from finaldrive.service.api.main import api_router
from finaldrive.service.api.renders import RenderSlots
from finaldrive.service.api.routes.jobs import StatusFromSnapshot
from finaldrive.service.config import Settings, get_settings
from finaldrive.service.services import start_services

DESCRIPTION = """Simulate motorcycle final-drive designs on roads: parameter sweeps and differential
evolution jobs, stored in a results database. Errors are `application/problem+json` documents.
When the server has `FINALDRIVE_API_TOKEN` set, every route needs `Authorization: Bearer <token>` (a browser signs
in with `POST /v1/session` instead: an HttpOnly cookie); requests whose Host is not in `FINALDRIVE_ALLOWED_HOSTS`
get 400."""

def create_app(settings: Settings | None = None) -> FastAPI:
    """The app. ``settings`` default to the environment (read at start-up, not here).

    Jobs are run by schedulers (``finaldrive scheduler``; ``finaldrive serve`` starts one)."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        resolved = settings or get_settings()
        services = await anyio.to_thread.run_sync(partial(start_services, resolved))
        app.state.services = services
        access_log.install()  # now: the server has configured its logging
        app.state.events = EventHub(services.db, services.status_cache, poll_s=resolved.events_poll_seconds,
                                    max_streams=resolved.max_streams,
                                    max_per_client=resolved.max_streams_per_client)
        app.state.renders = RenderSlots(resolved.max_concurrent_renders, resolved.render_wait_seconds)
        try:
            yield
        finally:
            await app.state.events.aclose()
            await anyio.to_thread.run_sync(services.close)

    app = FastAPI(title="finaldrive", version="1", description=DESCRIPTION, lifespan=lifespan, docs_url=None,
                  redoc_url=None)
    app.add_middleware(StatusFromSnapshot)  # innermost: behind the access control
    app.add_middleware(BodySizeLimit)
    # outermost: nothing is read before it; a browser without the token gets the sign-in page
    app.add_middleware(AccessControl, login_page=web.login_page)
    problems.install(app)
    app.include_router(api_router)
    app.include_router(access.router)  # POST/DELETE /v1/session: the dashboard's sign-in
    web.install(app)  # the dashboard at /, with /docs and /redoc from packaged assets

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = access.document(problems.problem_media_types(FastAPI.openapi(app)))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app
