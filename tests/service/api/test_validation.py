"""Invalid requests get a 4xx problem document naming the field, and create nothing."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

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


def test_token_guards_mutations(settings: Settings, fake: ToyTask) -> None:
    with TestClient(create_app(settings.model_copy(update={"api_token": SecretStr("s3cret")}))) as c:
        for headers in ({}, {"Authorization": "Bearer wrong"}):
            r = c.post("/v1/jobs", json=SWEEP, headers=headers)
            assert_problem(r, 401)
            assert r.headers["www-authenticate"] == "Bearer"
        assert c.get("/v1/jobs").json()["items"] == []
        ok = c.post("/v1/jobs", json=SWEEP, headers={"Authorization": "Bearer s3cret"})
        assert ok.status_code == 201
        job_id = ok.json()["id"]
        assert_problem(c.post(f"/v1/jobs/{job_id}/cancel"), 401)
        assert c.get(f"/v1/jobs/{job_id}").json()["state"] != "cancelled"
