"""/v1/jobs/{id}/evaluations: CSV pages stream rows in chunks; JSON pages are capped. /best: sensitivity
simulated by the scheduler, requests in flight limited per client."""

from __future__ import annotations

import csv
import io
import time

import pytest
from fastapi.testclient import TestClient

from finaldrive.engine import default_vehicle, finite_differences, resolve_roads, upper_limits
from finaldrive.service.api.routes import results
from finaldrive.service.api.sharpness import stencil
from finaldrive.service.db import columns
from tests.service.svc_helpers import SWEEP, ToyTask, best_when_done, toy_batch, wait_done


def test_csv_pages_stream_the_same_rows_as_json(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(columns, "CHUNK_ROWS", 5)  # several chunks a page
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    url = f"/v1/jobs/{job['id']}/evaluations"
    items = client.get(url).json()["items"]
    rows, cursor, pages = [], None, 0
    while True:
        r = client.get(url, params={"format": "csv", "limit": 7, **({"cursor": cursor} if cursor else {})})
        assert r.headers["content-type"].startswith("text/csv")
        page = list(csv.DictReader(io.StringIO(r.text)))
        assert 0 < len(page) <= 7 and list(page[0]) == list(results.CSV_COLUMNS)
        rows += page
        pages += 1
        cursor = r.headers["x-next-cursor"]
        if not cursor:
            break
    assert pages == 4 and len(rows) == len(items) == 24
    for row, item in zip(rows, items, strict=True):
        assert row == {k: "" if v is None else str(v) for k, v in item.items()}
    on_road = client.get(url, params={"format": "csv", "road": "flat", "limit": 100})
    assert on_road.text.count("\n") == 13 and on_road.headers["x-next-cursor"] == ""


def test_json_pages_are_capped(client: TestClient) -> None:
    job = client.post("/v1/jobs", json=SWEEP).json()
    url = f"/v1/jobs/{job['id']}/evaluations"
    r = client.get(url, params={"limit": 10_001})
    assert r.status_code == 422 and "format=csv" in r.json()["detail"]
    assert client.get(url, params={"limit": 10_000}).status_code == 200
    assert client.get(url, params={"limit": 100_000, "format": "csv"}).status_code == 200
    assert client.get("/v1/jobs/999/evaluations", params={"format": "csv"}).status_code == 404


def test_best_sensitivity_is_simulated_by_the_scheduler(client: TestClient, fake: ToyTask) -> None:
    """The API answers at once (202, the queued job named); the derivatives are those of the toy fitness
    the scheduler's task computes, so no simulation ran in the API; one sensitivity job per job."""
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP | {"roads": ["flat"]}).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    fake.gate.clear()  # the scheduler's task waits: the sensitivity job cannot finish yet
    started = time.monotonic()
    first = client.get(url, params={"sensitivity": "true"})
    assert time.monotonic() - started < 1.0
    assert first.status_code == 202 and first.headers["retry-after"] == "2"
    pending = first.json()
    assert pending["sensitivity_state"] in ("queued", "running") and pending["sharpness"][0]["sensitivity"] is None
    assert first.headers["location"] == f"/v1/jobs/{pending['sensitivity_job']}"
    again = client.get(url, params={"sensitivity": "true"}).json()
    assert again["sensitivity_job"] == pending["sensitivity_job"]
    designs = client.get(f"/v1/jobs/{pending['sensitivity_job']}").json()
    assert designs["kind"] == "designs" and designs["total"] == 7
    fake.gate.set()
    wait_done(client, pending["sensitivity_job"])
    done = client.get(url, params={"sensitivity": "true"})
    assert done.status_code == 200 and done.json()["sensitivity_state"] == "succeeded"
    s = done.json()["sharpness"][0]["sensitivity"]
    best = job["roads"][0]["best"]
    rows, schemes = stencil(best["a2_deg"], best["l2_m"], best["rws_m"], upper_limits(default_vehicle()))
    toy = toy_batch(rows, resolve_roads("flat")[0].road)
    expected = finite_differences(schemes, toy.distance_m, toy.fitness_m)
    assert s["simulations"] == 7 and s["schemes"] == schemes
    for name, value in expected.items():
        assert s[name] == pytest.approx(value, rel=1e-9, abs=1e-12), name
    assert len(client.get("/v1/jobs", params={"kind": "designs"}).json()["items"]) == 1


def test_a_cancelled_sensitivity_job_is_queued_again(client: TestClient, fake: ToyTask) -> None:
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP | {"roads": ["flat"]}).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    fake.gate.clear()
    first = client.get(url, params={"sensitivity": "true"}).json()["sensitivity_job"]
    assert client.post(f"/v1/jobs/{first}/cancel").json()["state"] == "cancelled"
    again = client.get(url, params={"sensitivity": "true"})
    fake.gate.set()
    assert again.status_code == 202 and again.json()["sensitivity_job"] != first
    wait_done(client, again.json()["sensitivity_job"])
    assert client.get(url, params={"sensitivity": "true"}).json()["sensitivity_state"] == "succeeded"


@pytest.mark.parametrize("option", ["sensitivity", "band", "model_band"])
def test_best_simulations_wait_for_the_job_to_finish(client: TestClient, fake: ToyTask, option: str) -> None:
    fake.gate.clear()
    job = client.post("/v1/jobs", json=SWEEP).json()
    r = client.get(f"/v1/jobs/{job['id']}/best", params={option: "true"})
    fake.gate.set()
    assert r.status_code == 409 and "once it has finished" in r.json()["detail"]
    assert client.get(f"/v1/jobs/{job['id']}/best").status_code == 200


def test_best_in_flight_is_limited_per_client(client: TestClient) -> None:
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    with results.IN_FLIGHT.slot("testclient"), results.IN_FLIGHT.slot("testclient"):
        r = client.get(url)
        assert r.status_code == 429 and r.headers["retry-after"] == "2"
        with results.IN_FLIGHT.slot("elsewhere"):
            pass  # another client still has room
    assert client.get(url).status_code == 200


def test_a_designs_job_evaluates_each_roads_own_designs(client: TestClient) -> None:
    spec = {"kind": "designs", "roads": ["flat", "sine:0.025:3"],
            "designs": [[[60.0, 0.1, 0.09]], [[0.0, 0.05, 0.09], [30.0, 0.15, 0.08]]]}
    job = wait_done(client, client.post("/v1/jobs", json=spec).json()["id"])
    assert job["state"] == "succeeded" and job["total"] == 3
    items = client.get(f"/v1/jobs/{job['id']}/evaluations").json()["items"]
    assert sorted((e["road"], e["candidate"], e["a2_deg"], e["l2_m"]) for e in items) == [
        ("flat", 0, pytest.approx(60.0), 0.1), ("sine:0.025:3", 0, 0.0, 0.05),
        ("sine:0.025:3", 1, pytest.approx(30.0), 0.15)]
    wrong = ((spec | {"designs": spec["designs"][:1]}, "designs"),
             (spec | {"designs": [[[0, 0.5, 0.09]]] * 2}, "designs"),  # L2 beyond the vehicle's limit
             (SWEEP | {"designs": [[[0, 0.1, 0.09]]]}, "designs"), ({**spec, "grid": "table9"}, "grid"))
    for bad, field in wrong:
        r = client.post("/v1/jobs", json=bad)
        assert r.status_code == 422 and field in r.text, bad


def test_a_design_given_twice_in_a_request_is_simulated_once(client: TestClient, fake: ToyTask) -> None:
    """Each distinct design of a request is simulated once; its copy is stored in its own slot as cached,
    with the same result."""
    design = [10.0, 0.05, 0.09]
    spec = {"kind": "designs", "roads": ["flat"], "designs": [[design, [20.0, 0.06, 0.09], design]]}
    before = fake.simulated
    job = wait_done(client, client.post("/v1/jobs", json=spec).json()["id"])
    assert fake.simulated - before == 2
    assert (job["state"], job["done"], job["cached"]) == ("succeeded", 3, 1)
    items = sorted(client.get(f"/v1/jobs/{job['id']}/evaluations").json()["items"], key=lambda e: e["candidate"])
    assert [e["cached"] for e in items] == [False, False, True]
    assert items[2]["fitness_m"] == items[0]["fitness_m"] != items[1]["fitness_m"]


def test_a_client_cannot_take_a_sensitivity_or_band_key(client: TestClient) -> None:
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP | {"roads": ["flat"]}).json()["id"])
    for key in (f"sensitivity:{job['id']}", f"band:tight:{job['id']}", f"model-band:drive_half:{job['id']}"):
        r = client.post("/v1/jobs", json=SWEEP, headers={"Idempotency-Key": key})
        assert r.status_code == 422 and "idempotency-key" in r.json()["detail"]


def test_best_bands_are_simulated_by_the_scheduler(client: TestClient, fake: ToyTask) -> None:
    """202 while the two re-run jobs (kind designs: 100x tighter, the reference method) run, then each
    road's best distinct designs with their bands: the toy fitness ignores the settings, so every band
    is 0 and only the best ties with itself (the real engine's: test_e2e_server.py)."""
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    assert client.get(url).json()["band_jobs"] is None
    fake.gate.clear()
    first = client.get(url, params={"band": "true"})
    assert first.status_code == 202 and first.json()["band_state"] in ("queued", "running")
    jobs = first.json()["band_jobs"]
    assert client.get(url, params={"band": "true"}).json()["band_jobs"] == jobs
    specs = {label: client.get(f"/v1/jobs/{i}").json()["spec"] for label, i in jobs.items()}
    assert specs["tight"]["settings"]["fast_tolerance"] == pytest.approx(5e-7)
    assert specs["reference"]["settings"]["method"] == "reference"
    assert [len(d) for d in specs["tight"]["designs"]] == [5, 5] and specs["tight"]["roads"] == SWEEP["roads"]
    fake.gate.set()
    for road, sharp in zip(job["roads"], best_when_done(client, url, "band", jobs)["sharpness"], strict=True):
        ties = sharp["ties"]
        assert sharp["numerical_band"]["fitness_m"] == road["best"]["fitness_m"] == ties[0]["fitness_m"]
        assert [t["band_m"] for t in ties] == [0.0] * 5 and [t["tie"] for t in ties] == [True] + [False] * 4
        assert len({(t["a2_deg"], t["l2_m"], t["rws_m"]) for t in ties}) == 5
        assert all(set(t["runs"]) == {"production", "tight", "reference"} for t in ties)


def test_a_vehicle_only_the_fast_method_models_is_banded_without_the_reference_run(client: TestClient,
                                                                                  fake: ToyTask) -> None:
    """The elastic chain (and the two-run chain) cannot be re-run by the reference method: the band is the
    tight re-run's alone and says why the reference run is left out; no reference job is queued."""
    vehicle = default_vehicle().replace(chain_compliance=1.0).to_dict()
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP | {"roads": ["flat"], "vehicle": vehicle}).json()["id"])
    url = f"/v1/jobs/{job['id']}/best"
    jobs = client.get(url, params={"band": "true"}).json()["band_jobs"]
    assert set(jobs) == {"tight"}
    ties = best_when_done(client, url, "band", jobs)["sharpness"][0]["ties"]
    assert all(set(t["runs"]) == {"production", "tight"} and t["band_m"] == 0.0 for t in ties)
    assert all("fast method only" in t["failed"]["reference"] for t in ties)
