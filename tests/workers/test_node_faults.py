"""Issue 30: nodes that join cold or die in the middle of a DE, on a two-node Ray cluster on this
machine with a PostgreSQL store and ``finaldrive serve``.

- A node whose numba cache is empty joins mid-DE: its workers compile the engine once for the node
  (workers/evaluate.py, engine/precompile.py) while the tasks they hold run again on the warm node
  (workers/dispatch.py, hedging): no generation waits more than 5 s longer than its neighbours.
- A node SIGKILLed mid-DE (its raylet and workers at once): Ray takes ~15 s to declare it dead, but
  its tasks run again elsewhere after about a second; the job ends with the serial run's results,
  bit for bit, and no generation waits more than 5 s longer than its neighbours.
"""

from __future__ import annotations

import itertools
import os
import secrets
import signal
import statistics
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import create_engine, text

from finaldrive.engine import evaluate
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.machine import free_port
from finaldrive.service.schemas import JobSpec
from tests.service.processes import Server
from tests.service.svc_helpers import wait_done
from tests.workers.test_mixed_nodes import REPO, _assert_same_bits, _items, start_node, stop_node
from tests.workers.test_ray_cluster import processes_under

pytest.importorskip("ray")
pytest.importorskip("psutil")

pytestmark = pytest.mark.slow

#: a DE of 120 generations (no convergence stop), each ~0.1 s on this machine's 2 cores; not so
#: long that its designs come within the result cache's 1e-12 of each other (a cached neighbour's
#: result is not the serial run's)
DE = {"kind": "de", "roads": ["sine:0.04:2"], "de": {"np": 24, "iters": 120, "patience": None}, "seed": 21,
      "settings": {"duration": 3.5}}
#: a generation may take this much longer than the median one [s] (the issue's acceptance)
STALL_S = 5.0


class Cluster:
    """A head of 1 CPU; nodes of 1 CPU added and killed by the test; token authentication on."""

    def __init__(self) -> None:
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
        self.env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), self.env.get("PYTHONPATH")]))
        self.env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
        self.address = f"127.0.0.1:{free_port()}"
        self.nodes: list[tuple[Any, str]] = []
        self.add(["--head", f"--port={self.address.rsplit(':', 1)[1]}", "--include-dashboard=false"], "head")

    def add(self, args: list[str] | None = None, name: str = "node", **env: str) -> tuple[Any, str]:
        temp_dir = tempfile.mkdtemp(prefix="fdf", dir="/tmp")
        node = start_node(args or [f"--address={self.address}"], {**self.env, **env}, temp_dir, name)
        self.nodes.append((node, temp_dir))
        return node, temp_dir

    def close(self) -> None:
        for node, temp_dir in reversed(self.nodes):
            stop_node(node, temp_dir)


@pytest.fixture
def cluster() -> Iterator[Cluster]:
    made = Cluster()
    try:
        yield made
    finally:
        made.close()


def generation_gaps(db_url: str, job_id: int) -> list[float]:
    """Seconds between the stored generations of the job's run, in order."""
    engine = create_engine(db_url)
    with engine.connect() as connection:
        times = list(connection.execute(text("SELECT created_at FROM generations WHERE job_id = :job "
                                             "ORDER BY generation"), {"job": job_id}).scalars())
    engine.dispose()
    return [(b - a).total_seconds() for a, b in itertools.pairwise(times)]


def _serial_rounds(spec: dict[str, Any]) -> tuple[list[Any], Any]:
    plan = build_plan(JobSpec.model_validate(spec).normalised())
    study = plan.study
    assert study.de is not None and study.bounds is not None
    de = study.de.build(study.bounds, study.seed)
    rounds = []
    while not de.done:
        batch = evaluate(de.ask(), study.roads[0].road, plan.settings)
        rounds.append(batch)
        de.tell(batch.fitness_m)
    return rounds, de


def _run_de(cluster: Cluster, db_url: str, log: Path, spec: dict[str, Any], during: Any) -> tuple[Any, list[float]]:
    """Run the DE ``spec`` through ``finaldrive serve`` on the cluster; ``during()`` once 20 generations
    are stored. Returns (the job's evaluations, seconds between its stored generations)."""
    server = Server(db_url, log, "--executor", "ray", env={**cluster.env, "RAY_ADDRESS": cluster.address}).start()
    try:
        client = server.client
        job_id = client.post("/v1/jobs", json=spec).json()["id"]
        deadline = time.monotonic() + 120
        while client.get(f"/v1/jobs/{job_id}").json()["done"] < 20 * spec["de"]["np"]:
            assert time.monotonic() < deadline, "the DE did not start:\n" + log.read_text()[-3000:]
            time.sleep(0.1)
        during()
        job = wait_done(client, job_id, timeout=600, poll=0.2)
        assert job["state"] == "succeeded", job
        items = _items(client, job_id)
    finally:
        server.terminate()
    return items, generation_gaps(db_url, job_id)


def _assert_no_stall(gaps: list[float]) -> None:
    """No generation stored more than STALL_S after the one before, beyond the mean gap (generations
    are stored a flush at a time, every 0.25 s: a median gap would be 0)."""
    usual = statistics.mean(gaps)
    assert max(gaps) <= usual + STALL_S, f"a generation waited {max(gaps):.2f} s against the usual {usual:.2f} s"


@pytest.mark.cluster   # Ray nodes of its own: no other test's cluster beside it
def test_a_node_with_an_empty_cache_joining_mid_de_stalls_no_generation(
        cluster: Cluster, postgres: Any, tmp_path: Path) -> None:
    cold_cache = tmp_path / "numba-cache"
    cold_cache.mkdir()

    def join() -> None:
        """Start the cold node, and wait until one of its workers begins compiling the engine into the
        node's own cache (one for all: tests/engine/test_compiled.py::test_of_many_callers_at_once_one_compiles)."""
        cluster.add(NUMBA_CACHE_DIR=str(cold_cache))
        deadline = time.monotonic() + 60
        while not {"compiling-fast", "compiled-fast"} & set(os.listdir(cold_cache)):
            assert time.monotonic() < deadline, f"the cold node got no work: {os.listdir(cold_cache)}"
            time.sleep(0.1)

    # longer than DE, and not compared with the serial run: its converged designs come within the
    # result cache's 1e-12 of each other
    spec = {**DE, "de": {**DE["de"], "iters": 400}}
    _, gaps = _run_de(cluster, str(postgres.new_database()), tmp_path / "server.log", spec, join)
    _assert_no_stall(gaps)


@pytest.mark.cluster   # Ray nodes of its own: no other test's cluster beside it
def test_a_node_killed_mid_de_stalls_no_generation_and_changes_nothing(
        cluster: Cluster, postgres: Any, tmp_path: Path) -> None:
    node, temp_dir = cluster.add()

    def kill() -> None:
        for proc in processes_under(temp_dir):   # the raylet, its workers and agents, at once
            proc.send_signal(signal.SIGKILL)
        os.killpg(node.pid, signal.SIGKILL)

    items, gaps = _run_de(cluster, str(postgres.new_database()), tmp_path / "server.log", DE, kill)
    _assert_no_stall(gaps)
    rounds, de = _serial_rounds(DE)
    assert len(items) == sum(len(b.status) for b in rounds) == de.n_evals
    for item in items:
        _assert_same_bits(item, rounds[item["step"]], item["candidate"])
