"""The dashboard's routes: its pages, their static files, the offline API docs and rerun's viewer.

Pages are static HTML shells whose scripts read the /v1 API (with the session's token, when the
server has one). Every HTML answer carries a Content-Security-Policy that lets a page load and fetch
only from this origin: nothing a page (or the viewer inside it) asks for leaves the machine.
"""

from __future__ import annotations

from pathlib import Path

import anyio
from fastapi import APIRouter, FastAPI, HTTPException
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from finaldrive.service.api.deps import JobId
from finaldrive.service.web import viewer

STATIC = Path(__file__).parent / "static"
CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval'; style-src 'self' 'unsafe-inline'; "
       "img-src 'self' data: blob:; font-src 'self' data:; connect-src 'self'; worker-src 'self' blob:; "
       "frame-src 'self'; frame-ancestors 'self'; base-uri 'self'; form-action 'self'")
HEADERS = {"Content-Security-Policy": CSP, "X-Content-Type-Options": "nosniff", "Referrer-Policy": "same-origin"}
_VIEWER_TYPES = {".html": "text/html", ".js": "text/javascript", ".wasm": "application/wasm",
                 ".ico": "image/x-icon"}

router = APIRouter(include_in_schema=False)


def _page(name: str) -> FileResponse:
    return FileResponse(STATIC / name, media_type="text/html", headers=HEADERS)


def login_page() -> bytes:
    """The page a browser gets (with 401) when the server has a token and the session none."""
    return (STATIC / "login.html").read_bytes()


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
    page.headers.update(HEADERS)
    return page


@router.get("/redoc")
def redoc() -> HTMLResponse:
    page = get_redoc_html(openapi_url="/openapi.json", title="finaldrive API",
                          redoc_js_url="/static/vendor/redoc/redoc.standalone.js",
                          redoc_favicon_url="/static/vendor/swagger-ui/favicon-32x32.png", with_google_fonts=False)
    page.headers.update(HEADERS)
    return page


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
    return FileResponse(folder / name, media_type=_VIEWER_TYPES[suffix], headers=HEADERS if suffix == ".html" else None)


def install(app: FastAPI) -> None:
    """Mount the dashboard on ``app`` (the app's own /docs and /redoc must be off)."""
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
