"""Access: with a token every route wants it (the session cookie writes only from the same origin); the sign-in
route; signed links; the Host allow-list."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from pydantic import SecretStr, ValidationError

from finaldrive.service.api.access import COOKIE, SIGNED_LINK_S, host_name, session_value, signature, signed_link
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from finaldrive.service.web import login_page
from tests.service.asgi_stream import AsgiStream
from tests.service.svc_helpers import SWEEP, ToyTask, running_scheduler, wait_done

TOKEN = "s3cret"
BEARER = {"Authorization": f"Bearer {TOKEN}"}
COOKIE_HEADER = {"Cookie": f"{COOKIE}={session_value(TOKEN)}"}
#: Path parameters filled in to reach every route.
PARAMS = {"job_id": "1", "recording_id": "1", "profile_id": "1", "name": "sweep-map"}
#: Paths of pages and files the dashboard will add: guarded like the API before they exist.
FUTURE = ["/", "/jobs/1", "/static/app.js", "/viewer/index.html"]


def get_paths(app: FastAPI) -> list[str]:
    """Every GET route of the app, its path parameters filled in."""
    paths: list[str] = []
    for route in app.routes:
        contexts = route.effective_route_contexts() if hasattr(route, "effective_route_contexts") else [route]
        paths += [c.path for c in contexts if "GET" in (getattr(c, "methods", None) or ())]
    return [re.sub(r"\{(\w+)\}", lambda m: PARAMS[m.group(1)], p) for p in paths]


@pytest.fixture
def guarded(settings: Settings) -> Iterator[TestClient]:
    """A service with a token, and job 1 finished (so its streams end)."""
    secured = settings.model_copy(update={"api_token": SecretStr(TOKEN)})
    with TestClient(create_app(secured)) as c, running_scheduler(secured, ToyTask()):
        job_id = c.post("/v1/jobs", json=SWEEP, headers=BEARER).json()["id"]
        c.headers.update(BEARER)
        wait_done(c, job_id)
        c.headers.pop("Authorization")
        yield c


def status(client: TestClient, path: str, headers: dict[str, str] | None = None, method: str = "GET") -> int:
    """The status of a request, taken as soon as the answer begins (streams are then closed)."""
    stream = AsgiStream(client, path, method=method, headers=headers)
    try:
        return stream.started()
    finally:
        stream.close()


def test_every_get_route_wants_the_token(guarded: TestClient) -> None:
    paths = get_paths(guarded.app)  # type: ignore[arg-type]
    assert {"/v1/health", "/v1/jobs/1/events", "/v1/events", "/openapi.json", "/docs", "/redoc",
            "/v1/recordings/1/file", "/v1/jobs/1/plots/sweep-map.png", "/v1/jobs/1/points"} <= set(paths)
    for path in [*paths, *FUTURE]:
        assert status(guarded, path) == 401, path
        assert status(guarded, path, {"Authorization": "Bearer wrong"}) == 401, path
        assert status(guarded, path, {"Cookie": f"{COOKIE}=wrong"}) == 401, path
        assert status(guarded, path, {"Cookie": f"{COOKIE}={TOKEN}"}) == 401, path  # the cookie is not the token
        assert status(guarded, path, BEARER) != 401, path
        assert status(guarded, path, COOKIE_HEADER) != 401, path


def test_the_refusal_is_a_problem_naming_the_credentials(guarded: TestClient) -> None:
    r = guarded.get("/v1/jobs/1")
    assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
    assert r.headers["content-type"] == "application/problem+json"
    assert "Authorization: Bearer" in r.json()["detail"] and COOKIE in r.json()["detail"]
    assert guarded.get("/v1/jobs/1", headers={"Authorization": f"bearer {TOKEN}"}).status_code == 200


@pytest.mark.parametrize("browser", [
    {}, {"Origin": "http://evil.example"}, {"Origin": "http://testserver:3000"},  # another service on the same host
    {"Origin": "https://testserver"}, {"Origin": "null"}, {"Sec-Fetch-Site": "same-site"},
    {"Sec-Fetch-Site": "cross-site", "Origin": "http://testserver"}, {"Sec-Fetch-Site": "none"}])
def test_the_cookie_never_authorises_a_write_from_elsewhere(guarded: TestClient, browser: dict[str, str]) -> None:
    for path in ("/v1/jobs", "/v1/jobs/1/cancel"):
        r = guarded.post(path, json=SWEEP, headers={**COOKIE_HEADER, **browser})
        assert r.status_code == 401, path
    assert guarded.get("/v1/jobs", headers=BEARER).json()["items"][0]["state"] == "succeeded"
    assert guarded.post("/v1/jobs", json=SWEEP, headers=BEARER).status_code == 201


@pytest.mark.parametrize("browser", [{"Sec-Fetch-Site": "same-origin"}, {"Origin": "http://testserver"},
                                     {"Sec-Fetch-Site": "same-origin", "Origin": "http://TestServer"}])
def test_the_cookie_authorises_the_dashboard_s_own_writes(guarded: TestClient, browser: dict[str, str]) -> None:
    r = guarded.post("/v1/jobs", json=SWEEP, headers={**COOKIE_HEADER, **browser})
    assert r.status_code == 201, r.text
    assert guarded.post(f"/v1/jobs/{r.json()['id']}/cancel", headers={**COOKIE_HEADER, **browser}).status_code == 200


def test_a_foreign_host_is_refused_even_with_the_token(guarded: TestClient) -> None:
    r = guarded.get("/v1/health", headers={**BEARER, "Host": "evil.example"})
    assert r.status_code == 400 and r.json()["type"] == "urn:finaldrive:problem:host-not-allowed"
    assert "evil.example" in r.json()["detail"] and "FINALDRIVE_ALLOWED_HOSTS" in r.json()["detail"]
    assert guarded.get("/v1/health", headers={**BEARER, "Host": "testserver:8000"}).status_code == 200


def test_host_names_and_defaults() -> None:
    assert [host_name(h) for h in ("LocalHost:80", "[::1]:8000", "::1", "127.0.0.1")] == [
        "localhost", "::1", "::1", "127.0.0.1"]
    assert Settings().allowed_hosts == ["127.0.0.1", "localhost", "[::1]", "::1"]
    assert Settings(host="fd.lan").allowed_hosts[-1] == "fd.lan"
    assert "0.0.0.0" not in Settings(host="0.0.0.0").allowed_hosts


def test_allowed_hosts_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FINALDRIVE_ALLOWED_HOSTS", "fd.example, api.example:8443")
    assert Settings().allowed_hosts == ["fd.example", "api.example:8443"]
    monkeypatch.setenv("FINALDRIVE_ALLOWED_HOSTS", '["*"]')
    assert Settings().allowed_hosts == ["*"]


def test_any_host_with_a_star(settings: Settings) -> None:
    with TestClient(create_app(settings.model_copy(update={"allowed_hosts": ["*"]}))) as c:
        assert c.get("/v1/roads", headers={"Host": "fd.internal:9000"}).status_code == 200


@pytest.mark.parametrize("empty", ["", "  "])
def test_an_empty_token_is_refused_at_start(monkeypatch: pytest.MonkeyPatch, empty: str) -> None:
    monkeypatch.setenv("FINALDRIVE_API_TOKEN", empty)
    with pytest.raises(ValidationError, match="FINALDRIVE_API_TOKEN is empty: set a token or unset the variable"):
        Settings()


def test_serve_refuses_an_empty_token(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from finaldrive.service.cli import main as cli

    monkeypatch.setenv("FINALDRIVE_API_TOKEN", "")
    assert cli(["serve", "--db", "sqlite:///:memory:"]) == 2
    assert "FINALDRIVE_API_TOKEN is empty" in capsys.readouterr().err


def test_a_browser_gets_the_login_page(settings: Settings) -> None:
    secured = settings.model_copy(update={"api_token": SecretStr(TOKEN)})
    with TestClient(create_app(secured)) as c:
        page = c.get("/", headers={"Accept": "text/html,application/xhtml+xml"})
        assert page.status_code == 401 and page.content == login_page().body and b"needs its token" in page.content
        assert page.headers["content-type"].startswith("text/html")
        assert "'unsafe-inline'" not in page.headers["content-security-policy"].split("script-src")[1].split(";")[0]
        assert c.get("/static/login.js").status_code == 200  # its script: public, like signing in
        assert c.get("/static/api.js").status_code == 401
        api = c.get("/v1/jobs", headers={"Accept": "text/html"})  # the API answers a problem whatever is asked
        assert api.status_code == 401 and api.headers["content-type"] == "application/problem+json"
        assert c.get("/").headers["content-type"] == "application/problem+json"


def _cookie_attributes(set_cookie: str) -> set[str]:
    return {part.strip().split("=")[0].lower() for part in set_cookie.split(";")[1:]}


@pytest.mark.parametrize("token", [TOKEN, "pass; word=%41 é"])
def test_signing_in_sets_an_httponly_strict_session_cookie(settings: Settings, token: str) -> None:
    secured = settings.model_copy(update={"api_token": SecretStr(token)})
    with TestClient(create_app(secured)) as c:
        for wrong in (token + "x", token[:-1], "", "x" * 5000):
            r = c.post("/v1/session", json={"token": wrong})
            assert r.status_code in (401, 422) and "set-cookie" not in r.headers, wrong
        assert c.post("/v1/session", json={}).status_code == 422
        assert c.post("/v1/session", content=b"token=x", headers={"Content-Type": "text/plain"}).status_code == 422
        assert c.get("/v1/jobs").status_code == 401
        r = c.post("/v1/session", json={"token": token})
        assert r.status_code == 204, r.text
        cookie = r.headers["set-cookie"]
        assert cookie.startswith(f"{COOKIE}={session_value(token)};") and token not in cookie
        attributes = _cookie_attributes(cookie)
        assert {"httponly", "samesite", "path"} <= attributes and "secure" not in attributes
        assert "samesite=strict" in cookie.lower() and "path=/" in cookie.lower()
        assert c.get("/v1/jobs").status_code == 200  # the client keeps the cookie
        page = c.get("/", headers={"Accept": "text/html"})
        assert page.status_code == 200 and b"<h1>Jobs</h1>" in page.content
        assert c.post("/v1/jobs", json=SWEEP).status_code == 401  # a write without an origin
        out = c.delete("/v1/session")
        assert out.status_code == 204 and "max-age=0" in out.headers["set-cookie"].lower()
        assert c.get("/v1/jobs").status_code == 401
    with TestClient(create_app(secured), base_url="https://testserver") as c:
        r = c.post("/v1/session", json={"token": token})
        assert r.status_code == 204 and "secure" in _cookie_attributes(r.headers["set-cookie"])
    with TestClient(create_app(settings)) as c:  # no token: nothing to sign in to
        r = c.post("/v1/session", json={"token": "anything"})
        assert r.status_code == 204 and "set-cookie" not in r.headers


def test_openapi_documents_the_bearer_scheme(guarded: TestClient) -> None:
    schema = guarded.get("/openapi.json", headers=BEARER).json()
    assert schema["components"]["securitySchemes"]["HTTPBearer"]["scheme"] == "bearer"
    assert schema["security"] == [{"HTTPBearer": []}]
    assert all("401" in op["responses"] for path in schema["paths"].values() for op in path.values())


def test_a_signed_link_opens_one_recording_file_for_an_hour(settings: Settings) -> None:
    """rerun's web viewer fetches the file with no cookie nor header: a link signed with the token opens it."""
    secured = settings.model_copy(update={"api_token": SecretStr(TOKEN)})
    path = "/v1/recordings/7/recording.rrd"
    link = signed_link(secured.api_token, path)
    expires = int(link.split("expires=")[1].split("&")[0])
    assert SIGNED_LINK_S - 5 <= expires - time.time() <= SIGNED_LINK_S
    with TestClient(create_app(secured)) as c:
        assert c.get(link).status_code == 404  # past the guard: recording 7 does not exist
        forged = link[:-4] + ("0000" if not link.endswith("0000") else "1111")
        old = signed_link(secured.api_token, path, now=time.time() - SIGNED_LINK_S - 1)
        other = signed_link(secured.api_token, "/v1/recordings/8/recording.rrd").replace("/8/", "/7/")
        elsewhere = signed_link(secured.api_token, "/v1/jobs")
        for refused in (path, forged, old, other, elsewhere, link.replace("recording.rrd", "file")):
            assert c.get(refused).status_code == 401, refused
        assert c.post(link).status_code == 401
    assert signed_link(None, path) == path


@pytest.mark.parametrize(("expires", "sig"), [
    pytest.param(*case, id=name) for name, case in {
        "superscript-two": ("²", None), "arabic-digits": ("١٢٣٤٥٦٧٨٩٠", None), "5000-digits": ("9" * 5000, None),
        "13-digits": ("9" * 13, None), "negative": ("-1", None), "plus": ("+99999999999", None),
        "space": (" 99999999999", None), "empty": ("", None), "non-ascii-signature": ("99999999999", "é" * 64),
        "short-signature": ("99999999999", "0" * 63), "5000-char-signature": ("99999999999", "0" * 5000),
        "nul-signature": ("99999999999", "\0" * 64), "non-hex-signature": ("99999999999", "g" * 64),
        "no-signature": ("99999999999", ""),
    }.items()])
def test_odd_signed_link_fields_are_refused_never_a_500(settings: Settings, expires: str, sig: str | None) -> None:
    secured = settings.model_copy(update={"api_token": SecretStr(TOKEN)})
    path = "/v1/recordings/7/recording.rrd"
    with TestClient(create_app(secured)) as c:  # a 500 would raise here
        given = signature(TOKEN, path, 99999999999) if sig is None else sig
        r = c.get(path, params={"expires": expires, "signature": given})
        assert r.status_code == 401, (expires, given[:20])
        assert c.get(path, params={"expires": "99999999999",
                                   "signature": signature(TOKEN, path, 99999999999)}).status_code == 404
