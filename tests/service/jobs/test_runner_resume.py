"""Stopping the service mid-job and starting it again (in-process, fake evaluation stream)."""

from __future__ import annotations

import sqlite3
import time
from typing import Any

from fastapi.testclient import TestClient

from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.svc_helpers import DE, SWEEP, FakeStream, wait_done


def run_until(settings: Settings, spec: dict[str, Any], stored: int) -> tuple[int, int]:
    """Submit ``spec``, stop the service once ``stored`` evaluations are in.

    Returns the job id and the number of evaluations stored when the service stopped."""
    with TestClient(create_app(settings, stream=FakeStream(batch_size=2, delay=0.01))) as c:
        job_id = c.post("/v1/jobs", json=spec).json()["id"]
        while (job := c.get(f"/v1/jobs/{job_id}").json())["done"] < stored:
            time.sleep(0.01)
        assert job["state"] == "running"
    with sqlite3.connect(settings.db_url.removeprefix("sqlite:///")) as db:
        state, done = db.execute("SELECT state, n_done FROM jobs WHERE id = ?", (job_id,)).fetchone()
    assert state == "interrupted"
    return int(job_id), int(done)


def test_sweep_resumes_with_only_what_is_missing(settings: Settings) -> None:
    job_id, stored = run_until(settings, SWEEP, stored=6)
    fake = FakeStream()
    with TestClient(create_app(settings, stream=fake)) as c:
        assert c.get(f"/v1/jobs/{job_id}").json()["state"] in ("interrupted", "running")
        job = wait_done(c, job_id)
        items = c.get(f"/v1/jobs/{job_id}/evaluations").json()["items"]
    assert job["state"] == "succeeded" and job["done"] == 24
    assert fake.simulated == 24 - stored < 24 - 6 + 1
    assert len({(e["road_index"], e["candidate"]) for e in items}) == len(items) == 24


def test_de_resumes_from_its_last_generation(settings: Settings, tmp_path: Any) -> None:
    spec = {**DE, "de": {"np": 6, "iters": 8}}
    reference_settings = settings.model_copy(update={"db_url": f"sqlite:///{tmp_path / 'ref.db'}"})
    with TestClient(create_app(reference_settings, stream=FakeStream())) as c:
        reference = wait_done(c, c.post("/v1/jobs", json=spec).json()["id"])
        ref_items = c.get(f"/v1/jobs/{reference['id']}/evaluations").json()["items"]

    job_id, _ = run_until(settings, spec, stored=20)
    with TestClient(create_app(settings, stream=FakeStream())) as c:
        job = wait_done(c, job_id)
        items = c.get(f"/v1/jobs/{job_id}/evaluations").json()["items"]
    assert job["state"] == "succeeded"
    assert job["roads"][0]["best"]["fitness_m"] == reference["roads"][0]["best"]["fitness_m"]

    def slots(rows: list[dict[str, Any]]) -> list[tuple[int, int, float, float, float]]:
        return sorted((e["step"], e["candidate"], e["a2"], e["l2"], e["rws"]) for e in rows)

    assert slots(items) == slots(ref_items)


def test_failed_simulation_is_stored_and_the_sweep_succeeds(client: TestClient, fake: FakeStream) -> None:
    fake.fail_above_l2 = 0.12
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    assert job["state"] == "succeeded" and (job["done"], job["failed"]) == (16, 8)
    failed = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"limit": 100}).json()["items"]
    failed = [e for e in failed if e["status"] == "failed"]
    assert {(e["l2"], e["reason"], e["fitness_m"]) for e in failed} == {(0.15, "fake divergence", None)}
    assert all(road["best"]["status"] == "ok" for road in job["roads"])
