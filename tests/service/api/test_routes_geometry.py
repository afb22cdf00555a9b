"""GET /v1/geometry: the static quantities and the travel curve, the same as the CLI's."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from finaldrive.engine import Design, default_vehicle, travel_kinematics


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


def test_travel_png(client: TestClient) -> None:
    r = client.get("/v1/geometry/travel.png", params={"a2_deg": 0, "l2_m": 0, "rws_m": 0.093, "points": 3})
    assert r.status_code == 200 and r.content[:4] == b"\x89PNG"
