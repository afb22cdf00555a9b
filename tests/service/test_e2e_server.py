"""End to end: ``finaldrive serve`` (uvicorn and its scheduler), the real engine, the serial executor, SQLite."""

from __future__ import annotations

import contextlib
import json
import math
import sqlite3
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import psutil
import pytest

from finaldrive.engine import DIAGNOSTICS, evaluate, numerical_bands, tie_flags
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.schemas import JobSpec
from tests.service.processes import Server
from tests.service.svc_helpers import wait_done

pytestmark = pytest.mark.slow  # starts servers or subprocesses

SIM = {"duration": 0.3}
SWEEP = {"kind": "sweep", "roads": ["flat"], "grid": "a2_deg=0:270:90,l2_m=0.05|0.15,rws_m=0.09", "settings": SIM}
DE = {"kind": "de", "roads": ["sine:0.02:3"], "de": {"np": 6, "iters": 3}, "seed": 7, "settings": SIM}
# the paper's method, so the job runs long enough (about 2 s) to be killed three times
LONG_DE = {"kind": "de", "roads": ["flat"], "de": {"np": 8, "iters": 14}, "seed": 11,
           "settings": {**SIM, "method": "reference"}}
TERMINAL = {"succeeded", "failed", "cancelled"}
#: a killed scheduler's job is taken over within seconds
LEASES = {"FINALDRIVE_LEASE_SECONDS": "2", "FINALDRIVE_HEARTBEAT_SECONDS": "0.2"}


@pytest.fixture
def server(tmp_path: Path) -> Iterator[Any]:
    """``finaldrive serve`` with the serial executor; ``server.start()`` returns its client."""

    class Restartable:
        def __init__(self) -> None:
            self.proc: Server | None = None

        def start(self) -> httpx.Client:
            self.proc = Server(f"sqlite:///{tmp_path / 'e2e.db'}", tmp_path / "server.log", "--executor", "serial",
                               env=LEASES)
            return self.proc.start().client

        def kill(self, *, alone: bool = False) -> None:
            """SIGKILL the server and its scheduler at once, as a crash of the machine would; ``alone``:
            the server only, whose scheduler must then stop by itself (within half a second, time
            enough to finish a short job)."""
            if self.proc is not None:
                scheduler = self.proc.descendants()
                for process in [] if alone else scheduler:
                    with contextlib.suppress(psutil.NoSuchProcess):
                        process.kill()
                self.proc.kill()
                _, alive = psutil.wait_procs(scheduler, timeout=10)
                assert not alive, "the scheduler outlived its server"

    srv = Restartable()
    try:
        yield srv
    finally:
        srv.kill()


def wait(client: httpx.Client, job_id: int) -> dict[str, Any]:
    return wait_done(client, job_id, timeout=120, poll=0.1)


def reference_de(spec: dict[str, Any]) -> Any:
    """The same DE, uninterrupted, in this process."""
    plan = build_plan(JobSpec.model_validate(spec).normalised())
    study = plan.study
    assert study.de is not None and study.bounds is not None
    de = study.de.build(study.bounds, study.seed)
    while not de.done:
        de.tell(evaluate(de.ask(), study.roads[0].road, plan.settings).fitness_m)
    return de


def test_sweep_and_de_over_http_match_in_process(server: Any) -> None:
    client = server.start()
    sweep = client.post("/v1/jobs", json=SWEEP)
    de = client.post("/v1/jobs", json=DE)
    assert (sweep.status_code, de.status_code) == (201, 201)

    plan = build_plan(JobSpec.model_validate(SWEEP).normalised())
    assert plan.study.designs is not None
    expected = evaluate(plan.study.designs, plan.study.roads[0].road, plan.settings)
    reference = reference_de(DE)

    sweep_job = wait(client, sweep.json()["id"])
    assert sweep_job["state"] == "succeeded"
    assert sweep_job["done"] + sweep_job["failed"] == len(plan.study.designs)
    assert sweep_job["failed"] == int(np.count_nonzero(~expected.ok))
    ok = np.where(expected.ok, expected.fitness_m, -np.inf)
    assert sweep_job["roads"][0]["best"]["fitness_m"] == pytest.approx(ok.max(), rel=1e-12)

    items = client.get(f"/v1/jobs/{sweep_job['id']}/evaluations").json()["items"]
    by_candidate = {e["candidate"]: e for e in items}
    assert sorted(by_candidate) == list(range(len(plan.study.designs)))
    for i, e in by_candidate.items():  # one result record: every field as the engine gave it, to the bit
        assert (e["status"], e["reason"]) == (expected.status[i], expected.reason[i])
        assert [e["a2_deg"], e["l2_m"], e["rws_m"]] == [math.degrees(expected.designs[i, 0]), *expected.designs[i, 1:]]
        for name in ("distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m", *DIAGNOSTICS):
            value = float(getattr(expected, name)[i])
            assert e[name] == (value if math.isfinite(value) else None), name
    csv = client.get(f"/v1/jobs/{sweep_job['id']}/evaluations", params={"format": "csv"}).text
    assert len(csv.strip().splitlines()) == len(plan.study.designs) + 1

    de_job = wait(client, de.json()["id"])
    assert de_job["state"] == "succeeded"
    assert de_job["done"] + de_job["failed"] == reference.n_evals
    best = client.get(f"/v1/jobs/{de_job['id']}/best").json()["roads"][0]["best"]
    assert best["fitness_m"] == pytest.approx(reference.best_f, rel=1e-12)
    assert [math.radians(best["a2_deg"]), best["l2_m"], best["rws_m"]] == pytest.approx(reference.best_x.tolist(),
                                                                                          rel=1e-12)

    # numerical bands: re-simulated by the scheduler (tight; reference), each equal to the engine's own
    url = f"/v1/jobs/{de_job['id']}/best"
    first = client.get(url, params={"band": "true"})
    assert first.status_code in (200, 202) and set(first.json()["band_jobs"]) == {"tight", "reference"}
    for job_id in first.json()["band_jobs"].values():
        assert wait(client, job_id)["state"] == "succeeded"
    done = client.get(url, params={"band": "true"})
    assert done.status_code == 200 and done.json()["band_state"] == "succeeded"
    road = done.json()["sharpness"][0]
    rows = np.array([[math.radians(t["a2_deg"]), t["l2_m"], t["rws_m"]] for t in road["ties"]])
    plan = build_plan(JobSpec.model_validate(DE).normalised())
    engine = numerical_bands(rows, plan.study.roads[0].road, plan.settings)
    assert road["ties"][0]["fitness_m"] == best["fitness_m"] and road["numerical_band"] == {
        k: v for k, v in road["ties"][0].items() if k not in ("a2_deg", "l2_m", "rws_m", "tie")}
    assert 2 <= len(rows) <= 5 and [t["fitness_m"] for t in road["ties"]] == sorted(
        (t["fitness_m"] for t in road["ties"]), reverse=True)
    for got, want in zip(road["ties"], engine, strict=True):
        for name in ("fitness_m", "distance_m", "band_m", "distance_band_m"):
            assert got[name] == pytest.approx(want[name], rel=1e-9, abs=1e-12), name
        assert (got["exceeds_limit"], got["failed"], set(got["runs"])) == (want["exceeds_limit"], want["failed"],
                                                                           set(want["runs"]))
        for label, values in want["runs"].items():
            assert got["runs"][label] == pytest.approx(values, rel=1e-9, abs=1e-12), label
    assert [t["tie"] for t in road["ties"]] == tie_flags(engine)


def test_de_survives_three_sigkills(server: Any, tmp_path: Path) -> None:
    client = server.start()
    job_id = client.post("/v1/jobs", json=LONG_DE).json()["id"]
    total = client.get(f"/v1/jobs/{job_id}").json()["total"]
    for kill in range(3):
        target = total * (kill + 1) // 4
        deadline = time.monotonic() + 120
        while True:  # read from the store, not the API's status (a hub tick behind): the kill comes sooner
            with sqlite3.connect(tmp_path / "e2e.db", timeout=30) as db:
                completed, state = db.execute("SELECT n_done + n_failed, state FROM jobs WHERE id = ?",
                                              (job_id,)).fetchone()
            if completed >= target or state in TERMINAL or time.monotonic() > deadline:
                break
            time.sleep(0.01)
        assert state == "running", (completed, state)
        server.kill(alone=kill == 0)  # the first with three quarters of the job left
        client = server.start()
        assert client.get(f"/v1/jobs/{job_id}").json()["state"] in ("interrupted", "running")
    job = wait(client, job_id)
    assert job["state"] == "succeeded"
    reference = reference_de(LONG_DE)  # after the kills: the server must not race ahead meanwhile

    with sqlite3.connect(tmp_path / "e2e.db") as db:
        slots = db.execute("SELECT step, candidate FROM evaluations WHERE job_id = ?", (job_id,)).fetchall()
        population = db.execute(
            "SELECT population FROM generations WHERE job_id = ? ORDER BY generation DESC LIMIT 1", (job_id,)
        ).fetchone()[0]
    assert len(slots) == len(set(slots)) == reference.n_evals == job["done"] + job["failed"]
    assert np.array_equal(np.array(json.loads(population)), reference.population)
    best = job["roads"][0]["best"]
    assert best["fitness_m"] == reference.best_f
    assert best["a2_deg"] == pytest.approx(math.degrees(reference.best_x[0]), rel=1e-15)  # stored in degrees
    assert [best["l2_m"], best["rws_m"]] == reference.best_x[1:].tolist()
