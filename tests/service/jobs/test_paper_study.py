"""The paper-study job kind: planning (104,190 evaluations), one job through the API, resume."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import ValidationError

from finaldrive.engine import PAPER_SWEEP_STEP as SWEEP_STEP
from finaldrive.service.cli import main
from finaldrive.service.config import Settings
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.main import create_app
from finaldrive.service.schemas import JobSpec
from tests.service.svc_helpers import ToyTask, running_scheduler, wait_done

TINY = {"kind": "paper-study", "roads": ["flat", "sine:0.04:3"], "grid": "a2_deg=0:300:60,l2_m=0.05|0.15",
        "de": {"np": 4, "iters": 3}, "seed": 1}
TINY_TOTAL = 2 * 12 + 2 * 4 * 4


def test_the_paper_study_plans_104190_evaluations() -> None:
    spec = JobSpec(kind="paper-study", roads=["paper"]).normalised()
    plan = build_plan(spec)
    assert (len(plan.study.roads), plan.study.n_de_runs) == (23, 23)
    assert (plan.study.sweep_total(), plan.study.de_total(), plan.total()) == (45_540, 23 * 2_550, 104_190)
    assert spec.grid == "table9" and spec.de is not None and spec.de.np == 50 and spec.de.iters == 50
    assert spec.settings.method == "fast"  # the engine's default, as for every kind
    assert (
        JobSpec(kind="paper-study", roads=["flat"], settings={"method": "reference"}).normalised().settings.method
        == "reference"
    )
    # a stored spec normalises to itself (the Idempotency-Key hash is stable)
    assert JobSpec.model_validate(spec.model_dump(mode="json")).normalised() == spec


def test_paper_study_rejects_an_aggregate() -> None:
    with pytest.raises(ValidationError, match="aggregate"):
        JobSpec(kind="paper-study", roads=["flat"], aggregate="mean")
    with pytest.raises(ValidationError, match="grid"):
        JobSpec(kind="de", roads=["flat"], grid="table9")


def _slots(items: list[dict[str, Any]]) -> list[tuple[int, int, int, float, float, float]]:
    return sorted((e["road_index"], e["step"], e["candidate"], e["a2_deg"], e["l2_m"], e["rws_m"]) for e in items)


def test_one_job_with_one_progress_view(client: TestClient) -> None:
    created = client.post("/v1/jobs", json=TINY).json()
    assert (created["kind"], created["total"]) == ("paper-study", TINY_TOTAL)
    job = wait_done(client, created["id"])
    items = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"limit": 1000}).json()["items"]
    assert job["state"] == "succeeded" and job["done"] == job["total"] == len(items) == TINY_TOTAL
    steps = {(e["road_index"], e["step"]) for e in items}
    assert {s for _, s in steps} == {SWEEP_STEP, 0, 1, 2, 3}
    assert sum(e["step"] == SWEEP_STEP for e in items) == 24
    assert len(set(_slots(items))) == len(items)


def test_a_paper_study_resumes_in_both_parts(settings: Settings, tmp_path: Path) -> None:
    ref = settings.model_copy(update={"db_url": f"sqlite:///{tmp_path / 'ref.db'}"})
    with TestClient(create_app(ref)) as c, running_scheduler(ref, ToyTask()):
        reference = _slots(c.get(f"/v1/jobs/{wait_done(c, c.post('/v1/jobs', json=TINY).json()['id'])['id']}"
                                 "/evaluations", params={"limit": 1000}).json()["items"])
    job_id = 0
    for stop_at in (10, 30):  # the sweep and the DEs run together: stopped twice mid-way
        with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask(delay=0.01)):
            job_id = c.post("/v1/jobs", json=TINY, headers={"Idempotency-Key": "tiny"}).json()["id"]
            while c.get(f"/v1/jobs/{job_id}").json()["done"] < stop_at:
                time.sleep(0.01)
        with sqlite3.connect(settings.db_url.removeprefix("sqlite:///")) as db:
            state, done = db.execute("SELECT state, n_done FROM jobs WHERE id = ?", (job_id,)).fetchone()
        assert state == "interrupted" and stop_at <= done < TINY_TOTAL
    fake = ToyTask()
    with TestClient(create_app(settings)) as c, running_scheduler(settings, fake):
        job = wait_done(c, job_id)
        items = c.get(f"/v1/jobs/{job_id}/evaluations", params={"limit": 1000}).json()["items"]
    assert job["state"] == "succeeded" and job["done"] == TINY_TOTAL
    assert fake.simulated == TINY_TOTAL - done
    assert _slots(items) == reference


def test_study_paper_local_runs_and_resumes_the_same_job(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["study", "paper", "--local", "--db", f"sqlite:///{tmp_path / 'cli.db'}", "--executor", "serial",
            "--roads", "flat", "--grid", "a2_deg=0:180:90,l2_m=0.1", "--np", "4", "--iters", "1",
            "--duration", "0.2", "--interval", "0.1"]
    assert main(args) == 0
    first = capsys.readouterr().out
    assert "job 1 (submitted)" in first and "job 1 succeeded: 11 ok" in first
    assert main(args) == 0
    assert "job 1 (existing)" in capsys.readouterr().out
