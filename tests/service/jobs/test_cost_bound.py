"""The CPU limit bounds a job's cost: the estimate is above what simulations measure on the
roughest roads, a job estimated over the limit is refused, and a running job is stopped at its
budget of measured time (real engine, serial executor, SQLite file)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

from finaldrive.engine import Design, Road, SimSettings, default_vehicle, estimate_cost, simulate
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import Evaluation, Job
from finaldrive.service.jobs.budget import spent_s
from finaldrive.service.jobs.scheduler import SchedulerConfig
from finaldrive.service.main import create_app
from finaldrive.service.services import open_database
from finaldrive.workers.evaluate import run_engine_on_roads
from tests.service.svc_helpers import running_scheduler

#: 1.8 CPU-s: a few 60 s simulations on the 1 mm x 5 cm road (~0.6 s each on the reference machine)
SMALL_BUDGET_H = 0.0005
ROUGH = "sine:0.001:0.05"
ROUGH_SWEEP = {"kind": "sweep", "roads": [ROUGH], "grid": "a2_deg=0:330:30,l2_m=0.1,rws_m=0.09",
               "settings": {"duration": 60}}


def _noisy_profile(points: int, length_m: float, rms_m: float, seed: int) -> Road:
    """A measured-like profile: flat for its first 3 m, then noise of ``rms_m`` at every point."""
    xs = np.linspace(-2.0, length_m, points)
    ys = np.where(xs < 3.0, 0.0, np.random.default_rng(seed).normal(0.0, rms_m, points))
    return Road.from_points(xs, ys, name="noise")


@pytest.mark.parametrize(("road", "duration"), [
    (Road(), 3.5),
    (Road.parse(ROUGH), 10.0),
    (_noisy_profile(100_000, 100.0, 5e-3, 1), 3.5),
])
def test_the_estimate_is_above_the_measured_cpu_time_of_each_simulation(road: Road, duration: float) -> None:
    settings = SimSettings(duration=duration, max_wall_s=None)
    simulate(Design(0.5, 0.1, 0.1), Road(), settings.with_(duration=0.05))  # compiled (or loaded) first
    estimate = estimate_cost(settings, 1, [road]).cpu_s
    rng = np.random.default_rng(5)
    for _ in range(3):
        design = Design(float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(0, 0.2)), float(rng.uniform(0.05, 0.15)))
        began = time.process_time()
        simulate(design, road, settings)
        assert time.process_time() - began <= estimate


@pytest.mark.parametrize(("road", "duration"), [(Road(), 3.5), (Road.parse(ROUGH), 10.0)])
def test_the_estimate_is_above_the_measured_cpu_time_with_the_elastic_chain(road: Road, duration: float) -> None:
    """The elastic chain's own state (docs/engine.md#the-elastic-chain-and-cush-drive) is priced too."""
    vehicle = default_vehicle().replace(chain_compliance=1.0)
    settings = SimSettings(duration=duration, max_wall_s=None)
    simulate(Design(0.5, 0.1, 0.1), Road(), settings.with_(duration=0.05), vehicle)  # compiled (or loaded) first
    estimate = estimate_cost(settings, 1, [road], vehicle).cpu_s
    rng = np.random.default_rng(6)
    for _ in range(3):
        design = Design(float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(0, 0.2)), float(rng.uniform(0.05, 0.15)))
        began = time.process_time()
        simulate(design, road, settings, vehicle)
        assert time.process_time() - began <= estimate


def test_the_estimate_prices_the_costliest_road_and_the_vehicles_reach() -> None:
    settings = SimSettings(duration=60.0)
    flat = estimate_cost(settings, 1000, [Road()])
    rough = estimate_cost(settings, 1000, [Road(), Road.parse(ROUGH)])
    assert rough.cpu_s > 50 * flat.cpu_s
    profile = _noisy_profile(100_000, 10_000.0, 1e-3, 2)
    near = estimate_cost(SimSettings(duration=3.5), 1, [profile])  # ~35 m reached: ~350 of its points
    far = estimate_cost(settings, 1, [profile])                     # ~8 km: 80% of them
    assert far.steps > 100 * near.steps


def test_a_job_estimated_over_the_limit_is_refused(settings: Settings) -> None:
    tight = settings.model_copy(update={"max_job_cpu_hours": SMALL_BUDGET_H})
    with TestClient(create_app(tight)) as c:
        response = c.post("/v1/jobs", json=ROUGH_SWEEP)
        assert response.status_code == 422, response.text
        assert "FINALDRIVE_MAX_JOB_CPU_HOURS" in response.text and "costliest road" in response.text
        small = {**ROUGH_SWEEP, "roads": ["flat"], "grid": "a2_deg=0,l2_m=0.1,rws_m=0.09",
                 "settings": {"duration": 1}}
        assert c.post("/v1/jobs", json=small).status_code == 201


def test_a_running_job_is_stopped_at_its_budget_keeping_what_was_stored(settings: Settings) -> None:
    with TestClient(create_app(settings)) as c:  # the API's limit (100 CPU-h) accepts the job
        response = c.post("/v1/jobs", json=ROUGH_SWEEP)
        assert response.status_code == 201, response.text
        job_id = response.json()["id"]
        config = SchedulerConfig(lease_s=30.0, heartbeat_s=0.05, flush_s=0.02, batch_size=1, recordings=False,
                                 max_job_cpu_s=SMALL_BUDGET_H * 3600)
    db = open_database(settings)
    with running_scheduler(settings, run_engine_on_roads, config=config):
        deadline = time.monotonic() + 120
        while (job := _job(db, job_id)).state in ("queued", "running"):
            assert time.monotonic() < deadline, "the job did not stop"
            time.sleep(0.05)
    with db.read() as session:
        stored = session.scalar(select(func.count()).select_from(Evaluation).where(Evaluation.job_id == job_id)) or 0
        spent = spent_s(session, job_id)
    db.dispose()
    assert job.state == "failed"
    assert "stopped at its CPU budget of 0.0005 CPU-hours (FINALDRIVE_MAX_JOB_CPU_HOURS)" in (job.error or "")
    assert 0 < stored < 12 and stored == job.n_done + job.n_failed, (stored, job.n_done, job.n_failed, spent)
    one = spent / stored
    assert SMALL_BUDGET_H * 3600 < spent <= SMALL_BUDGET_H * 3600 + 1.5 * one  # past it by one simulation at most


def _job(db: Database, job_id: int) -> Job:
    with db.read() as session:
        job = session.get(Job, job_id)
        assert job is not None
        session.expunge(job)
        return job
