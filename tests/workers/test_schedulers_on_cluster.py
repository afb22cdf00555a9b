"""Issue 30: several schedulers on one PostgreSQL store and one Ray cluster (two nodes on this machine).

One scheduler drives a Ray cluster; a second one on it waits as a standby (Ray keeps a pool of
workers per driver, and two drivers filling the same CPUs evict each other's workers: 13 worker
restarts in 3.4 min before). Four jobs with one scheduler, then four beside a standby: all succeed,
each evaluation stored once; the standby's Ray job starts no worker, and the first's starts none
beyond its copies of overdue tasks.
SIGKILLed, the first scheduler leaves no process behind, and the standby's results flow within a
lease plus 10 s.
"""

from __future__ import annotations

import os
import secrets
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from finaldrive.service.machine import free_port
from tests.service.processes import Proc, Server
from tests.service.svc_helpers import wait_done
from tests.workers.test_mixed_nodes import REPO, start_node, stop_node

pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")

pytestmark = pytest.mark.slow

SIM = {"duration": 1.0}
LEASE_S = 5.0
JOBS = [
    {"kind": "sweep", "roads": ["sine:0.04:3"], "grid": "a2_deg=0:350:10,l2_m=0.05|0.1,rws_m=0.07|0.09",
     "settings": SIM},
    {"kind": "de", "roads": ["sine:0.04:2"], "de": {"np": 8, "iters": 4}, "seed": 3, "settings": SIM},
    {"kind": "sweep", "roads": ["flat"], "grid": "a2_deg=0:350:10,l2_m=0.05|0.1,rws_m=0.07|0.09",
     "settings": SIM},
    {"kind": "de", "roads": ["flat"], "de": {"np": 8, "iters": 4}, "seed": 5, "settings": SIM},
]
#: a job long enough to SIGKILL its scheduler in the middle: 5,760 simulations of 3.5 s, ~15 s on 2
#: cores (with SIM's 1 s and one road it ended within a second on CI, before the kill)
LONG = {"kind": "sweep", "roads": ["sine:0.04:3", "sine:0.04:2"],
        "grid": "a2_deg=0:359:1,l2_m=0.04|0.07|0.1|0.13,rws_m=0.07|0.09", "settings": {"duration": 3.5}}


@pytest.fixture
def cluster() -> Iterator[tuple[str, dict[str, str], list[str]]]:
    """(address, the clients' environment, the nodes' temp dirs): a head and a node of 1 CPU each."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    dirs = [tempfile.mkdtemp(prefix="fds", dir="/tmp") for _ in range(2)]
    address = f"127.0.0.1:{free_port()}"
    nodes = [start_node(["--head", f"--port={address.rsplit(':', 1)[1]}", "--include-dashboard=false"], env,
                        dirs[0], "head")]
    try:
        nodes.append(start_node([f"--address={address}"], env, dirs[1], "node"))
        yield address, env, dirs
    finally:
        for node, temp_dir in zip(reversed(nodes), reversed(dirs[:len(nodes)]), strict=True):
            stop_node(node, temp_dir)


def worker_starts(dirs: list[str]) -> dict[str, int]:
    """Ray worker processes started on the nodes so far, by Ray job id where the log's name carries it
    (``ffffffff``: started ahead of any job; Ray 2.40 names every log so): one ``worker-*.err`` each
    (read in the sessions' own folders, not again through the ``session_latest`` link)."""
    starts: dict[str, int] = {}
    for d in dirs:
        for log in Path(d).glob("session_*/logs/worker-*.err"):
            if not log.parents[1].is_symlink():
                job = log.stem.split("-")[2]
                starts[job] = starts.get(job, 0) + 1
    return starts


def _hedges(proc: Proc) -> int:
    """Copies of overdue tasks the scheduler has started so far (``workers/dispatch.py`` logs each one):
    a copy is of a scheduling class of its own, so Ray may start a worker for it."""
    return proc.log.read_text().count("running it again")


def _scheduler(name: str, db_url: str, address: str, env: dict[str, str], log: Path) -> Proc:
    return Proc(["scheduler", "--db", db_url, "--executor", "ray", "--id", name], log,
                env={**env, "RAY_ADDRESS": address, "FINALDRIVE_LEASE_SECONDS": str(LEASE_S)}).start()


def _stored_once(client: Any, job: dict[str, Any]) -> None:
    items = client.get(f"/v1/jobs/{job['id']}/evaluations", params={"limit": 10_000}).json()["items"]
    keys = [(e["road_index"], e["step"], e["candidate"]) for e in items]
    assert len(keys) == len(set(keys)) == job["done"] + job["failed"] > 0, job


def _wait_log(proc: Proc, text: str, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while text not in proc.log.read_text():
        assert proc.alive(), proc.log.read_text()[-3000:]
        assert time.monotonic() < deadline, f"{text!r} not in {proc.log}:\n{proc.log.read_text()[-3000:]}"
        time.sleep(0.2)


@pytest.mark.cluster   # Ray nodes of its own: no other test's cluster beside it
def test_a_second_scheduler_waits_as_a_standby_and_takes_over(
        cluster: tuple[str, dict[str, str], list[str]], postgres: Any, tmp_path: Path) -> None:
    address, env, dirs = cluster
    db_url = str(postgres.new_database())
    api = Server(db_url, tmp_path / "api.log", "--no-scheduler").start()
    first = second = None
    try:
        client = api.client
        first = _scheduler("first", db_url, address, env, tmp_path / "first.log")
        _wait_log(first, "scheduler first starting", 120)
        # four jobs with one scheduler, then four more beside a standby: the standby starts no Ray
        # worker and evicts none of the first's (two drivers evicted each other's 13 times in 3.4 min)
        starts, hedges = [], []
        for seed_shift in (0, 100):
            if seed_shift:
                second = _scheduler("second", db_url, address, env, tmp_path / "second.log")
                _wait_log(second, "waiting as a standby", 60)
                assert "one scheduler per Ray cluster" in second.log.read_text()
            specs = [{**spec, "seed": spec["seed"] + seed_shift} if "seed" in spec else
                     {**spec, "settings": {**SIM, "duration": SIM["duration"] + seed_shift / 1000}} for spec in JOBS]
            ids = [client.post("/v1/jobs", json=spec).json()["id"] for spec in specs]
            jobs = [wait_done(client, job_id, timeout=300, poll=0.2) for job_id in ids]
            assert [job["state"] for job in jobs] == ["succeeded"] * 4, jobs
            for job in jobs:
                _stored_once(client, job)
            starts.append(worker_starts(dirs))
            hedges.append(_hedges(first))
        # the first's own workers: none started anew but for its copies of overdue tasks (a loaded CI machine
        # makes some); the standby's Ray job: none at all
        ours = set(starts[0]) - {"ffffffff"}
        added = {job: n - starts[0].get(job, 0) for job, n in starts[1].items() if n != starts[0].get(job, 0)}
        said = f"Ray workers started, by Ray job: {starts[0]} with one scheduler, {starts[1]} with two; " \
               f"copies of overdue tasks in the second round: {hedges[1] - hedges[0]}"
        assert not set(added) - ours, said
        assert sum(added.values()) <= hedges[1] - hedges[0], said
        health = client.get("/v1/health").json()
        assert [s["id"] for s in health["schedulers"]] == ["first"]   # the standby has not registered
        load = health["schedulers"][0]
        assert load["busy_share"] is not None and 0.0 <= load["busy_share"] <= 1.0
        assert load["in_flight_tasks"] is not None and load["backlog_designs"] is not None

        # SIGKILL the first mid-job: its children go with it; the standby takes over
        long_id = client.post("/v1/jobs", json=LONG).json()["id"]
        deadline = time.monotonic() + 120
        while client.get(f"/v1/jobs/{long_id}").json()["done"] < 200:
            assert time.monotonic() < deadline, "the long job did not start"
            time.sleep(0.1)
        children = first.descendants()
        first.kill()
        killed_at = time.monotonic()
        at_kill = client.get(f"/v1/jobs/{long_id}").json()
        done_at_kill = at_kill["done"]
        assert at_kill["state"] == "running", f"the long job ended before the kill: {at_kill}"
        gone = psutil.wait_procs(children, timeout=10)[1]
        assert not gone, f"the killed scheduler's processes outlived it: {[p.pid for p in gone]}"
        while client.get(f"/v1/jobs/{long_id}").json()["done"] <= done_at_kill + 10:
            assert time.monotonic() < killed_at + LEASE_S + 10, (
                "the standby's results did not flow within the lease + 10 s:\n" + second.log.read_text()[-3000:])
            time.sleep(0.1)
        job = wait_done(client, long_id, timeout=300, poll=0.2)
        assert job["state"] == "succeeded", job
        assert job["done"] + job["failed"] == 5760
        _stored_once(client, job)
    finally:
        for proc in (second, first):
            if proc is not None and proc.alive():
                proc.terminate()
        api.terminate()
