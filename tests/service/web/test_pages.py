"""The dashboard's server side without a browser: pages and their headers, the offline docs, rerun's
viewer files, and the JSON the pages draw (DE history, a recording's series)."""

from __future__ import annotations

import base64
import hashlib
import re
import tempfile
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from finaldrive.service.media.recording import properties_of, scalars_of
from finaldrive.service.web import viewer
from finaldrive.service.web.pages import STATIC, policy
from tests.service.svc_helpers import DE, wait_done

#: anything a page could load from elsewhere
FOREIGN = re.compile(r"""(?:src|href)\s*=\s*["'](?:https?:)?//""", re.I)
#: inline script in the dashboard's own HTML: a <script> without src, an on* handler, a javascript: URL
INLINE = re.compile(r"""<script(?![^>]*\ssrc=)[^>]*>|\son\w+\s*=|javascript:""", re.I)


def script_src(csp: str) -> list[str]:
    """The sources of a policy's script-src directive."""
    directives = {d.split()[0]: d.split()[1:] for d in csp.split(";") if d.strip()}
    return directives["script-src"]


@pytest.mark.parametrize("path", ["/", "/jobs/1", "/design"])
def test_pages_are_html_with_a_same_origin_policy(client: TestClient, path: str) -> None:
    r = client.get(path)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    csp = r.headers["content-security-policy"]
    assert "default-src 'self'" in csp and "connect-src 'self'" in csp
    assert script_src(csp) == ["'self'", "'wasm-unsafe-eval'"]  # no 'unsafe-inline', no 'unsafe-eval'
    assert not FOREIGN.search(r.text)


def test_the_dashboard_s_html_has_no_inline_script() -> None:
    pages = list(STATIC.glob("*.html"))
    assert len(pages) >= 4
    for path in pages:
        assert not INLINE.search(path.read_text()), path


def test_pages_made_by_others_may_run_only_their_own_inline_scripts(client: TestClient) -> None:
    """Swagger UI's page (FastAPI's) has an inline script: allowed by its hash, nothing else inline."""
    page = client.get("/docs")
    sources = script_src(page.headers["content-security-policy"])
    inline = re.findall(r"<script>(.*?)</script>", page.text, re.S)
    assert inline and sources == ["'self'", "'wasm-unsafe-eval'", *(
        f"'sha256-{base64.b64encode(hashlib.sha256(body.encode()).digest()).decode()}'" for body in inline)]
    assert script_src(client.get("/redoc").headers["content-security-policy"]) == ["'self'", "'wasm-unsafe-eval'"]
    assert "'unsafe-inline'" not in script_src(policy(b"<script>x</script><script src=a.js></script>"))


def test_every_static_file_loads_nothing_from_elsewhere() -> None:
    for path in STATIC.glob("*.*"):
        assert not FOREIGN.search(path.read_text()), path


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_api_docs_use_the_packaged_assets(client: TestClient, path: str) -> None:
    page = client.get(path)
    assert page.status_code == 200
    assets = re.findall(r"""(?:src|href)=["']([^"']+)["']""", page.text)
    assert assets and all(a.startswith("/") for a in assets), assets
    for asset in assets:
        if asset.startswith("/static/"):
            assert client.get(asset).status_code == 200, asset
    assert "fonts.googleapis" not in page.text and "cdn." not in page.text


def test_the_vendored_redoc_draws_no_logo_from_its_cdn() -> None:
    assert "cdn.redoc.ly" not in (STATIC / "vendor" / "redoc" / "redoc.standalone.js").read_text()


def test_de_history_json(client: TestClient) -> None:
    job = client.post("/v1/jobs", json=DE).json()
    done = wait_done(client, job["id"])
    history = client.get(f"/v1/jobs/{job['id']}/history")
    assert history.status_code == 200
    body = history.json()
    assert body["kind"] == "de" and [r["road"] for r in body["runs"]] == ["flat"]
    generations = body["runs"][0]["generations"]
    assert [g["generation"] for g in generations] == list(range(DE["de"]["iters"] + 1))  # type: ignore[index]
    best = [g["best_fitness_m"] for g in generations]
    assert best == sorted(best), "DE keeps its best: the best so far never falls"
    assert all(g["mean_fitness_m"] <= g["best_fitness_m"] for g in generations)
    assert best[-1] == pytest.approx(done["roads"][0]["best"]["fitness_m"])
    sweep = client.post("/v1/jobs", json={"kind": "sweep", "roads": ["flat"], "grid": "a2_deg=0,l2_m=0.05,rws_m=0.09"})
    assert client.get(f"/v1/jobs/{sweep.json()['id']}/history").status_code == 409
    assert client.get("/v1/jobs/999/history").status_code == 404


def test_recording_series_are_the_recorded_numbers(client: TestClient) -> None:
    designs = [{"a2_deg": 195.3, "l2_m": 0.037, "rws_m": 0.088, "label": "T11"},
               {"a2_deg": 270, "l2_m": 0.15, "rws_m": 0.15}]
    r = client.post("/v1/recordings", json={"road": "sine:0.04:3", "duration": 0.4, "fps": 25, "designs": designs})
    rid = r.json()["id"]
    assert client.get(f"/v1/recordings/{rid}/series").status_code == 409  # not produced yet
    deadline = time.monotonic() + 120
    while (status := client.get(f"/v1/recordings/{rid}").json()["status"]) not in ("succeeded", "failed"):
        assert time.monotonic() < deadline
        time.sleep(0.1)
    assert status == "succeeded"
    body = client.get(f"/v1/recordings/{rid}/series").json()
    assert len(body["t_s"]) == 11 and body["t_s"][0] == 0 and body["t_s"][-1] == pytest.approx(0.4)
    assert [run["label"] for run in body["runs"]] == ["T11", "a2 = 270 deg, L2 = 0.150 m, R_WS = 0.150 m"]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "r.rrd"
        path.write_bytes(client.get(f"/v1/recordings/{rid}/recording.rrd").content)
        for k, run in enumerate(body["runs"]):
            _, tension = scalars_of(path, f"/plots/chain_tension_n/g{k + 1}")
            assert run["series"]["chain_tension_n"] == pytest.approx(tension.tolist())
            assert run["outcome"]["distance_m"] == properties_of(path, f"g{k + 1}")["distance_m"]
            # the last frame is the end of the run: its distance is the outcome's
            assert run["series"]["distance_m"][-1] == pytest.approx(run["outcome"]["distance_m"], abs=1e-9)
            assert run["outcome"]["chain_tension_max_n"] >= max(run["series"]["chain_tension_n"]) - 1e-6


def test_offline_index_drops_the_font_links() -> None:
    page = ('<head><link rel="preconnect" href="https://fonts.googleapis.com" />\n<link\n  href="https://fonts.'
            'googleapis.com/css2?family=Inter" rel="stylesheet"\n/><title>x</title></head>')
    assert viewer.offline_index(page) == "<head>\n<title>x</title></head>"


@pytest.mark.slow
def test_rerun_s_viewer_is_served_from_the_installed_sdk(client: TestClient) -> None:
    index = client.get("/viewer/")
    assert index.status_code == 200 and "re_viewer.js" in index.text and "fonts.googleapis" not in index.text
    assert "connect-src 'self'" in index.headers["content-security-policy"]
    sources = script_src(index.headers["content-security-policy"])
    assert "'unsafe-inline'" not in sources and len([s for s in sources if s.startswith("'sha256-")]) >= 2
    wasm = client.get("/viewer/re_viewer_bg.wasm")
    assert wasm.status_code == 200 and wasm.headers["content-type"] == "application/wasm"
    assert wasm.content[:4] == b"\0asm"
    assert client.get("/viewer/secrets.txt").status_code == 404
    assert (viewer.cache_folder() / "index.html").exists()


def test_offline_index_leaves_the_viewer_s_handle_on_its_window() -> None:
    """The design page hands the starting viewer its recording through it (static/design.js)."""
    page = "<script>function on_wasm_loaded() {\n  let handle = new wasm_bindgen.WebHandle(options);\n}</script>"
    assert "let handle = new wasm_bindgen.WebHandle(options); window.finaldriveViewer = handle;" in (
        viewer.offline_index(page))
