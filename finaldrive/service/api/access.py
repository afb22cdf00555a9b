"""Who may talk to the service: the Host allow-list and, when a token is set, the token on every route.

A pure ASGI middleware in front of everything (API, OpenAPI pages, any page or static file):

- the request's Host (port ignored) must be one of ``settings.allowed_hosts`` ("*": any), else
  400: a token-less service on loopback cannot be reached through DNS rebinding;
- with ``settings.api_token`` set, every request needs ``Authorization: Bearer <token>`` (what the
  CLI and API clients send), or the dashboard's session cookie, else 401. A browser's page request
  (GET, Accept text/html, outside /v1/) gets ``login_page()`` as the 401.
- The session cookie (``finaldrive_token``) is set by the server only: ``POST /v1/session`` with the
  token (checked in constant time) answers ``Set-Cookie`` with ``HttpOnly; SameSite=Strict`` (and
  ``Secure`` over https), ``DELETE /v1/session`` clears it. Its value is an HMAC keyed by the token,
  not the token, and no script can read it. It authorises GET and HEAD (the page's fetches,
  EventSource, <img>, <iframe>) and, for the dashboard's own writes (submit, cancel, upload,
  record), other methods only from the same origin: ``Sec-Fetch-Site: same-origin`` when the browser
  sends that header, else an ``Origin`` equal to the request's own scheme and Host. SameSite=Strict
  keeps other sites' requests cookie-less; the origin check also refuses a page of the same site on
  another port (another service on localhost), so no CSRF. Bearer tokens work everywhere as before.
- a recording's file may also be read through a signed link (:func:`signed_link`: an HMAC of the
  path and an expiry, keyed by the token), which is how rerun's web viewer, which sends neither
  the cookie nor headers, loads it in the design page. Its fields are parsed within bounds (ASCII
  digits, at most 12 of them; a 64-character hex signature): anything else is a 401.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import time
from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Body
from pydantic import SecretStr
from starlette.requests import Request
from starlette.responses import Response
from starlette.types import ASGIApp, Receive, Scope, Send

from finaldrive.service.api.problems import PROBLEM_MEDIA_TYPE, ApiProblem, documented, problem_response

COOKIE = "finaldrive_token"
#: Methods the cookie authorises from anywhere (reads); other methods need a same-origin request.
READ_METHODS = frozenset({"GET", "HEAD"})
SCHEME_NAME = "HTTPBearer"
SESSION_PATH = "/v1/session"
#: Requests that pass without credentials: signing in and out, and the sign-in page's script.
PUBLIC = frozenset({("POST", SESSION_PATH), ("DELETE", SESSION_PATH), ("GET", "/static/login.js"),
                    ("HEAD", "/static/login.js")})
#: The longest token ``POST /v1/session`` reads.
MAX_TOKEN_CHARS = 4096


def host_name(host: str) -> str:
    """The lower-case host of a Host header value or an allowed name, without port or IPv6 brackets."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:].split("]", 1)[0]
    return host if host.count(":") > 1 else host.split(":", 1)[0]  # a bare IPv6 address has no port


def bearer(request: Request) -> str | None:
    """The request's bearer token, if it has one."""
    scheme, _, value = request.headers.get("authorization", "").partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


def session_value(secret: str) -> str:
    """The session cookie's value: an HMAC of a fixed label keyed by the token (never the token itself)."""
    return hmac.new(secret.encode(), b"finaldrive dashboard session", hashlib.sha256).hexdigest()


def same_origin(request: Request) -> bool:
    """Whether a browser sent the request from a page of this origin (see the module's docstring)."""
    site = request.headers.get("sec-fetch-site")
    if site is not None:
        return site == "same-origin"
    origin = request.headers.get("origin")
    return origin is not None and origin.lower() == f"{request.url.scheme}://{request.headers.get('host', '')}".lower()


#: Paths a signed link may open without the token: a finished recording's file, for rerun's web viewer,
#: which fetches it without the page's cookie or headers.
SIGNED_PATH = re.compile(r"/v1/recordings/[0-9]+/recording\.rrd")
#: How long a signed link stays valid [s].
SIGNED_LINK_S = 3600
#: The most digits an ``expires`` may have (Unix seconds until the year 33658).
EXPIRES_DIGITS = 12


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
    """A GET of a signable path with a valid, unexpired signature (fields checked before any parse)."""
    if request.method not in READ_METHODS or not SIGNED_PATH.fullmatch(request.url.path):
        return False
    expires, given = request.query_params.get("expires", ""), request.query_params.get("signature", "")
    if not (0 < len(expires) <= EXPIRES_DIGITS and expires.isascii() and expires.isdigit()):
        return False
    if int(expires) < time.time() or len(given) != 64 or not given.isascii():
        return False
    return hmac.compare_digest(given.encode(), signature(secret, request.url.path, int(expires)).encode())


def _matches(given: str, expected: str) -> bool:
    """Constant-time equality, whatever the lengths (compares digests)."""
    return hmac.compare_digest(_digest(given), _digest(expected))


def _digest(text: str) -> bytes:
    return hashlib.sha256(text.encode(errors="surrogatepass")).digest()


def authorised(request: Request, secret: str) -> bool:
    """Whether the request may pass a service whose token is ``secret``."""
    if (request.method, request.url.path) in PUBLIC:
        return True
    given = bearer(request)
    if given is not None:
        return _matches(given, secret)
    cookie = request.cookies.get(COOKIE)
    if cookie is not None and _matches(cookie, session_value(secret)):
        return request.method in READ_METHODS or same_origin(request)
    return _signed(request, secret)


class AccessControl:
    """The middleware; settings are read from the running app (they exist once the lifespan started)."""

    def __init__(self, app: ASGIApp, *, login_page: Callable[[], Response] | None = None) -> None:
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
        if token is not None and not authorised(request, token.get_secret_value()):
            return self._unauthorized(request)
        return None

    def _unauthorized(self, request: Request) -> Response:
        browser_page = (request.method == "GET" and "text/html" in request.headers.get("accept", "")
                        and not request.url.path.startswith("/v1/"))
        if browser_page and self.login_page is not None:
            return self.login_page()
        return problem_response(request, 401, UNAUTHORIZED, slug="unauthorized", headers={"WWW-Authenticate": "Bearer"})


UNAUTHORIZED = ("a valid token is required: the header `Authorization: Bearer <token>` (any method) or the dashboard's "
                f"session cookie `{COOKIE}` (set by `POST {SESSION_PATH}`; writes only from the dashboard's own "
                "pages); the token is the server's FINALDRIVE_API_TOKEN")

router = APIRouter(prefix="/v1", tags=["session"])
_SIGN_IN_ERRORS: dict[int | str, dict[str, Any]] = {s: documented(401, 422)[s] for s in (401, 422)}


@router.post("/session", status_code=204, response_class=Response, responses=_SIGN_IN_ERRORS,
             summary="Sign a browser in: the dashboard's session cookie (HttpOnly, SameSite=Strict)")
def sign_in(request: Request,
            token: Annotated[str, Body(embed=True, min_length=1, max_length=MAX_TOKEN_CHARS)]) -> Response:
    """With the server's token, answers 204 and ``Set-Cookie: finaldrive_token=...; HttpOnly; SameSite=Strict``
    (``Secure`` over https); a wrong token gets 401. A server without a token needs no sign-in: 204, no cookie."""
    secret = request.app.state.services.settings.api_token
    response = Response(status_code=204)
    if secret is None:
        return response
    if not _matches(token, secret.get_secret_value()):
        raise ApiProblem(401, "body.token: that is not the server's token", slug="unauthorized")
    response.set_cookie(COOKIE, session_value(secret.get_secret_value()), path="/", httponly=True, samesite="strict",
                        secure=request.url.scheme == "https")
    return response


@router.delete("/session", status_code=204, response_class=Response, summary="Sign a browser out")
def sign_out(request: Request) -> Response:
    """Clears the session cookie (204)."""
    response = Response(status_code=204)
    response.delete_cookie(COOKIE, path="/", httponly=True, samesite="strict", secure=request.url.scheme == "https")
    return response


def document(openapi: dict[str, Any]) -> dict[str, Any]:
    """The bearer scheme in an OpenAPI document: a global requirement (Swagger UI's Authorize) and a 401
    (and the Host check's 400) on every operation."""
    components = openapi.setdefault("components", {})
    components.setdefault("securitySchemes", {})[SCHEME_NAME] = {
        "type": "http", "scheme": "bearer",
        "description": f"FINALDRIVE_API_TOKEN, when the server sets one (a browser signs in with POST {SESSION_PATH}: "
                       f"the HttpOnly cookie {COOKIE})"}
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
