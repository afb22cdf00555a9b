"""Rerun recordings: the .rrd read back (entities, frames, values), and the /v1/recordings API."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from rerun.chunk import RrdReader

from finaldrive.engine import DIAGNOSTICS, Design, Road, SimSettings, simulate
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from finaldrive.service.recording import (
    PARTS,
    PLOTS,
    frame_count,
    properties_of,
    record,
    scalars_of,
    series_settings,
)
from tests.service.processes import console_script
from tests.service.svc_helpers import ToyTask, running_scheduler, wait_done

ROAD = Road.parse("sine:0.04:3")
DURATION, FPS = 0.4, 50
DESIGNS = [("geometry 1", Design.from_deg(0.0, 0.0, 0.093)), ("geometry 2", Design.from_deg(270.0, 0.15, 0.15))]


def verify(path: Path) -> None:
    """``rerun rrd verify`` exits 0 (analytics off first, so no banner or network)."""
    exe = console_script("rerun")
    subprocess.run([exe, "analytics", "disable"], capture_output=True, check=False)
    done = subprocess.run([exe, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


@pytest.fixture(scope="module")
def rrd(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rrd") / "two.rrd"
    record(path, DESIGNS, ROAD, duration=DURATION, fps=FPS)
    return path


def test_two_geometries_every_part_every_frame(rrd: Path) -> None:
    frames = round(DURATION * FPS) + 1
    for key in ("g1", "g2"):
        for part in (*PARTS, "tyre_forces"):
            assert frame_count(rrd, f"/world/{key}/{part}") == frames, part
        for _, name, _ in PLOTS:
            assert frame_count(rrd, f"/plots/{name}/{key}") == frames, name
    reader = RrdReader(str(rrd))
    assert [r.application_id for r in reader.recordings()] == ["finaldrive"]
    assert reader.blueprints(), "the default blueprint is stored"
    static = {c.entity_path for c in reader.stream().to_chunks() if c.is_static}
    assert {"/world/g1", "/world/g2", "/world/g1/road", "/world/g2/road"} <= static
    verify(rrd)


def test_each_geometry_carries_its_outcome_and_exact_extremes(rrd: Path) -> None:
    for i, (label, design) in enumerate(DESIGNS):
        result = simulate(design, ROAD, series_settings(DURATION, FPS))
        props = properties_of(rrd, f"g{i + 1}")
        assert props["label"] == label and props["a2_deg"] == design.a2_deg and props["rws_m"] == design.rws
        for name in ("distance_m", "fitness_m", "slack_m", *DIAGNOSTICS):
            assert props[name] == pytest.approx(getattr(result, name), rel=1e-12, abs=1e-12), name
        # the extremes are the integrator's, not the 50 fps series': at least as wide as what is drawn
        assert props["chain_tension_max_n"] >= scalars_of(rrd, f"/plots/chain_tension_n/g{i + 1}")[1].max()


def test_series_equal_the_engines(rrd: Path) -> None:
    for i, (_, design) in enumerate(DESIGNS):
        series = simulate(design, ROAD, series_settings(DURATION, FPS)).series
        assert series is not None
        for key, name, _ in PLOTS:
            t, values = scalars_of(rrd, f"/plots/{name}/g{i + 1}")
            np.testing.assert_allclose(t, series["t_s"], atol=1e-9)
            np.testing.assert_allclose(values, series[key], rtol=1e-12, atol=1e-12)


def test_fps_must_divide_the_step_rate() -> None:
    with pytest.raises(ValueError, match="fps must divide"):
        series_settings(1.0, 7, SimSettings())


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    """The API and a scheduler (it produces the recordings; the jobs use the toy fitness)."""
    settings = Settings(db_url=f"sqlite:///{tmp_path / 'r.db'}", executor="serial", status_cache_seconds=0,
                        allowed_hosts=["testserver"])
    with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask()):
        yield c


def wait_recording(client: TestClient, rid: int, timeout: float = 60) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        body = client.get(f"/v1/recordings/{rid}").json()
        if body["status"] in ("succeeded", "failed"):
            return body
        time.sleep(0.05)
    raise AssertionError(body)


def test_api_records_a_jobs_best_beside_a_design(client: TestClient, tmp_path: Path) -> None:
    job = client.post("/v1/jobs", json={"kind": "sweep", "roads": ["sine:0.04:3"],
                                        "grid": "a2_deg=0:90:90,l2_m=0.05,rws_m=0.09"}).json()
    wait_done(client, job["id"])
    r = client.post("/v1/recordings", json={"job_id": job["id"], "duration": 0.2, "fps": 25,
                                            "designs": [{"a2_deg": 270, "l2_m": 0.15, "rws_m": 0.15}]})
    assert r.status_code == 202 and r.headers["Location"] == f"/v1/recordings/{r.json()['id']}"
    body = wait_recording(client, r.json()["id"])
    assert body["status"] == "succeeded", body
    labels = [f"job {job['id']} best", "a2 = 270 deg, L2 = 0.150 m, R_WS = 0.150 m"]
    assert [d["label"] for d in body["designs"]] == labels
    assert body["road"] == "sine:0.04:3" and body["frames"] == 6 and "path" not in body
    download = client.get(body["file"])
    assert download.status_code == 200
    assert download.headers["content-disposition"] == f'attachment; filename="finaldrive-recording-{body["id"]}.rrd"'
    out = tmp_path / "dl.rrd"
    out.write_bytes(download.content)
    assert frame_count(out, "/world/g2/chain") == 6
    verify(out)


def test_api_errors(client: TestClient) -> None:
    assert client.get("/v1/recordings/99").status_code == 404
    assert client.get("/v1/recordings/99/file").status_code == 404
    no_road = client.post("/v1/recordings", json={"designs": [{"a2_deg": 0, "l2_m": 0, "rws_m": 0.09}]})
    assert no_road.status_code == 422 and "road" in no_road.json()["detail"]
    bad_road = client.post("/v1/recordings",
                           json={"road": "moon", "designs": [{"a2_deg": 0, "l2_m": 0, "rws_m": 0.09}]})
    assert bad_road.status_code == 422 and bad_road.json()["detail"].startswith("body.road: unknown road")
    assert client.post("/v1/recordings", json={"job_id": 42}).status_code == 404
    too_big = client.post("/v1/recordings",
                          json={"road": "flat", "designs": [{"a2_deg": 190, "l2_m": 0.5, "rws_m": 0.5}]})
    assert too_big.status_code == 422 and "l2_max" in too_big.json()["detail"]  # refused, never a failed recording
    failing = client.post("/v1/recordings", json={"road": "bump:0.5:0.01:0", "duration": 0.2,
                                                   "designs": [{"a2_deg": 190, "l2_m": 0.05, "rws_m": 0.09}]}).json()
    body = wait_recording(client, failing["id"])  # a kerb under the tyre: no equilibrium; the service goes on
    assert body["status"] == "failed" and "static equilibrium not found" in body["error"]
    assert client.get(f"/v1/recordings/{body['id']}/file").status_code == 409


def test_scene_read_back_matches_the_engine(rrd: Path) -> None:
    from finaldrive.engine.model import coordinates as C
    from finaldrive.service.recording import scene_at

    strips, arrows = scene_at(rrd, 0.2)
    assert {f"/world/g1/{p}" for p in PARTS} <= set(strips) and len(arrows) == 2
    q = simulate(DESIGNS[0][1], ROAD, series_settings(DURATION, FPS)).series["q"][10]  # t = 0.2 s
    chain = [[q[C.X10], q[C.Y10]], [q[C.X11], q[C.Y11]]]
    np.testing.assert_allclose(strips["/world/g1/chain"][0], chain, atol=1e-6)  # stored as float32
