"""Errors as RFC 9457 problem details (``application/problem+json``), never tracebacks."""

from __future__ import annotations

import logging
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import InterfaceError, OperationalError, TimeoutError as PoolTimeout
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from finaldrive.service.db.repository import LimitReached
from finaldrive.service.schemas import Problem, ProblemItem

log = logging.getLogger(__name__)

PROBLEM_MEDIA_TYPE = "application/problem+json"


class ApiProblem(Exception):
    """Raise from a route to answer with a problem document."""

    def __init__(
        self, status: int, detail: str, *, slug: str | None = None,
        errors: list[ProblemItem] | None = None, headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(detail)
        self.status, self.detail, self.slug, self.errors, self.headers = status, detail, slug, errors, headers


def problem_response(
    request: Request, status: int, detail: str, *, slug: str | None = None,
    errors: list[ProblemItem] | None = None, headers: dict[str, str] | None = None,
) -> JSONResponse:
    body = Problem(
        type=f"urn:finaldrive:problem:{slug}" if slug else "about:blank",
        title=HTTPStatus(status).phrase, status=status, detail=detail,
        instance=request.url.path, errors=errors,
    )
    return JSONResponse(
        body.model_dump(exclude_none=True), status_code=status, media_type=PROBLEM_MEDIA_TYPE, headers=headers
    )


def validation_problem(loc: tuple[str | int, ...], msg: str) -> ApiProblem:
    """A 422 naming one field (``loc`` as in pydantic errors, e.g. ("body", "roads", 0))."""
    return ApiProblem(
        422, f"{_where(loc)}: {msg}", slug="validation-error", errors=[ProblemItem(loc=list(loc), msg=msg)]
    )


def _where(loc: tuple[str | int, ...] | list[Any]) -> str:
    return ".".join(str(part) for part in loc) or "request"


async def _on_api_problem(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, ApiProblem)
    return problem_response(request, exc.status, exc.detail, slug=exc.slug, errors=exc.errors, headers=exc.headers)


async def _on_http_exception(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    detail = exc.detail if isinstance(exc.detail, str) else HTTPStatus(exc.status_code).phrase
    return problem_response(request, exc.status_code, detail, headers=getattr(exc, "headers", None))


async def _on_validation_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    items = [ProblemItem(loc=list(e.get("loc", ())), msg=str(e.get("msg", "invalid"))) for e in exc.errors()]
    detail = "; ".join(f"{_where(i.loc)}: {i.msg}" for i in items[:5]) or "invalid request"
    return problem_response(request, 422, detail, slug="validation-error", errors=items)


#: Seconds a client should wait before repeating a request the store could not serve.
RETRY_AFTER_S = 5


async def _on_store_unavailable(request: Request, exc: Exception) -> JSONResponse:
    """The store is locked past its timeout, full, or unreachable: 503, and the details only in the log."""
    log.warning("store unavailable on %s %s: %s", request.method, request.url.path, " ".join(str(exc).split())[:500])
    return problem_response(request, 503, "the results store is unavailable (locked, full or unreachable); "
                            "nothing was changed; retry later", slug="store-unavailable",
                            headers={"Retry-After": str(RETRY_AFTER_S)})


async def _on_limit_reached(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, LimitReached)
    if exc.lasting:
        return problem_response(request, 507, str(exc), slug="limit-reached")
    return problem_response(request, 429, str(exc), slug="limit-reached", headers={"Retry-After": "30"})


class ErrorsAsProblems:
    """The safety net: an exception no handler took becomes a logged 500 problem document, and is not
    raised further. Starlette's own net re-raises after answering, and uvicorn then drops the connection;
    this one keeps it. Once a response has started (a stream) an exception can only end it: re-raised."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def watched(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, watched)
        except Exception as exc:
            if started:
                raise
            request = Request(scope)
            log.exception("unhandled error on %s %s", request.method, request.url.path, exc_info=exc)
            await problem_response(request, 500, "internal error; see the server log")(scope, receive, send)


def install(app: FastAPI) -> None:
    """The problem handlers, and :class:`ErrorsAsProblems` as the outermost middleware added so far (call
    this after adding the others)."""
    app.add_exception_handler(ApiProblem, _on_api_problem)
    app.add_exception_handler(LimitReached, _on_limit_reached)
    app.add_exception_handler(StarletteHTTPException, _on_http_exception)
    app.add_exception_handler(RequestValidationError, _on_validation_error)
    for error in (OperationalError, InterfaceError, PoolTimeout):
        app.add_exception_handler(error, _on_store_unavailable)
    app.add_middleware(ErrorsAsProblems)


def documented(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entries for problem statuses, and 503 (every route reads the store; media type
    fixed in the OpenAPI hook)."""
    text = {
        400: "the body could not be read (its bytes are not UTF-8)",
        401: "missing or wrong bearer token (only when FINALDRIVE_API_TOKEN is set)",
        404: "no such job or resource",
        409: "the resource is not ready for this (e.g. a recording still being produced)",
        413: "request body larger than FINALDRIVE_MAX_BODY_BYTES",
        415: "the body's Content-Type is not one this operation takes",
        422: "invalid request; `errors` names each field and the reason",
        429: "too many at once: event streams open (FINALDRIVE_MAX_STREAMS_PER_CLIENT, FINALDRIVE_MAX_STREAMS), "
             "jobs unfinished (FINALDRIVE_MAX_ACTIVE_JOBS) or recordings pending (FINALDRIVE_MAX_PENDING_RECORDINGS); "
             "retry after Retry-After seconds",
        507: "the store keeps as many road profiles as FINALDRIVE_MAX_PROFILES allows",
        503: "the results store is unavailable (locked, full or unreachable), or the server is busy rendering "
             "(plots, points); retry after Retry-After seconds",
    }
    return {s: {"model": Problem, "description": text[s]} for s in (*statuses, 503)}


def problem_media_types(openapi: dict[str, Any]) -> dict[str, Any]:
    """Declare error responses as application/problem+json in an OpenAPI document."""
    for path in openapi.get("paths", {}).values():
        for operation in path.values():
            for status, response in operation.get("responses", {}).items():
                content = response.get("content")
                schema = next(iter(content.values())).get("schema", {}) if content else {}
                if status[0] in "45" and str(schema.get("$ref", "")).endswith("/Problem"):  # JSON, SSE -> problem
                    response["content"] = {PROBLEM_MEDIA_TYPE: next(iter(content.values()))}
    return openapi
