"""The dashboard's routes: its pages, their static files, the offline API docs and rerun's viewer.

Pages are static HTML shells whose scripts read the /v1 API (with the session's HttpOnly cookie, when
the server has a token) and build the DOM from text, never HTML. Every HTML answer carries a
Content-Security-Policy that lets a page load and fetch only from this origin (nothing a page, or the
viewer inside it, asks for leaves the machine) and runs no inline script: the dashboard's scripts are
files; the inline scripts of pages made by others (Swagger UI's from FastAPI, rerun's viewer) are
allowed by their SHA-256 hashes only (:func:`policy`). ``'wasm-unsafe-eval'`` is for rerun's viewer.
"""

from __future__ import annotations

import base64
import hashlib
import re
from functools import lru_cache
from pathlib import Path

import anyio
from fastapi import APIRouter, FastAPI, HTTPException
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from finaldrive.service.api.deps import JobId
from finaldrive.service.web import viewer

STATIC = Path(__file__).parent / "static"
SCRIPT_SRC = "script-src 'self' 'wasm-unsafe-eval'"
CSP = (f"default-src 'self'; {SCRIPT_SRC}; style-src 'self' 'unsafe-inline'; object-src 'none'; "
       "img-src 'self' data: blob:; font-src 'self' data:; connect-src 'self'; worker-src 'self' blob:; "
       "frame-src 'self'; frame-ancestors 'self'; base-uri 'self'; form-action 'self'")
HEADERS = {"Content-Security-Policy": CSP, "X-Content-Type-Options": "nosniff", "Referrer-Policy": "same-origin"}
_INLINE_SCRIPT = re.compile(rb"<script(?![^>]*\ssrc\s*=)[^>]*>(.*?)</script\s*>", re.S | re.I)
_VIEWER_TYPES = {".html": "text/html", ".js": "text/javascript", ".wasm": "application/wasm",
                 ".ico": "image/x-icon"}

router = APIRouter(include_in_schema=False)


def _page(name: str) -> FileResponse:
    return FileResponse(STATIC / name, media_type="text/html", headers=HEADERS)


def policy(html: bytes) -> str:
    """The CSP for a page made by others: :data:`CSP`, its script-src also allowing exactly the page's inline
    scripts (by hash)."""
    hashes = [f"'sha256-{base64.b64encode(hashlib.sha256(body).digest()).decode()}'"
              for body in _INLINE_SCRIPT.findall(html)]
    return CSP.replace(SCRIPT_SRC, " ".join([SCRIPT_SRC, *hashes]))


def _with_policy(page: HTMLResponse) -> HTMLResponse:
    page.headers.update({**HEADERS, "Content-Security-Policy": policy(bytes(page.body))})
    return page


@lru_cache(maxsize=4)
def _viewer_policy(index: Path) -> str:
    return policy(index.read_bytes())


def login_page() -> Response:
    """The sign-in page a browser gets (a 401) when the server has a token and the request no session."""
    return Response((STATIC / "login.html").read_bytes(), status_code=401, media_type="text/html",
                    headers={**HEADERS, "WWW-Authenticate": "Bearer"})


@router.get("/")
def jobs_page() -> FileResponse:
    return _page("jobs.html")


@router.get("/jobs/{job_id}")
def job_page(job_id: JobId) -> FileResponse:
    return _page("job.html")


@router.get("/design")
def design_page() -> FileResponse:
    return _page("design.html")


@router.get("/docs")
def swagger_ui() -> HTMLResponse:
    page = get_swagger_ui_html(
        openapi_url="/openapi.json", title="finaldrive API",
        swagger_js_url="/static/vendor/swagger-ui/swagger-ui-bundle.js",
        swagger_css_url="/static/vendor/swagger-ui/swagger-ui.css",
        swagger_favicon_url="/static/vendor/swagger-ui/favicon-32x32.png",
    )
    return _with_policy(page)


@router.get("/redoc")
def redoc() -> HTMLResponse:
    page = get_redoc_html(openapi_url="/openapi.json", title="finaldrive API",
                          redoc_js_url="/static/vendor/redoc/redoc.standalone.js",
                          redoc_favicon_url="/static/vendor/swagger-ui/favicon-32x32.png", with_google_fonts=False)
    return _with_policy(page)


@router.get("/viewer/")
@router.get("/viewer/{name}")
async def viewer_file(name: str = "index.html") -> Response:
    """rerun's web viewer (``/viewer/?url=<recording>``), from the installed rerun-sdk."""
    if name not in viewer.FILES:
        raise HTTPException(404)
    try:
        folder = await anyio.to_thread.run_sync(viewer.assets)
    except viewer.ViewerUnavailable as exc:
        return Response(f"rerun's web viewer is unavailable: {exc}", status_code=503, media_type="text/plain")
    suffix = Path(name).suffix
    headers = {**HEADERS, "Content-Security-Policy": _viewer_policy(folder / name)} if suffix == ".html" else None
    return FileResponse(folder / name, media_type=_VIEWER_TYPES[suffix], headers=headers)


def install(app: FastAPI) -> None:
    """Mount the dashboard on ``app`` (the app's own /docs and /redoc must be off)."""
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
