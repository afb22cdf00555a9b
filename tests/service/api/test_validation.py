"""Invalid requests get a 4xx problem document naming the field, and create nothing."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from finaldrive.engine import default_vehicle
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.svc_helpers import DE, SWEEP, ToyTask

BAD_SPECS = [
    ({**SWEEP, "roads": ["moon-road"]}, "roads.0", "unknown road 'moon-road'"),
    ({**DE, "bounds": {"l2_m": [0.2, 0.1]}}, "bounds", "lower bound 0.2 is above upper bound 0.1"),
    ({**DE, "de": {"np": 3}}, "de.np", "greater than or equal to 4"),
    ({**SWEEP, "settings": {"duration": -1}}, "settings.duration", "greater than 0"),
    ({**SWEEP, "grid": "l2_m=0:oops"}, "grid", ""),
    ({**SWEEP, "vehicle": {"parameters": {}}}, "vehicle", "missing"),
    ({**SWEEP, "bounds": {}}, "body", "bounds: not allowed for a sweep"),
    ({**SWEEP, "kind": "grid-search"}, "kind", ""),
    ({**SWEEP, "colour": "red"}, "colour", "Extra inputs are not permitted"),
    ({**DE, "de": {"np": 10, "max_evals": 5}}, "de", "max_evals: must be >= np (10), got 5"),
]


def assert_problem(r: Any, status: int) -> dict[str, Any]:
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert body["status"] == status and body["detail"]
    return body


@pytest.mark.parametrize(("spec", "field", "reason"), BAD_SPECS)
def test_bad_spec_is_422_naming_the_field(client: TestClient, spec: dict[str, Any], field: str, reason: str) -> None:
    body = assert_problem(client.post("/v1/jobs", json=spec), 422)
    assert field in body["detail"] and reason in body["detail"]
    assert client.get("/v1/jobs").json()["items"] == []


def test_body_over_the_limit_is_413(client: TestClient) -> None:
    huge = b'{"kind": "sweep", "roads": ["' + b"x" * 10_000_000 + b'"]}'
    assert_problem(client.post("/v1/jobs", content=huge, headers={"content-type": "application/json"}), 413)

    def chunks() -> Iterator[bytes]:  # no Content-Length: counted while reading
        yield huge[:5_000_000]
        yield huge[5_000_000:]

    assert_problem(client.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"}), 413)
    assert client.get("/v1/jobs").json()["items"] == []


def test_job_over_the_size_limit(settings: Settings, fake: ToyTask) -> None:
    with TestClient(create_app(settings.model_copy(update={"max_job_evaluations": 100}))) as c:
        body = assert_problem(c.post("/v1/jobs", json={**DE, "de": {"np": 10, "iters": 10}}), 422)
        assert "110 evaluations" in body["detail"] and "limit of 100" in body["detail"]
        assert c.get("/v1/jobs").json()["items"] == []


def test_unknown_job_and_bad_cursor(client: TestClient) -> None:
    for path in ("/v1/jobs/5", "/v1/jobs/5/evaluations", "/v1/jobs/5/best", "/v1/jobs/5/events"):
        assert_problem(client.get(path), 404)
    assert_problem(client.get("/v1/jobs", params={"cursor": "zz"}), 422)


def _vehicle(key: str, value: Any) -> dict[str, Any]:
    from finaldrive.engine import default_vehicle

    d = default_vehicle().to_dict()
    next(group for group in d["parameters"].values() if key in group)[key]["value"] = value
    return d


def _nested(depth: int) -> str:
    return '{"a": ' * depth + "1" + "}" * depth


#: What gave a 500, or was accepted though meaningless (issue 14, item 5): each a 422 naming the field and limit.
LIMITS = [
    ({**SWEEP, "vehicle": _vehicle("L3", 10**400)}, "vehicle.parameters.geometry.L3.value", "<= 1e+10"),
    ({**SWEEP, "vehicle": _vehicle("m_chassis", 1e300)}, "vehicle.parameters.inertia.m_chassis.value", "10000000000"),
    ({**SWEEP, "vehicle": _vehicle("l2_max", 1e-12)}, "vehicle", "'l2_max': must be >= 1e-09"),
    ({**SWEEP, "vehicle": _vehicle("rws_tyre_margin", 0.3)}, "vehicle", "'rws_tyre_margin': must be less than"),
    ({**DE, "bounds": {"rws_m": [0.05, 1e308]}}, "bounds.rws_m", "more than the vehicle's limit of 0.2 m"),
    ({**DE, "bounds": {"l2_m": [0, 5]}}, "bounds.l2_m", "more than the vehicle's limit of 0.2 m (l2_max)"),
    ({**DE, "vehicle": _vehicle("l2_max", 0.1)}, "bounds.l2_m", "upper bound 0.2 m is more than the vehicle's limit"),
    ({**SWEEP, "grid": "a2_deg=0,l2_m=5,rws_m=0.09"}, "grid", "l2_m = 5 m, more than the vehicle's limit of 0.2 m"),
    ({**SWEEP, "grid": "a2_deg=0,l2_m=0.1,rws_m=0.5"}, "grid", "rws_m = 0.5 m, more than the vehicle's limit of 0.2 m"),
    ({**SWEEP, "roads": ["sine:1e308:1e-308"]}, "roads.0", "within +-0.5 m"),
    ({**SWEEP, "roads": ["sine:0.01:1e-308"]}, "roads.0", "wavelength LAMBDA must be in [0.05, 10000] m"),
    ({**SWEEP, "roads": ["bump:0.01:1e-9"]}, "roads.0", "width SIGMA must be in [0.01, 10000] m"),
    ({**DE, "de": {"np": "10"}}, "de.np", "valid integer"),
    ({**DE, "de": {"np": 10.0}}, "de.np", "valid integer"),
    ({**DE, "de": {"f": "0.5"}}, "de.f", "valid number"),
    ({**SWEEP, "seed": True}, "seed", "valid integer"),
    ({**SWEEP, "settings": {"duration": "3"}}, "settings.duration", "valid number"),
    ({**SWEEP, "settings": {"dt": 1e-300}}, "settings.dt", "greater than or equal to 0.000001"),
]


@pytest.mark.parametrize(("spec", "field", "reason"), LIMITS)
def test_each_limit_is_422_naming_the_field_and_the_limit(
    client: TestClient, spec: dict[str, Any], field: str, reason: str
) -> None:
    r = client.post("/v1/jobs", content=json.dumps(spec), headers={"content-type": "application/json"})
    body = assert_problem(r, 422)
    assert field in body["detail"] and reason in body["detail"], body["detail"]
    assert client.get("/v1/jobs").json()["items"] == []


def test_infinite_bounds_deep_vehicles_and_odd_cursors_are_422(client: TestClient) -> None:
    raw = {"content-type": "application/json"}
    body = assert_problem(client.post("/v1/jobs", headers=raw, content=(
        '{"kind": "de", "roads": ["flat"], "bounds": {"l2_m": [0, Infinity]}}')), 422)
    assert "bounds.l2_m.1" in body["detail"] and "finite number" in body["detail"]
    for depth in (900, 5000):
        deep = f'{{"kind": "sweep", "roads": ["flat"], "vehicle": {_nested(depth)}}}'
        r = client.post("/v1/jobs", headers=raw, content=deep)
        assert r.status_code in (400, 422), (depth, r.status_code)
        assert r.headers["content-type"] == "application/problem+json"
    job = client.post("/v1/jobs", json=SWEEP).json()
    for path in ("/v1/jobs", f"/v1/jobs/{job['id']}/evaluations", "/v1/roads/profiles"):
        body = assert_problem(client.get(path + "?cursor=%C2%B2"), 422)
        assert "query.cursor" in body["detail"]
    assert [j["id"] for j in client.get("/v1/jobs").json()["items"]] == [job["id"]]


def test_recorded_designs_are_held_to_the_vehicle(client: TestClient) -> None:
    body = assert_problem(client.post("/v1/recordings", json={
        "road": "flat",
        "designs": [{"a2_deg": 0, "l2_m": 0.1, "rws_m": 0.09}, {"a2_deg": 0, "l2_m": 0.1, "rws_m": 0.25}]}),
        422)
    assert "designs.1" in body["detail"] and "rws = 0.25 m: must be <= 0.2 m" in body["detail"]


def test_a_vehicle_the_method_cannot_simulate_is_422(client: TestClient) -> None:
    vehicle = default_vehicle().replace(chain_runs=2).to_dict()
    body = assert_problem(client.post("/v1/jobs", json={
        **SWEEP, "vehicle": vehicle, "settings": {"method": "reference"}}), 422)
    assert "settings.method" in body["detail"] and "chain_runs = 2" in body["detail"], body["detail"]
    assert client.post("/v1/jobs", json={**SWEEP, "vehicle": vehicle}).status_code == 201  # the fast method can
