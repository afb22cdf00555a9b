"""A small HTTP client for the finaldrive job service (httpx; speaks only the /v1 API).

Errors come back as two exceptions the CLI maps to exit codes: :class:`ApiError` (the
server answered 4xx/5xx; ``detail`` is the problem document's one-line detail) and
:class:`Unreachable` (no answer: refused, timed out, DNS).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx

DEFAULT_SERVER = "http://127.0.0.1:8000"


class ClientError(Exception):
    """Base of the client's errors; ``str()`` is one line."""


class ApiError(ClientError):
    def __init__(self, status: int, detail: str) -> None:
        super().__init__(f"HTTP {status}: {detail}")
        self.status = status
        self.detail = detail


class Unreachable(ClientError):
    pass


def default_server() -> str:
    return os.environ.get("FINALDRIVE_SERVER") or DEFAULT_SERVER


def auth_headers(token: str | None = None) -> dict[str, str]:
    """The bearer header of ``token`` (default: $FINALDRIVE_API_TOKEN) for every request, reads included."""
    token = token if token is not None else os.environ.get("FINALDRIVE_API_TOKEN")
    return {"Authorization": f"Bearer {token}"} if token else {}


class ServiceClient:
    """The service's endpoints as methods; ``http`` can be injected (tests, transports)."""

    def __init__(self, server: str | None = None, *, token: str | None = None,
                 http: httpx.Client | None = None, timeout: float = 30.0) -> None:
        self.server = (server or default_server()).rstrip("/")
        self.http = http or httpx.Client(base_url=self.server, timeout=timeout, headers=auth_headers(token))

    def close(self) -> None:
        self.http.close()

    def __enter__(self) -> ServiceClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ transport
    def request(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        try:
            response = self.http.request(method, path, **kwargs)
        except httpx.TransportError as exc:
            raise Unreachable(f"cannot reach the service at {self.server}: {exc or type(exc).__name__}") from None
        if response.is_error:
            raise ApiError(response.status_code, _detail(response))
        return response

    def json(self, method: str, path: str, **kwargs: Any) -> Any:
        return self.request(method, path, **kwargs).json()

    def object(self, method: str, path: str, **kwargs: Any) -> dict[str, Any]:
        """A JSON object answer (anything else is an error of the server)."""
        body = self.json(method, path, **kwargs)
        if not isinstance(body, dict):
            raise ApiError(502, f"expected a JSON object from {path}, got {type(body).__name__}")
        return body

    # ------------------------------------------------------------------ endpoints
    def health(self) -> dict[str, Any]:
        return self.object("GET", "/v1/health")

    def submit(self, spec: dict[str, Any], idempotency_key: str | None = None) -> dict[str, Any]:
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        return self.object("POST", "/v1/jobs", json=spec, headers=headers)

    def upload_profile(self, csv_text: str, name: str = "") -> dict[str, Any]:
        """Store a measured road (CSV of x, y [m]); the answer's ``spec`` (profile:ID) names it in jobs."""
        return self.object("POST", "/v1/roads", content=csv_text.encode(), params={"name": name},
                           headers={"Content-Type": "text/csv"})

    def jobs(self, *, state: str | None = None, kind: str | None = None, limit: int = 50) -> list[dict[str, Any]]:
        params = {k: v for k, v in {"state": state, "kind": kind, "limit": limit}.items() if v is not None}
        return list(self.json("GET", "/v1/jobs", params=params)["items"])

    def job(self, job_id: int) -> dict[str, Any]:
        return self.object("GET", f"/v1/jobs/{job_id}")

    def cancel(self, job_id: int) -> dict[str, Any]:
        return self.object("POST", f"/v1/jobs/{job_id}/cancel")

    def best(self, job_id: int, tolerance_pct: float | None = None, sensitivity: bool = False,
             wait_s: float = 600.0, band: bool = False, model_band: bool = False) -> dict[str, Any]:
        """The job's best designs; with ``sensitivity`` (``band``, ``model_band``), polled (as Retry-After
        asks) until the scheduler has simulated the finite differences (the numerical bands, the model
        bands), at most ``wait_s`` (then ApiError 504)."""
        params = {name: "true" for name, wanted in (("sensitivity", sensitivity), ("band", band),
                                                    ("model_band", model_band)) if wanted}
        if tolerance_pct is not None:
            params["tolerance_pct"] = repr(tolerance_pct)
        deadline = time.monotonic() + wait_s
        while True:
            response = self.request("GET", f"/v1/jobs/{job_id}/best", params=params)
            if response.status_code != 202:
                body: dict[str, Any] = response.json()
                return body
            if time.monotonic() > deadline:
                body = response.json()
                raise ApiError(504, f"job {job_id}: its sensitivity job {body.get('sensitivity_job')}, band jobs "
                               f"{body.get('band_jobs')} or model-band jobs {body.get('model_band_jobs')} have not "
                               f"finished within {wait_s:g} s")
            retry = response.headers.get("Retry-After", "")
            time.sleep(min(float(retry), 10.0) if retry.isdigit() else 2.0)

    def evaluations_csv(self, job_id: int, road: str | None = None, page: int = 10_000) -> Iterator[str]:
        """The job's evaluations as CSV text, page by page (the header only in the first)."""
        cursor: str | None = None
        first = True
        while True:
            params: dict[str, Any] = {"format": "csv", "limit": page}
            if road is not None:
                params["road"] = road
            if cursor:
                params["cursor"] = cursor
            response = self.request("GET", f"/v1/jobs/{job_id}/evaluations", params=params)
            text = response.text
            yield text if first else text.split("\n", 1)[1] if "\n" in text else ""
            first = False
            cursor = response.headers.get("X-Next-Cursor") or None
            if cursor is None:
                return

    def plot(self, job_id: int, name: str, road: str | None = None) -> bytes:
        params = {"road": road} if road is not None else {}
        return self.request("GET", f"/v1/jobs/{job_id}/plots/{name}.png", params=params).content

    def create_recording(self, body: dict[str, Any]) -> dict[str, Any]:
        return self.object("POST", "/v1/recordings", json=body)

    def recording(self, recording_id: int) -> dict[str, Any]:
        return self.object("GET", f"/v1/recordings/{recording_id}")

    def download_recording(self, recording_id: int, dest: Path) -> int:
        """Stream the .rrd to ``dest``; returns the bytes written."""
        try:
            with self.http.stream("GET", f"/v1/recordings/{recording_id}/file") as response:
                if response.is_error:
                    response.read()
                    raise ApiError(response.status_code, _detail(response))
                n = 0
                with dest.open("wb") as out:
                    for block in response.iter_bytes():
                        n += out.write(block)
                return n
        except httpx.TransportError as exc:
            raise Unreachable(f"cannot reach the service at {self.server}: {exc}") from None


def _detail(response: httpx.Response) -> str:
    """The problem document's detail (or title), else the start of the body, on one line."""
    try:
        body = response.json()
    except ValueError:
        body = None
    if isinstance(body, dict):
        text = str(body.get("detail") or body.get("title") or body)
    else:
        text = response.text.strip()[:200] or response.reason_phrase
    return " ".join(text.split())
