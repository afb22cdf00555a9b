"""What one client may make the service keep: unfinished jobs and pending recordings are capped (429
naming the setting), stored road profiles too (507); an Idempotency-Key replays its job only for a while;
/v1/health says at once when a scheduler's results cannot be stored."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from finaldrive.service.config import Settings
from finaldrive.service.db.leases import register_scheduler, report_store_error
from finaldrive.service.main import create_app
from finaldrive.service.services import open_database
from tests.service.svc_helpers import SWEEP

RECORDING = {"road": "flat", "duration": 0.2, "designs": [{"a2_deg": 270, "l2_m": 0.15, "rws_m": 0.15}]}


@pytest.fixture
def capped(tmp_path: Path) -> Iterator[TestClient]:
    """The API alone (no scheduler: what is submitted stays queued), with small caps."""
    settings = Settings(db_url=f"sqlite:///{tmp_path / 'fd.db'}", executor="serial", allowed_hosts=["testserver"],
                        max_active_jobs=2, max_pending_recordings=1, max_profiles=1, idempotency_key_hours=0.0003)
    with TestClient(create_app(settings)) as client:
        yield client


def _limited(response: httpx.Response, setting: str) -> None:
    assert response.status_code == 429
    body = response.json()
    assert body["type"] == "urn:finaldrive:problem:limit-reached" and setting in body["detail"]
    assert response.headers["Retry-After"] == "30"


def test_unfinished_jobs_are_capped_and_a_cancel_makes_room(capped: TestClient) -> None:
    ids = [capped.post("/v1/jobs", json={**SWEEP, "seed": s}).json()["id"] for s in (1, 2)]
    _limited(capped.post("/v1/jobs", json={**SWEEP, "seed": 3}), "FINALDRIVE_MAX_ACTIVE_JOBS")
    assert capped.post(f"/v1/jobs/{ids[0]}/cancel").status_code == 200
    assert capped.post("/v1/jobs", json={**SWEEP, "seed": 3}).status_code == 201


def test_pending_recordings_and_stored_profiles_are_capped(capped: TestClient) -> None:
    assert capped.post("/v1/recordings", json=RECORDING).status_code == 202
    _limited(capped.post("/v1/recordings", json=RECORDING), "FINALDRIVE_MAX_PENDING_RECORDINGS")
    first = {"name": "one", "points": [[0, 0], [1, 0.01], [2, 0]]}
    assert capped.post("/v1/roads", json=first).status_code == 201
    assert capped.post("/v1/roads", json=first).status_code == 200  # the same points: no new profile
    full = capped.post("/v1/roads", json={"name": "two", "points": [[0, 0], [1, 0.02], [2, 0]]})
    assert full.status_code == 507 and "Retry-After" not in full.headers  # profiles are kept: no waiting helps
    assert "FINALDRIVE_MAX_PROFILES" in full.json()["detail"]


def test_an_idempotency_key_expires(capped: TestClient) -> None:
    headers = {"Idempotency-Key": "k-1"}
    first = capped.post("/v1/jobs", json=SWEEP, headers=headers)
    assert capped.post("/v1/jobs", json=SWEEP, headers=headers).json()["id"] == first.json()["id"]
    time.sleep(1.2)  # past 0.0003 h
    again = capped.post("/v1/jobs", json=SWEEP, headers=headers)
    assert again.status_code == 201 and again.json()["id"] != first.json()["id"]


def test_health_is_503_at_once_when_a_live_schedulers_results_cannot_be_stored(tmp_path: Path) -> None:
    settings = Settings(db_url=f"sqlite:///{tmp_path / 'fd.db'}", executor="serial", allowed_hosts=["testserver"])
    with TestClient(create_app(settings)) as client:
        db = open_database(settings)
        try:
            with db.write() as session:
                register_scheduler(session, "s1", host="h", pid=1, executor="serial", capacity=1)
            assert client.get("/v1/health").status_code == 200
            with db.write() as session:
                report_store_error(session, "s1", "database or disk is full")
            sick = client.get("/v1/health")
            with db.write() as session:  # the same scheduler restarted: its writer has yet to say
                register_scheduler(session, "s1", host="h", pid=2, executor="serial", capacity=1)
            assert client.get("/v1/health").status_code == 200
        finally:
            db.dispose()
    assert sick.status_code == 503 and sick.json()["store"]["writable"] is False
    assert sick.json()["schedulers"][0]["store_error"] == "database or disk is full"
