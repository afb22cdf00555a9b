"""/v1/jobs: submit, idempotency, list, get, cancel, results (a scheduler thread with the toy fitness)."""

from __future__ import annotations

import csv
import io

import pytest
from fastapi.testclient import TestClient

from tests.service.svc_helpers import DE, SWEEP, ToyTask, wait_done


def test_sweep_runs_and_streams_results(client: TestClient) -> None:
    r = client.post("/v1/jobs", json=SWEEP)
    assert r.status_code == 201, r.text
    job = r.json()
    assert r.headers["location"] == f"/v1/jobs/{job['id']}"
    assert job["total"] == 4 * 3 * 2
    done = wait_done(client, job["id"])
    assert done["state"] == "succeeded"
    assert (done["done"], done["failed"]) == (24, 0)
    assert [road["name"] for road in done["roads"]] == ["flat", "sine:0.025:3"]
    best_flat = done["roads"][0]["best"]
    assert best_flat["l2_m"] == 0.1 and round(best_flat["a2_deg"]) == 60

    page = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"limit": 10}).json()
    assert len(page["items"]) == 10 and page["next_cursor"]
    rest = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"cursor": page["next_cursor"]}).json()
    assert len(rest["items"]) == 14 and rest["next_cursor"] is None
    ids = [e["id"] for e in page["items"] + rest["items"]]
    assert ids == sorted(set(ids))

    text = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"format": "csv", "road": "flat"})
    assert text.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(text.text)))
    assert len(rows) == 12 and {row["road"] for row in rows} == {"flat"}

    best = client.get(f"/v1/jobs/{job['id']}/best").json()
    assert best["roads"][0]["best"]["id"] == best_flat["id"]


def test_result_cache_spans_jobs(client: TestClient, fake: ToyTask) -> None:
    first = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    simulated = fake.simulated
    second = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    assert fake.simulated == simulated
    assert (second["done"], second["cached"]) == (24, 24)
    assert second["roads"][0]["best"]["fitness_m"] == first["roads"][0]["best"]["fitness_m"]


def test_de_job_and_best_is_never_a_failure(client: TestClient, fake: ToyTask) -> None:
    fake.fail_above_l2 = 0.1
    job = wait_done(client, client.post("/v1/jobs", json=DE).json()["id"])
    assert job["state"] == "succeeded"
    assert job["total"] == job["done"] + job["failed"] == 6 * 5
    assert job["failed"] > 0
    failed = [e for e in client.get(f"/v1/jobs/{job['id']}/evaluations").json()["items"] if e["status"] == "failed"]
    assert failed and all(e["reason"] == "fake divergence" and e["fitness_m"] is None for e in failed)
    best = job["roads"][0]["best"]
    assert best["status"] == "ok" and best["l2_m"] <= 0.1


def test_robust_de_scores_every_road(client: TestClient) -> None:
    spec = {"kind": "robust-de", "roads": ["flat", "sine:0.025:3"], "de": {"np": 5, "iters": 2},
            "aggregate": "worst"}
    job = wait_done(client, client.post("/v1/jobs", json=spec).json()["id"])
    assert job["state"] == "succeeded" and job["done"] == 2 * 5 * 3
    robust = client.get(f"/v1/jobs/{job['id']}/best").json()["robust_best"]
    assert robust["aggregate"] == "worst" and robust["generation"] == 3
    assert robust["score_m"] <= min(r["best"]["fitness_m"] for r in job["roads"])


def test_idempotency_key(client: TestClient) -> None:
    headers = {"Idempotency-Key": "abc"}
    first = client.post("/v1/jobs", json=SWEEP, headers=headers)
    again = client.post("/v1/jobs", json=SWEEP, headers=headers)
    assert (first.status_code, again.status_code) == (201, 200)
    assert again.json()["id"] == first.json()["id"]
    other = client.post("/v1/jobs", json={**SWEEP, "seed": 9}, headers=headers)
    assert other.status_code == 422
    assert other.json()["type"].endswith("idempotency-key-reused")
    assert len(client.get("/v1/jobs").json()["items"]) == 1


def test_list_filters_and_paginates(client: TestClient) -> None:
    ids = [wait_done(client, client.post("/v1/jobs", json=spec).json()["id"])["id"] for spec in (SWEEP, DE, SWEEP)]
    page = client.get("/v1/jobs", params={"limit": 2}).json()
    assert [j["id"] for j in page["items"]] == ids[::-1][:2]
    last = client.get("/v1/jobs", params={"limit": 2, "cursor": page["next_cursor"]}).json()
    assert [j["id"] for j in last["items"]] == [ids[0]] and last["next_cursor"] is None
    assert [j["id"] for j in client.get("/v1/jobs", params={"kind": "de"}).json()["items"]] == [ids[1]]
    assert client.get("/v1/jobs", params={"state": "running"}).json()["items"] == []


def test_cancel_is_idempotent_and_stops_dispatch(client: TestClient, fake: ToyTask) -> None:
    fake.gate.clear()
    job = client.post("/v1/jobs", json=SWEEP).json()
    first = client.post(f"/v1/jobs/{job['id']}/cancel")
    fake.gate.set()
    again = client.post(f"/v1/jobs/{job['id']}/cancel")
    assert first.status_code == again.status_code == 200
    assert first.json()["state"] == again.json()["state"] == "cancelled"
    final = wait_done(client, job["id"])
    assert final["state"] == "cancelled" and final["done"] < 24
    assert client.post("/v1/jobs/999/cancel").status_code == 404


def test_events_stream_until_the_end(client: TestClient) -> None:
    job = client.post("/v1/jobs", json=SWEEP).json()
    with client.stream("GET", f"/v1/jobs/{job['id']}/events") as r:
        assert r.headers["content-type"].startswith("text/event-stream")
        body = "".join(r.iter_text())
    assert "event: progress" in body and "event: end" in body
    assert '"state":"succeeded"' in body.replace(" ", "")


def test_roads_and_health(client: TestClient) -> None:
    roads = client.get("/v1/roads").json()
    assert len(roads) == 23 and roads[0]["name"] == "flat"
    health = client.get("/v1/health").json()
    assert health["status"] == "ok" and [s["executor"] for s in health["schedulers"]] == ["serial"]


def test_concurrent_jobs_share_the_executor_round_robin(client: TestClient, fake: ToyTask) -> None:
    fake.gate.clear()
    # a's designs (0.48 s) outlast the scheduler's heartbeat (0.05 s) and its look for new jobs (0.2 s) with room
    # to spare, so b joins while a runs (at 5 ms a design, 0.12 s, a loaded CI ran all of a's before b's)
    fake.delay = 0.02
    a = client.post("/v1/jobs", json=SWEEP).json()["id"]
    b_roads = ["bump:0.01:0.5", "bump:0.02:0.5"]  # none of a's: a task may hold both jobs' rows
    b = client.post("/v1/jobs", json=SWEEP | {"seed": 1, "roads": b_roads}).json()["id"]
    fake.roads_run.clear()
    fake.gate.set()
    wait_done(client, a), wait_done(client, b)
    # the executor ran their designs interleaved, not one job's after the other's (told by each row's
    # road; the store's ids would tell only when each job's results were handed to the writer)
    order = fake.roads_run
    of_a = [i for i, spec in enumerate(order) if not spec.startswith("bump")]
    of_b = [i for i, spec in enumerate(order) if spec.startswith("bump")]
    assert len(of_a) == len(of_b) == 24
    assert min(of_b) < max(of_a) and min(of_a) < max(of_b)


def test_best_reports_the_near_optimal_set(client: TestClient) -> None:
    """Toy fitness 20 - (a2 - 1)^2 - 10 (l2 - 0.1)^2 - ...: at a2 = 60 deg every L2 of the grid is
    within 0.2 % (40 mm) of the best, no other a2 is."""
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    best = client.get(f"/v1/jobs/{job['id']}/best", params={"tolerance_pct": 0.2}).json()
    flat = best["sharpness"][0]
    assert flat["road"] == "flat" and flat["tolerance_pct"] == 0.2 and flat["evaluated"] == 12
    assert flat["count"] == 3 and flat["ranges"]["l2_m"] == [0.05, 0.15]
    assert round(flat["ranges"]["a2_deg"][0]) == round(flat["ranges"]["a2_deg"][1]) == 60
    assert flat["verdicts"] == {"a2_deg": "decided", "l2_m": "undetermined", "rws_m": "fixed"}
    assert flat["sensitivity"] is None
    assert client.get(f"/v1/jobs/{job['id']}/best", params={"tolerance_pct": 0}).status_code == 422


def test_best_of_a_de_reports_its_final_population(client: TestClient) -> None:
    job = wait_done(client, client.post("/v1/jobs", json=DE).json()["id"])
    sharp = client.get(f"/v1/jobs/{job['id']}/best").json()["sharpness"][0]
    assert sharp["final_population"]["count"] == 6 and sharp["evaluated"] == 6 * 5
    lo, hi = sharp["final_population"]["ranges"]["fitness_m"]
    assert hi == pytest.approx(sharp["best_fitness_m"]) and lo <= hi


def test_a_cmaes_job_runs_and_optimiser_settings_are_refused_by_name(client: TestClient) -> None:
    """The method is a setting: a cmaes job succeeds through the protocol; an unknown method, a
    setting out of range and a budget below the preset's NP are 422s naming the field."""
    spec = {**DE, "de": {"optimiser": "cmaes", "np": 6, "iters": 3, "sigma": 0.2}}
    job = wait_done(client, client.post("/v1/jobs", json=spec).json()["id"])
    assert job["state"] == "succeeded" and job["done"] == 6 * 4
    assert job["spec"]["de"] == {"preset": "default", "optimiser": "cmaes", "np": 6, "f": 0.8, "cp": 0.6, "mp": 0.1,
                                 "mr_fraction": 0.2, "sigma": 0.2, "iters": 3, "patience": 15, "tol_m": 2e-4,
                                 "max_evals": None}
    history = client.get(f"/v1/jobs/{job['id']}/history").json()["runs"][0]["generations"]
    assert [g["n_evals"] for g in history] == [6, 12, 18, 24]
    for de, where in [({"optimiser": "bfgs"}, "optimiser: unknown method 'bfgs'"), ({"sigma": 2.0}, "sigma"),
                      ({"preset": "paper", "max_evals": 20}, "max_evals: must be >= np (50)"),
                      ({"preset": "fast"}, "preset")]:
        response = client.post("/v1/jobs", json={**DE, "de": de})
        assert response.status_code == 422 and where in response.json()["detail"], (de, response.json())
