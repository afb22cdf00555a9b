"""/best?model_band=true (service.api.model_bands): a finished job's best designs under each modelling
alternative, simulated by the scheduler as designs jobs with the alternative's vehicle or road.

The scheduler's task here is the toy fitness plus a term in the drive torque that reorders the designs
by L2, so the drive alternatives change the ranking and the others (which leave the torque and the
road's height alone) do not; what the API reports is checked against that formula."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy.stats import spearmanr
from sqlalchemy import update

from finaldrive.engine import ALTERNATIVES, BatchResult, Road, SimSettings, Vehicle, default_vehicle
from finaldrive.service.config import Settings
from finaldrive.service.db.models import Job
from finaldrive.service.services import open_database
from finaldrive.workers.evaluate import by_road
from tests.service.svc_helpers import SWEEP, ToyTask, best_when_done, toy_batch, wait_done

PAPER_TORQUE = default_vehicle()["torque"]
#: m of fitness a m of L2 per unit of relative torque change
SLOPE = 50.0


def toy_fitness(a2_rad: float, l2_m: float, rws_m: float, height_m: float, torque: float) -> float:
    base = 20 - (a2_rad - 1) ** 2 - 10 * (l2_m - 0.1) ** 2 - 100 * (rws_m - 0.09) ** 2 - height_m
    return base + SLOPE * (torque / PAPER_TORQUE - 1.0) * l2_m


class DriveToy(ToyTask):
    """The toy fitness with the drive torque's term (engine.vehicle's torque; the paper's when no vehicle)."""

    def __call__(self, rows: np.ndarray, roads: tuple[Road, ...], settings: SimSettings,
                 vehicle: Vehicle | None) -> list[tuple[int, BatchResult]]:
        torque = (vehicle or default_vehicle())["torque"]
        out = []
        for road, x in by_road(rows):
            batch = toy_batch(x, roads[road])
            shift = SLOPE * (torque / PAPER_TORQUE - 1.0) * x[:, 1]
            out.append((road, BatchResult.of(x, batch.status, batch.reason, distance_m=batch.fitness_m + shift + 0.5,
                                             squat_ratio=0.9, slack_m=0.001, fitness_m=batch.fitness_m + shift,
                                             chain_length_m=1.2, wall_s=0.01)))
        return out


@pytest.fixture
def fake() -> ToyTask:
    return DriveToy()


def test_model_bands_are_simulated_by_the_scheduler_with_each_alternatives_model(client: TestClient) -> None:
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    first = client.get(url, params={"model_band": "true"})
    assert first.status_code in (200, 202)
    jobs = first.json()["model_band_jobs"]
    expected = {a.name for a in ALTERNATIVES} - {"road_enveloped"}
    assert set(jobs) == expected
    assert client.get(url, params={"model_band": "true"}).json()["model_band_jobs"] == jobs   # queued once
    specs = {name: client.get(f"/v1/jobs/{i}").json()["spec"] for name, i in jobs.items()}
    torque = {name: next(group["torque"]["value"] for group in spec["vehicle"]["parameters"].values()
                         if "torque" in group) for name, spec in specs.items()}
    assert torque["drive_double"] == pytest.approx(2 * PAPER_TORQUE) and torque["drive_half"] == pytest.approx(
        PAPER_TORQUE / 2) and torque["front_wheel_spin"] == pytest.approx(PAPER_TORQUE)
    assert specs["road_phase_90"]["roads"] == ["sine:0.025:3:90"]          # a sine road only
    assert specs["drive_double"]["roads"] == SWEEP["roads"]
    for road, sharp in zip(SWEEP["roads"], best_when_done(client, url, "model_band", jobs)["sharpness"], strict=True):
        bands = sharp["model_bands"]
        designs = [(np.radians(d["a2_deg"]), d["l2_m"], d["rws_m"]) for d in bands["designs"]]
        height = Road.parse(road).height
        base = [toy_fitness(*d, height, PAPER_TORQUE) for d in designs]
        assert bands["baseline"]["fitness_m"] == pytest.approx(base, abs=1e-12)
        assert "road_enveloped" in bands["skipped"] and "computed" in bands["skipped_reasons"]["road_enveloped"]
        if road == "flat":
            assert {"road_phase_90", "road_phase_180"} <= set(bands["skipped"])
        for name, alt in bands["alternatives"].items():
            factor = {"drive_double": 2.0, "drive_half": 0.5}.get(name, 1.0)
            changed = [toy_fitness(*d, height, factor * PAPER_TORQUE) for d in designs]
            assert alt["fitness_m"] == pytest.approx(changed, abs=1e-9), name
            rho = spearmanr(base, changed).statistic
            assert alt["rank_correlation"] == pytest.approx(rho if np.isfinite(rho) else 1.0), name
            assert alt["largest_change_m"] == pytest.approx(max(abs(c - b) for c, b in zip(changed, base, strict=True)),
                                                            abs=1e-9)
        assert bands["alternatives"]["front_wheel_spin"]["largest_change_m"] == pytest.approx(0.0, abs=1e-12)
        assert bands["alternatives"]["drive_double"]["largest_change_m"] > 0.1



def test_an_alternative_whose_job_failed_is_left_out_with_why_and_the_others_shown(
        client: TestClient, settings: Settings) -> None:
    """A model-band job that failed (its CPU budget, say) is not run again by asking again: the others'
    results are answered, and the failed one is among the skipped with its job and error."""
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP | {"roads": ["flat"]}).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    jobs = client.get(url, params={"model_band": "true"}).json()["model_band_jobs"]
    for i in jobs.values():
        wait_done(client, i)
    db = open_database(settings)
    with db.write() as session:   # as the scheduler would mark a job over its budget
        session.execute(update(Job).where(Job.id == jobs["drive_half"]).values(state="failed", error="over budget"))
    done = client.get(url, params={"model_band": "true"}).json()
    assert done["model_band_jobs"] == jobs and done["model_band_state"] == "failed"
    bands = done["sharpness"][0]["model_bands"]
    assert "drive_half" not in bands["alternatives"] and "drive_double" in bands["alternatives"]
    assert bands["skipped_reasons"]["drive_half"] == f"its job {jobs['drive_half']} failed: over budget"
    assert "drive_half" in bands["skipped"]


def test_the_lower_load_range_is_left_out_for_a_vehicle_whose_range_is_lower_already(client: TestClient) -> None:
    vehicle = default_vehicle().replace(Fz_max=4000.0).to_dict()
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP | {"roads": ["flat"], "vehicle": vehicle}).json()["id"])
    body = client.get(f"/v1/jobs/{job['id']}/best", params={"model_band": "true"}).json()
    assert "tyre_load_range_4800" not in body["model_band_jobs"]
    bands = best_when_done(client, f"/v1/jobs/{job['id']}/best", "model_band", body["model_band_jobs"])
    bands = bands["sharpness"][0]["model_bands"]
    assert "does not apply" in bands["skipped_reasons"]["tyre_load_range_4800"]
