"""Schemathesis over the OpenAPI schema, in-process: no server error, no undocumented status."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import schemathesis
from fastapi import FastAPI
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from pydantic import SecretStr
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

from finaldrive.engine import Design, default_vehicle, static_geometry
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.svc_helpers import ToyTask, running_scheduler

pytestmark = pytest.mark.slow  # starts servers or subprocesses

CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]


@pytest.fixture(scope="module")
def app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FastAPI]:
    db = Path(tmp_path_factory.mktemp("fuzz")) / "fuzz.db"
    config = Settings(db_url=f"sqlite:///{db}", executor="serial", max_job_evaluations=500, events_poll_seconds=0.01,
                      api_token=SecretStr("fuzz-token"), allowed_hosts=["testserver", "localhost"])
    application = create_app(config)
    # /v1/geometry runs the engine in the request: load (or compile) the model before the 10 s read timeouts
    static_geometry(Design.from_deg(0.0, 0.0, 0.093), default_vehicle())
    # runs the lifespan (schemathesis calls the started app); a scheduler keeps /v1/health at 200
    with TestClient(application), running_scheduler(config, ToyTask()):
        yield application


@pytest.fixture(scope="module")
def api_schema(app: FastAPI) -> schemathesis.BaseSchema:
    return schemathesis.openapi.from_asgi("/openapi.json", app, headers={"Authorization": "Bearer fuzz-token"})


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck))
def test_api_conforms_to_its_schema(case: schemathesis.Case) -> None:
    case.call_and_validate(headers={"Authorization": "Bearer fuzz-token"}, checks=CHECKS)


@schema.include(method="POST").parametrize()
@settings(max_examples=5, deadline=None, suppress_health_check=list(HealthCheck))
def test_mutations_without_token_conform(case: schemathesis.Case) -> None:
    case.call_and_validate(checks=CHECKS)
