"""End to end, real processes: several services and schedulers on one store, crashes, locks, cancel, SIGTERM.

``finaldrive serve`` and ``finaldrive scheduler`` run as processes with the real engine (short
simulations), on a SQLite file and on a real PostgreSQL server (tests/pg.py).
"""

from __future__ import annotations

import contextlib
import json
import signal
import sqlite3
import time
from pathlib import Path
from typing import Any

import psutil
import pytest
from sqlalchemy import create_engine, text

from tests.service.processes import Proc, Server
from tests.service.svc_helpers import TERMINAL, wait_done

pytestmark = pytest.mark.slow

SIM = {"duration": 0.3}
DE = {"kind": "de", "roads": ["flat,sine:0.02:3"], "de": {"np": 8, "iters": 5}, "seed": 5, "settings": SIM}
#: A seeded DE of 1,220 evaluations in 61 generations (no early stop), long enough for three crashes of its store.
DURABLE_DE = {"kind": "de", "roads": ["flat,sine:0.02:3"], "de": {"preset": "paper", "np": 10, "iters": 60}, "seed": 11,
              "settings": {"duration": 1.0}}
#: Fast leases, so a killed scheduler's job is taken over in seconds.
LEASES = {"FINALDRIVE_LEASE_SECONDS": "2", "FINALDRIVE_HEARTBEAT_SECONDS": "0.2"}


GENERATIONS = "SELECT count(*) FROM generations WHERE job_id = :j"


def rows(db_url: str, query: str, **params: Any) -> list[tuple[Any, ...]]:
    engine = create_engine(db_url)
    try:
        with engine.connect() as conn:
            return [tuple(r) for r in conn.execute(text(query), params)]
    finally:
        engine.dispose()


def slots(db_url: str, job_id: int) -> list[tuple[int, int, int]]:
    return rows(db_url, "SELECT road_index, step, candidate FROM evaluations WHERE job_id = :j", j=job_id)


def final_populations(db_url: str, job_id: int) -> dict[int, str]:
    found = rows(db_url, "SELECT run, generation, population FROM generations WHERE job_id = :j", j=job_id)
    last: dict[int, tuple[int, str]] = {}
    for run, generation, population in found:
        if run not in last or generation > last[run][0]:
            last[run] = (generation, str(population))
    return {run: population for run, (_, population) in last.items()}


def stored(db_url: str, job_id: int) -> tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]:
    """A job's evaluations and DE generations as the store holds them, sorted, without what may differ
    between two runs of a seeded job (ids, times, cache flags)."""
    evaluations = rows(db_url, "SELECT road_index, step, candidate, a2_deg, l2_m, rws_m, status, fitness_m, "
                       "distance_m, squat_ratio, slack_m FROM evaluations WHERE job_id = :j", j=job_id)
    found = rows(db_url, "SELECT run, generation, population, fitness_m, best_fitness_m, n_evals FROM generations "
                 "WHERE job_id = :j", j=job_id)
    generations = [(run, step, _json(population), _json(fitness), best, n) for run, step, population, fitness, best, n
                   in found]
    return sorted(evaluations), sorted(generations)


def _json(value: Any) -> str:
    return json.dumps(json.loads(value) if isinstance(value, str) else value)


def reference(tmp_path: Path, spec: dict[str, Any]) -> tuple[str, int]:
    """The same job run by one service alone: (its database, job id)."""
    url = f"sqlite:///{tmp_path / 'alone.db'}"
    server = Server(url, tmp_path / "alone.log", "--executor", "serial").start()
    try:
        job_id = server.client.post("/v1/jobs", json=spec).json()["id"]
        assert wait_done(server.client, job_id, timeout=300, poll=0.2)["state"] == "succeeded"
    finally:
        server.terminate()
    return url, job_id


def test_two_services_on_one_sqlite_file(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'shared.db'}"
    ref_url, ref_id = reference(tmp_path, DE)
    one = Server(url, tmp_path / "one.log", "--executor", "serial").start()
    two = Server(url, tmp_path / "two.log", "--executor", "serial").start()
    try:
        ids = [one.client.post("/v1/jobs", json={**DE, "seed": s}).json()["id"] for s in (5, 6)]
        ids.append(two.client.post("/v1/jobs", json={**DE, "seed": 7}).json()["id"])
        deadline = time.monotonic() + 60  # the second service's scheduler registers after its API answers
        while len([s for s in one.client.get("/v1/health").json()["schedulers"] if s["alive"]]) < 2:
            assert time.monotonic() < deadline, "the second scheduler never registered"
            time.sleep(0.2)
        jobs = [wait_done(two.client, job_id, timeout=300, poll=0.2) for job_id in ids]
        assert all(job["state"] == "succeeded" for job in jobs)
        for job_id in ids:
            found = slots(url, job_id)
            assert len(found) == len(set(found)) == len(slots(ref_url, ref_id))
        assert final_populations(url, ids[0]) == final_populations(ref_url, ref_id)
    finally:
        one.terminate()
        two.terminate()


@pytest.mark.parametrize("store", ["sqlite", "postgresql"])
def test_a_scheduler_killed_three_times_loses_and_repeats_nothing(store: str, tmp_path: Path,
                                                                  request: pytest.FixtureRequest) -> None:
    if store == "sqlite":
        url = f"sqlite:///{tmp_path / 'study.db'}"
    else:
        url = request.getfixturevalue("postgres").new_database()
    ref_url, ref_id = reference(tmp_path, DURABLE_DE)
    api = Server(url, tmp_path / "api.log", "--no-scheduler").start()
    try:
        job = api.client.post("/v1/jobs", json=DURABLE_DE).json()
        for kill in range(4):
            scheduler = Proc(["scheduler", "--db", url, "--executor", "serial", "--id", f"s{kill}"],
                             tmp_path / "scheduler.log", LEASES).start()
            if kill == 3:
                break
            # killed as soon as a commit takes the store to 5, 10, 15 of the 61 generations: between the
            # store's commit and the scheduler's acknowledgement of it, most times
            while (count := rows(url, GENERATIONS, j=job["id"])[0][0]) < 5 * (kill + 1):
                assert scheduler.alive(), (tmp_path / "scheduler.log").read_text()
                time.sleep(0.002)
            scheduler.kill()  # SIGKILL: its lease lapses; the next one (another id) waits it out
            assert count < 61, "the job was done before the kill"
        done = wait_done(api.client, job["id"], timeout=300, poll=0.2)
        scheduler.terminate()
    finally:
        api.terminate()
    assert done["state"] == "succeeded" and done["done"] + done["failed"] == done["total"] == 2 * 10 * 61
    found = slots(url, job["id"])
    assert len(found) == len(set(found)) == done["total"]
    assert stored(url, job["id"]) == stored(ref_url, ref_id)


def test_an_exclusive_lock_of_30_s_delays_the_job_and_health_says_so(tmp_path: Path) -> None:
    path = tmp_path / "locked.db"
    server = Server(f"sqlite:///{path}", tmp_path / "server.log", "--executor", "serial").start()
    try:
        job = server.client.post("/v1/jobs", json={**DE, "de": {"np": 8, "iters": 12}}).json()
        while server.client.get(f"/v1/jobs/{job['id']}").json()["done"] < 8:
            time.sleep(0.05)
        locker = sqlite3.connect(path, timeout=60)
        locker.execute("BEGIN EXCLUSIVE")
        statuses = []
        try:
            end = time.monotonic() + 30
            while time.monotonic() < end:
                statuses.append(server.client.get("/v1/health").status_code)
                time.sleep(1.0)
        finally:
            locker.rollback()
            locker.close()
        assert set(statuses) == {503}
        done = wait_done(server.client, job["id"], timeout=300, poll=0.2)
        # 200 again once the scheduler's next heartbeat is stored: its store access backs off up to 5 s
        # after an outage, and the job's results (written by their own thread) may land before that
        deadline = time.monotonic() + 10
        while server.client.get("/v1/health").status_code != 200 and time.monotonic() < deadline:
            time.sleep(0.2)
        assert server.client.get("/v1/health").status_code == 200
    finally:
        server.terminate()
    assert done["state"] == "succeeded" and done["error"] is None and done["done"] + done["failed"] == 2 * 8 * 13


def _busy(procs: list[psutil.Process], window: float = 0.5) -> list[int]:
    """Pids of the processes that used the CPU for more than a fifth of ``window``."""
    before = {}
    for p in procs:
        with contextlib.suppress(psutil.NoSuchProcess):
            before[p.pid] = sum(p.cpu_times()[:2])
    time.sleep(window)
    busy = []
    for p in procs:
        try:
            if sum(p.cpu_times()[:2]) - before.get(p.pid, 0.0) > 0.2 * window:
                busy.append(p.pid)
        except psutil.NoSuchProcess:
            pass
    return busy


#: Simulations of 30 s or more each (the paper's method at a fine step: 600,000 steps).
LONG = {"kind": "sweep", "roads": ["flat"], "grid": "a2_deg=0:90:30,l2_m=0.05,rws_m=0.09",
        "settings": {"method": "reference", "duration": 60.0, "dt": 0.0001}}


def test_cancel_frees_the_workers_of_long_simulations_within_2_s(tmp_path: Path) -> None:
    server = Server(f"sqlite:///{tmp_path / 'long.db'}", tmp_path / "server.log", "--executor", "process",
                    env={"FINALDRIVE_NUM_WORKERS": "2"}).start()
    try:
        job = server.client.post("/v1/jobs", json=LONG).json()
        deadline = time.monotonic() + 60
        while len(working := _busy(server.descendants())) < 2:  # both workers simulate
            assert time.monotonic() < deadline, "the simulations never started"
        assert server.client.post(f"/v1/jobs/{job['id']}/cancel").json()["state"] == "cancelled"
        start = time.monotonic()
        simulating = [psutil.Process(pid) for pid in working]
        while _busy(simulating, 0.2):  # the workers that were simulating stop (killed, or idle)
            assert time.monotonic() - start < 3.0, "workers still simulating after the cancel"
        assert time.monotonic() - start <= 2.0
        assert server.client.get(f"/v1/jobs/{job['id']}").json()["state"] == "cancelled"
    finally:
        server.terminate()


def test_sigterm_stops_long_simulations_within_2_s_and_gives_the_job_back(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'long.db'}"
    server = Server(url, tmp_path / "server.log", "--executor", "process", env={"FINALDRIVE_NUM_WORKERS": "2"}).start()
    job = server.client.post("/v1/jobs", json=LONG).json()
    deadline = time.monotonic() + 60
    while len(working := _busy(server.descendants())) < 2:  # both workers simulate
        assert time.monotonic() < deadline, "the simulations never started"
    simulating = [psutil.Process(pid) for pid in working]
    start = time.monotonic()
    assert server.proc is not None
    server.proc.send_signal(signal.SIGTERM)
    _, alive = psutil.wait_procs(simulating, timeout=2.0)
    alive = [p for p in alive if p.status() != psutil.STATUS_ZOMBIE]
    assert not alive, f"workers still running 2 s after SIGTERM: {[p.pid for p in alive]}"
    server.terminate(timeout=20)
    assert time.monotonic() - start < 10
    assert not [p for p in server.descendants() if p.status() != psutil.STATUS_ZOMBIE]
    assert rows(url, "SELECT state, owner FROM jobs WHERE id = :j", j=job["id"]) == [("interrupted", None)]



@pytest.mark.parametrize("kill", [False, True], ids=["pg_ctl-restart-immediate", "sigkill-postmaster"])
def test_three_crashes_of_postgresql_lose_no_acknowledged_result(kill: bool, tmp_path: Path) -> None:
    """Every result the store acknowledged survives its crashes: the job's rows equal an uninterrupted run's."""
    from tests.pg import PostgresServer, bindir

    binaries = bindir()
    if binaries is None:
        pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found; install Debian's postgresql")
    ref_url, ref_id = reference(tmp_path, DURABLE_DE)
    expected = stored(ref_url, ref_id)
    postgres = PostgresServer(binaries).start()   # a server of its own: this test crashes it
    try:
        url = postgres.new_database()
        # a job's dispatch pauses two generations (2 x 20 results) ahead of the store: the DE cannot run to its
        # end in memory while the server restarts (it did, on a loaded machine), so each crash finds it running
        server = Server(url, tmp_path / "server.log", "--executor", "serial",
                        env={**LEASES, "FINALDRIVE_MAX_BACKLOG_ROWS": "40"}).start()
        try:
            job_id = server.client.post("/v1/jobs", json=DURABLE_DE).json()["id"]
            for crash in range(3):  # each once generations 5, 10, 15 of 61 are stored
                deadline = time.monotonic() + 120
                while True:
                    count, state = -1, None
                    with contextlib.suppress(Exception):  # the server is recovering from the last crash
                        count, state = rows(url, "SELECT (SELECT count(*) FROM generations WHERE job_id = :j), "
                                            "(SELECT state FROM jobs WHERE id = :j)", j=job_id)[0]
                    assert state not in TERMINAL, f"the job ended before crash {crash + 1}"
                    if count >= 5 * (crash + 1):
                        break
                    assert time.monotonic() < deadline and server.alive(), (tmp_path / "server.log").read_text()
                    time.sleep(0.01)
                postgres.crash(kill=kill)
            done = _wait_through_outages(server, job_id)
        finally:
            server.terminate()
        assert done["state"] == "succeeded" and done["total"] == 2 * 10 * 61
        assert done["done"] + done["failed"] == done["total"]
        assert stored(url, job_id) == expected
    finally:
        postgres.stop()


def _wait_through_outages(server: Server, job_id: int, timeout: float = 300) -> dict[str, Any]:
    """The job once finished, asking again while the store is down."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with contextlib.suppress(Exception):
            job = server.client.get(f"/v1/jobs/{job_id}").json()
            if job.get("state") in TERMINAL:
                return dict(job)
        time.sleep(0.2)
    raise AssertionError(f"job {job_id} did not finish within {timeout} s")
