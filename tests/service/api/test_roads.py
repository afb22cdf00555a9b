"""/v1/roads: measured road profiles uploaded, listed, used by jobs as profile:ID, and cached by content."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from finaldrive.engine import PROFILE_MAX_POINTS, Design, Road, SimSettings, simulate
from finaldrive.service.cli import main, remote
from finaldrive.service.client import ServiceClient
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from finaldrive.service.profiles import road_from_csv
from finaldrive.workers.evaluate import run_engine_on_roads
from tests.service.api.test_validation import assert_problem
from tests.service.svc_helpers import ToyTask, running_scheduler, wait_done

CSV = "x,y\n# a kerb at 1 m\n0,0\n1,0.01\n2,0.0\n"
GRID = "a2_deg=0:90:30,l2_m=0.1,rws_m=0.09"


class _Borrowed(ServiceClient):
    """A client over the test's TestClient, which it leaves open."""

    def close(self) -> None:
        pass


def upload_csv(client: TestClient, text: str, name: str = "kerb") -> Any:
    return client.post("/v1/roads", content=text.encode(), params={"name": name},
                       headers={"content-type": "text/csv"})


def test_upload_get_list_and_the_same_points_again(store_url: str) -> None:
    """On SQLite and PostgreSQL (the migration's table on both)."""
    with TestClient(create_app(Settings(db_url=store_url, executor="serial", allowed_hosts=["testserver"]))) as client:
        r = upload_csv(client, CSV)
        assert r.status_code == 201, r.text
        out = r.json()
        assert r.headers["location"] == f"/v1/roads/{out['id']}"
        assert out["spec"] == f"profile:{out['id']}" and out["name"] == "kerb" and out["n_points"] == 3
        assert (out["x_min_m"], out["x_max_m"], out["y_min_m"], out["y_max_m"]) == (0, 2, 0, 0.01)
        again = client.post("/v1/roads", json={"name": "same", "points": [[0, 0], [1, 0.01], [2, 0]]})
        assert again.status_code == 200 and again.json()["id"] == out["id"]  # one row per content
        assert again.json()["content_hash"] == out["content_hash"]
        other = client.post("/v1/roads", json={"points": [[0, 0], [3, 0.02]]}).json()
        detail = client.get(f"/v1/roads/{out['id']}").json()
        assert detail["points"] == [[0, 0], [1, 0.01], [2, 0]]
        page = client.get("/v1/roads/profiles", params={"limit": 1}).json()
        assert [p["id"] for p in page["items"]] == [other["id"]] and page["next_cursor"]
        rest = client.get("/v1/roads/profiles", params={"cursor": page["next_cursor"]}).json()
        assert [p["id"] for p in rest["items"]] == [out["id"]] and rest["next_cursor"] is None
        assert "points" not in rest["items"][0]
        assert len(client.get("/v1/roads").json()) == 23  # the presets are unchanged
        assert_problem(client.get("/v1/roads/999"), 404)


BAD_CSV = [
    ("x,y\n0,0\n2,0\n1,0\n", "body.line.4", "strictly increasing"),
    ("x,y\n0,0\n1,nan\n", "body.line.3", "finite"),
    ("0,0\n1,2,3\n", "body.line.2", "two columns"),
    ("0,0\n1,oops\n", "body.line.2", "must be numbers"),
    ("x,y\n0,0\n", "body", "2 to"),
]
BAD_JSON = [
    ({"points": [[0, 0], [1, 0], [1, 0]]}, "body.points.2", "strictly increasing"),
    ({"points": [[0, 0], [1, 5000]]}, "body.points.1", "within +-1000 m"),
    ({"points": [[0, 0]]}, "body.points", "at least 2"),
    ({"points": [[0, 0], ["1", 0]]}, "body.points.1.0", "valid number"),
    ({"points": [[i, 0] for i in range(PROFILE_MAX_POINTS + 1)]}, "body.points", f"at most {PROFILE_MAX_POINTS}"),
]


@pytest.mark.parametrize(("text", "where", "reason"), BAD_CSV)
def test_a_bad_csv_is_422_naming_the_line(client: TestClient, text: str, where: str, reason: str) -> None:
    body = assert_problem(upload_csv(client, text), 422)
    assert where in body["detail"] and reason in body["detail"], body
    assert client.get("/v1/roads/profiles").json()["items"] == []


@pytest.mark.parametrize(("doc", "where", "reason"), BAD_JSON)
def test_bad_points_are_422_naming_the_row(settings: Settings, doc: dict[str, Any], where: str, reason: str) -> None:
    big = settings.model_copy(update={"max_body_bytes": 10_000_000})
    with TestClient(create_app(big)) as client:
        body = assert_problem(client.post("/v1/roads", json=doc), 422)
        assert where in body["detail"] and reason in body["detail"], body
        assert client.get("/v1/roads/profiles").json()["items"] == []


def test_nan_json_and_other_media_types(client: TestClient) -> None:
    r = client.post("/v1/roads", content=b'{"points": [[0, 0], [1, NaN]]}',
                    headers={"content-type": "application/json"})
    assert "body.points.1.1" in assert_problem(r, 422)["detail"]
    assert_problem(client.post("/v1/roads", content=b"0,0\n1,0", headers={"content-type": "image/png"}), 415)
    assert_problem(client.post("/v1/roads", content=b"\xff\xfe", headers={"content-type": "text/csv"}), 400)


def test_jobs_use_profile_id_and_the_cache_knows_it_by_content(client: TestClient, fake: ToyTask) -> None:
    first = upload_csv(client, CSV).json()
    job = client.post("/v1/jobs", json={"kind": "sweep", "roads": [first["spec"]], "grid": GRID}).json()
    done = wait_done(client, job["id"])
    assert done["state"] == "succeeded" and done["roads"][0]["spec"] == first["spec"]
    assert fake.simulated == 4
    # the same points under another id are impossible (one row per content); the same design on the same
    # points in a second job comes from the cache, keyed by the points' hash
    again = wait_done(client, client.post("/v1/jobs", json={"kind": "sweep", "roads": [first["spec"]],
                                                            "grid": GRID}).json()["id"])
    assert again["cached"] == 4 and fake.simulated == 4
    moved = upload_csv(client, CSV.replace("0.01", "0.02")).json()
    moved_job = client.post("/v1/jobs", json={"kind": "sweep", "roads": [moved["spec"]], "grid": GRID}).json()
    wait_done(client, moved_job["id"])
    assert fake.simulated == 8  # other points: simulated again


@pytest.mark.parametrize(("road", "reason"), [
    ("profile:999", "no such road profile"),
    ("profile:/tmp/road.csv", "expected profile:ID"),
])
def test_a_job_naming_no_stored_profile_is_422(client: TestClient, road: str, reason: str) -> None:
    body = assert_problem(client.post("/v1/jobs", json={"kind": "sweep", "roads": [road], "grid": GRID}), 422)
    assert "roads.0" in body["detail"] and reason in body["detail"]
    assert client.get("/v1/jobs").json()["items"] == []


def test_submit_uploads_a_profile_file(client: TestClient, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "kerb.csv"
    path.write_text(CSV)
    monkeypatch.setattr(remote, "connect", lambda args: _Borrowed("http://testserver", http=client))
    assert main(["submit", "sweep", "--road", f"profile:{path}", "--road", "flat", "--grid", GRID, "--json"]) == 0
    job = json.loads(capsys.readouterr().out)
    stored = client.get("/v1/roads/profiles").json()["items"]
    assert [r["name"] for r in stored] == ["kerb.csv"]
    assert job["spec"]["roads"] == [stored[0]["spec"], "flat"]
    path.write_text("0,0\n0,1\n")
    assert main(["submit", "sweep", "--road", f"profile:{path}", "--grid", GRID]) == 2
    assert "body.line.2: x must be strictly increasing" in capsys.readouterr().err


def test_an_uploaded_profile_gives_the_distance_simulate_gives_locally(
    settings: Settings, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Acceptance: the engine through the service (a scheduler running the real task) and the CLI agree exactly."""
    path = tmp_path / "bumps.csv"
    path.write_text("x,y\n" + "".join(f"{0.25 * i:g},{0.01 * (i % 3 == 1):g}\n" for i in range(-8, 40)))
    design = ["--a2-deg", "195.3", "--l2-m", "0.037", "--rws-m", "0.088"]
    assert main(["simulate", "--road", f"profile:{path}", *design, "--duration", "1", "--json"]) == 0
    local = json.loads(capsys.readouterr().out)
    assert local["status"] == "ok"
    with TestClient(create_app(settings)) as client, running_scheduler(settings, run_engine_on_roads):
        spec = upload_csv(client, path.read_text()).json()["spec"]
        job = client.post("/v1/jobs", json={"kind": "sweep", "roads": [spec],
                                            "grid": "a2_deg=195.3,l2_m=0.037,rws_m=0.088",
                                            "settings": {"duration": 1.0}}).json()
        assert wait_done(client, job["id"], timeout=120)["state"] == "succeeded"
        [evaluation] = client.get(f"/v1/jobs/{job['id']}/evaluations").json()["items"]
    assert evaluation["distance_m"] == local["distance_m"]


@pytest.mark.parametrize("spec", ["sine:0.04:3", "sine:0.04:2"])
def test_a_sine_written_to_csv_drives_as_the_sine_within_a_tenth_of_a_millimetre(spec: str) -> None:
    """Acceptance. Sampling every 2.5 mm (800-1,200 points a wavelength) from x = -1 m (behind the rear
    tyre) to 24 m (past the front tyre's end after ~20 m): linear interpolation is then off the sine by
    at most H (2 pi / lambda)^2 h^2 / 8 < 0.3 um in height and 0.3 mrad in slope. What is left is the
    adaptive integrator choosing other steps at the profile's kinks: at the default tolerance (5e-5) that
    noise alone moves the distance by ~0.2 mm (the sine's own distance moves by 0.1 mm between tolerances
    5e-5 and 5e-6), so both runs use 5e-6 and the same method, ROS2 (the profile's; on the sine the
    default is ROS34PW2, whose distance differs from ROS2's by 0.4-0.8 mm at this tolerance: the two
    integrators' own errors, which fall slowly), where the road, not the integrator, is compared."""
    road = Road.parse(spec)
    xs = np.round(np.arange(-1.0, 24.0 + 1e-9, 0.0025), 6)
    text = "x,y\n" + "".join(f"{x!r},{float(road.height_at(x))!r}\n" for x in xs.tolist())
    assert len(text) < 1_048_576  # uploadable under the default body limit
    profile = road_from_csv(text, "sine.csv")
    design = Design.from_deg(195.3, 0.037, 0.088)
    settings = SimSettings(fast_tolerance=5e-6, fast_ros2=True)
    exact, sampled = simulate(design, road, settings), simulate(design, profile, settings)
    assert exact.status == sampled.status == "ok"
    assert abs(sampled.distance_m - exact.distance_m) < 1e-4


def test_a_recording_on_a_measured_road(client: TestClient) -> None:
    """The recording's spec carries the points: the producer needs no other table."""
    from tests.service.test_recordings import wait_recording

    spec = upload_csv(client, CSV).json()["spec"]
    r = client.post("/v1/recordings", json={"road": spec, "duration": 0.1, "fps": 10,
                                             "designs": [{"a2_deg": 195.3, "l2_m": 0.037, "rws_m": 0.088}]})
    assert r.status_code == 202, r.text
    assert wait_recording(client, r.json()["id"])["status"] == "succeeded"
    bad = client.post("/v1/recordings",
                      json={"road": "profile:999", "designs": [{"a2_deg": 0, "l2_m": 0, "rws_m": 0.09}]})
    assert "body.road" in assert_problem(bad, 422)["detail"]
