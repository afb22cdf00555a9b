"""GET /v1/geometry: the static quantities and the travel curve, the same as the CLI's."""

from __future__ import annotations

import math

import pytest
from fastapi.testclient import TestClient

from finaldrive.engine import Design, Road, SimSettings, default_vehicle, travel_kinematics
from finaldrive.engine.model.coordinates import PHI, THETA
from finaldrive.engine.setup import prepare
from tests.service.svc_helpers import SWEEP


def test_geometry_with_travel_is_the_engines(client: TestClient) -> None:
    r = client.get("/v1/geometry", params={"a2_deg": 0, "l2_m": 0, "rws_m": 0.093, "travel": "true", "points": 5})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["squat_ratio"] == pytest.approx(1.092, abs=0.01)      # Table 14, geometry 1
    expected = travel_kinematics(Design.from_deg(0, 0, 0.093), default_vehicle(), 5)
    assert [c["squat_ratio"] for c in body["travel_curve"]["curve"]] == pytest.approx(
        [c["squat_ratio"] for c in expected["curve"]], rel=1e-12)
    assert body["travel_curve"]["static_sag"]["sag_pct"] == pytest.approx(expected["static_sag"]["sag_pct"])


def test_geometry_without_travel_and_bad_input(client: TestClient) -> None:
    body = client.get("/v1/geometry", params={"a2_deg": 195.3, "l2_m": 0.037, "rws_m": 0.088}).json()
    assert body["travel_curve"] is None and body["res_m"] == pytest.approx(0.044)
    assert client.get("/v1/geometry", params={"a2_deg": 0, "l2_m": 0, "rws_m": 0.001}).status_code == 422
    assert client.get("/v1/geometry", params={"a2_deg": 0, "l2_m": 0, "rws_m": 0.09, "points": 1}).status_code == 422


def test_the_swingarm_at_static_sag_is_the_engines_equilibrium_of_the_jobs_vehicle(client: TestClient) -> None:
    """The swingarm angle (pivot to rear axle, chassis frame) of the static equilibrium on flat ground: the
    paper's vehicle by default, a job's own with job=ID (here a rear spring 20 mm longer: the swingarm sits
    about 7 deg lower)."""
    query = {"a2_deg": 204, "l2_m": 0.02, "rws_m": 0.088}
    design = Design.from_deg(204, 0.02, 0.088)
    paper = default_vehicle()
    longer = paper.replace(s_rs=paper["s_rs"] + 0.02)
    job = client.post("/v1/jobs", json={**SWEEP, "vehicle": longer.to_dict()}).json()["id"]
    angles = []
    for vehicle, params in ((paper, query), (longer, {**query, "job": job})):
        q0 = prepare(design, Road(), SimSettings(), vehicle).q0
        body = client.get("/v1/geometry", params={**params, "travel": "true", "points": 2}).json()
        assert body["swingarm_angle_deg"] == pytest.approx(math.degrees(q0[PHI] - q0[THETA]), abs=1e-9)
        assert body["swingarm_angle_deg"] == pytest.approx(body["travel_curve"]["static_sag"]["swingarm_angle_deg"],
                                                           abs=1e-9)
        angles.append(body["swingarm_angle_deg"])
    assert 190 < angles[0] < 191 and angles[1] - angles[0] > 5   # the paper's: 0.4 deg below its design pose (190)
    assert client.get("/v1/geometry", params={**query, "job": 999}).status_code == 404


def test_travel_png(client: TestClient) -> None:
    r = client.get("/v1/geometry/travel.png", params={"a2_deg": 0, "l2_m": 0, "rws_m": 0.093, "points": 3})
    assert r.status_code == 200 and r.content[:4] == b"\x89PNG"
