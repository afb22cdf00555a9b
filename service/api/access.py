"""Who may talk to the service: the Host allow-list and, when a token is set, the token on every route.

A pure ASGI middleware in front of everything (API, OpenAPI pages, any page or static file):

- the request's Host (port ignored) must be one of ``settings.allowed_hosts`` ("*": any), else
  400: a token-less service on loopback cannot be reached through DNS rebinding;
- with ``settings.api_token`` set, every request needs ``Authorization: Bearer <token>``, or,
  for GET and HEAD only, the cookie ``finaldrive_token=<token>`` (what a browser can send on
  EventSource, <img> and <iframe> requests; never enough for a write, so no CSRF), else 401.
  A browser's page request (GET, Accept text/html, outside /v1/) gets ``login_page()`` as the
  401's body when one is given;
- a recording's file may also be read through a signed link (:func:`signed_link`: an HMAC of the
  path and an expiry, keyed by the token), which is how rerun's web viewer, which sends neither
  the cookie nor headers, loads it in the design page.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
import time
from collections.abc import Callable
from typing import Any
from urllib.parse import unquote

from pydantic import SecretStr
from starlette.requests import Request
from starlette.responses import Response
from starlette.types import ASGIApp, Receive, Scope, Send

from finaldrive.service.api.problems import PROBLEM_MEDIA_TYPE, problem_response

COOKIE = "finaldrive_token"
#: Methods a cookie may authorise (reads only).
COOKIE_METHODS = frozenset({"GET", "HEAD"})
SCHEME_NAME = "HTTPBearer"


def host_name(host: str) -> str:
    """The lower-case host of a Host header value or an allowed name, without port or IPv6 brackets."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:].split("]", 1)[0]
    return host if host.count(":") > 1 else host.split(":", 1)[0]  # a bare IPv6 address has no port


def token_given(request: Request) -> str | None:
    """The credentials of the request: the bearer token, else (GET/HEAD) the cookie."""
    scheme, _, value = request.headers.get("authorization", "").partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    if request.method in COOKIE_METHODS:
        cookie = request.cookies.get(COOKIE)
        return None if cookie is None else unquote(cookie)  # the sign-in page URL-encodes it
    return None


#: Paths a signed link may open without the token: a finished recording's file, for rerun's web viewer,
#: which fetches it without the page's cookie or headers.
SIGNED_PATH = re.compile(r"/v1/recordings/[0-9]+/recording\.rrd")
#: How long a signed link stays valid [s].
SIGNED_LINK_S = 3600


def signature(secret: str, path: str, expires: int) -> str:
    """HMAC-SHA256 of ``path`` and its expiry (Unix seconds), keyed by the token."""
    return hmac.new(secret.encode(), f"{path}\n{expires}".encode(), hashlib.sha256).hexdigest()


def signed_link(token: SecretStr | None, path: str, now: float | None = None) -> str:
    """``path`` with ``?expires=&signature=`` when the server has a token (else ``path`` itself)."""
    if token is None:
        return path
    expires = int((time.time() if now is None else now) + SIGNED_LINK_S)
    return f"{path}?expires={expires}&signature={signature(token.get_secret_value(), path, expires)}"


def _signed(request: Request, secret: str) -> bool:
    """A GET of a signable path with a valid, unexpired signature."""
    if request.method not in COOKIE_METHODS or not SIGNED_PATH.fullmatch(request.url.path):
        return False
    expires, given = request.query_params.get("expires", ""), request.query_params.get("signature", "")
    if not expires.isdigit() or int(expires) < time.time():
        return False
    return secrets.compare_digest(given.encode(), signature(secret, request.url.path, int(expires)).encode())


def _matches(given: str | None, expected: str) -> bool:
    return given is not None and secrets.compare_digest(given.encode(), expected.encode())


class AccessControl:
    """The middleware; settings are read from the running app (they exist once the lifespan started)."""

    def __init__(self, app: ASGIApp, *, login_page: Callable[[], bytes] | None = None) -> None:
        self.app = app
        self.login_page = login_page

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket":  # the service has none: refuse rather than leave one unguarded
            await send({"type": "websocket.close", "code": 1008})
            return
        refusal = self.refusal(scope) if scope["type"] == "http" else None
        await (refusal or self.app)(scope, receive, send)

    def refusal(self, scope: Scope) -> Response | None:
        """The answer refusing the request, or None when it may pass."""
        settings = scope["app"].state.services.settings
        request = Request(scope)
        host = host_name(request.headers.get("host", ""))
        allowed = {host_name(h) for h in settings.allowed_hosts}
        if "*" not in allowed and host not in allowed:
            detail = (f"host {host!r} is not allowed: add it to FINALDRIVE_ALLOWED_HOSTS (comma-separated names; "
                      "'*' allows any)")
            return problem_response(request, 400, detail, slug="host-not-allowed")
        token = settings.api_token
        if token is not None and not (_matches(token_given(request), token.get_secret_value())
                                      or _signed(request, token.get_secret_value())):
            return self._unauthorized(request)
        return None

    def _unauthorized(self, request: Request) -> Response:
        headers = {"WWW-Authenticate": "Bearer"}
        browser_page = (request.method == "GET" and "text/html" in request.headers.get("accept", "")
                        and not request.url.path.startswith("/v1/"))
        if browser_page and self.login_page is not None:
            return Response(self.login_page(), status_code=401, media_type="text/html", headers=headers)
        detail = ("a valid token is required: the header `Authorization: Bearer <token>` (any method) or the cookie "
                  f"`{COOKIE}=<token>` (GET and HEAD only); the token is the server's FINALDRIVE_API_TOKEN")
        return problem_response(request, 401, detail, slug="unauthorized", headers=headers)


def document(openapi: dict[str, Any]) -> dict[str, Any]:
    """The bearer scheme in an OpenAPI document: a global requirement (Swagger UI's Authorize) and a 401
    (and the Host check's 400) on every operation."""
    components = openapi.setdefault("components", {})
    components.setdefault("securitySchemes", {})[SCHEME_NAME] = {
        "type": "http", "scheme": "bearer",
        "description": f"FINALDRIVE_API_TOKEN, when the server sets one (GET/HEAD also take the cookie {COOKIE})"}
    openapi["security"] = [{SCHEME_NAME: []}]
    problem = {"content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}}}
    for path in openapi.get("paths", {}).values():
        for operation in path.values():
            responses = operation.setdefault("responses", {})
            responses.setdefault("401", {"description": "missing or wrong token (only when FINALDRIVE_API_TOKEN "
                                                        "is set)", **problem})
            responses.setdefault("400", {"description": "the Host header is not one of FINALDRIVE_ALLOWED_HOSTS, "
                                                        "or the body could not be read", **problem})
    return openapi
