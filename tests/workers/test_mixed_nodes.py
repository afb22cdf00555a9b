"""Issue 30: the same answer from every node. A two-node Ray cluster on this machine, one node
computing as a CPU without AVX2 and FMA would (glibc's libm variants and OpenBLAS's kernels chosen
by ``GLIBC_TUNABLES`` and ``OPENBLAS_CORETYPE``), a PostgreSQL store and ``finaldrive serve`` on it:
a seeded DE and a sweep through the API equal, bit for bit, the same runs in this process (the
serial order, this machine's own libm). Before engine.model.libm, 59 of 648 sweep rows and the DE's
optimum differed on such a cluster.
"""

from __future__ import annotations

import math
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from finaldrive.engine import DIAGNOSTICS, evaluate
from finaldrive.service.jobs.plan import build_plan
from finaldrive.service.machine import free_port
from finaldrive.service.schemas import JobSpec
from tests.engine.test_libm import OTHER_CPU
from tests.service.processes import Server
from tests.service.svc_helpers import wait_done
from tests.workers.test_ray_cluster import processes_under

pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
SIM = {"duration": 1.5}
SWEEP = {"kind": "sweep", "roads": ["sine:0.04:3"],
         "grid": "a2_deg=0:355:5,l2_m=0.04|0.07|0.1|0.13,rws_m=0.05|0.07|0.09|0.11", "settings": SIM}
DE = {"kind": "de", "roads": ["sine:0.04:2"], "de": {"np": 8, "iters": 5}, "seed": 13, "settings": SIM}


def distinct_free_ports(n: int, taken: set[int]) -> list[int]:
    """``n`` ports free on 127.0.0.1 now, distinct from each other and from ``taken`` (two calls of free_port
    may give the same port: Ray then refuses to start, "port ... used by other components")."""
    out: list[int] = []
    while len(out) < n:
        port = free_port()
        if port not in taken and port not in out:
            out.append(port)
    return out


def start_node(args: list[str], env: dict[str, str], temp_dir: str, name: str) -> subprocess.Popen[bytes]:
    log = Path(temp_dir) / f"{name}.log"
    taken = {int(arg.rsplit(":", 1)[1] if arg.startswith("--address=") else arg.split("=", 1)[1])
             for arg in args if arg.startswith(("--port=", "--address="))}
    flags = ("--node-manager-port", "--object-manager-port", "--metrics-export-port", "--dashboard-agent-listen-port",
             "--dashboard-agent-grpc-port", "--runtime-env-agent-port")
    ports = [f"{flag}={port}" for flag, port in zip(flags, distinct_free_ports(len(flags), taken), strict=True)]
    with open(log, "w") as out:
        node = subprocess.Popen([sys.executable, "-m", "ray.scripts.scripts", "start", "--block", *args, *ports,
                                 "--node-ip-address=127.0.0.1", "--num-cpus=1", "--disable-usage-stats",
                                 f"--temp-dir={temp_dir}"],
                                cwd=REPO, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + 90
    while "block forever" not in log.read_text():
        assert node.poll() is None, f"ray {name} exited:\n{log.read_text()}"
        assert time.monotonic() < deadline, f"ray {name} did not start:\n{log.read_text()}"
        time.sleep(0.2)
    return node


def stop_node(node: subprocess.Popen[bytes], temp_dir: str) -> None:
    node.send_signal(signal.SIGTERM)
    try:
        node.wait(30)
    except subprocess.TimeoutExpired:
        os.killpg(node.pid, signal.SIGKILL)
        node.wait(10)
    for proc in processes_under(temp_dir):
        proc.kill()
    shutil.rmtree(temp_dir, ignore_errors=True)


@pytest.fixture
def mixed_cluster() -> Iterator[tuple[str, dict[str, str]]]:
    """(address, the clients' environment): a head of 1 CPU and a node of 1 CPU under OTHER_CPU,
    token authentication on."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    head_dir = tempfile.mkdtemp(prefix="fdh", dir="/tmp")
    other_dir = tempfile.mkdtemp(prefix="fdo", dir="/tmp")
    address = f"127.0.0.1:{free_port()}"
    head = start_node(["--head", f"--port={address.rsplit(':', 1)[1]}", "--include-dashboard=false"], env,
                       head_dir, "head")
    other = None
    try:
        other = start_node([f"--address={address}"], {**env, **OTHER_CPU}, other_dir, "other")
        yield address, env
    finally:
        if other is not None:
            stop_node(other, other_dir)
        stop_node(head, head_dir)


def _other_cpu_workers_cpu_s() -> float:
    """User CPU seconds of the Ray worker processes on this machine (Ray names them ``ray::<task>`` or
    ``ray::IDLE``) that run under OTHER_CPU. Other tests' workers come and go beside this one (pytest-xdist):
    one that exits while it is read is skipped."""
    busy = 0.0
    for proc in psutil.process_iter(["name", "cmdline"]):
        words = " ".join(proc.info["cmdline"] or ())
        if not (((proc.info["name"] or "").startswith("ray::") and "Agent" not in words)
                or "default_worker.py" in words):
            continue
        try:
            if proc.environ().get("GLIBC_TUNABLES") == OTHER_CPU["GLIBC_TUNABLES"]:
                busy += proc.cpu_times().user
        except (psutil.NoSuchProcess, psutil.AccessDenied):   # ZombieProcess is a NoSuchProcess
            continue
    return busy


def _items(client: Any, job_id: int) -> list[dict[str, Any]]:
    items = client.get(f"/v1/jobs/{job_id}/evaluations", params={"limit": 10_000}).json()["items"]
    return sorted(items, key=lambda e: (e["step"], e["candidate"]))


def _assert_same_bits(item: dict[str, Any], batch: Any, i: int) -> None:
    assert (item["status"], item["reason"]) == (batch.status[i], batch.reason[i])
    assert [math.radians(item["a2_deg"]), item["l2_m"], item["rws_m"]] == pytest.approx(batch.designs[i].tolist(),
                                                                                        rel=1e-15)
    for name in ("distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m", *DIAGNOSTICS):
        value = float(getattr(batch, name)[i])
        assert item[name] == (value if math.isfinite(value) else None), name


@pytest.mark.cluster   # two Ray nodes of its own: no other test's cluster beside it
def test_a_seeded_de_and_a_sweep_on_a_mixed_cluster_equal_the_serial_run(
        mixed_cluster: tuple[str, dict[str, str]], postgres: Any, tmp_path: Path) -> None:
    address, env = mixed_cluster
    server = Server(str(postgres.new_database()), tmp_path / "server.log", "--executor", "ray",
                    env={**env, "RAY_ADDRESS": address}).start()
    try:
        client = server.client
        ids = [client.post("/v1/jobs", json=spec).json()["id"] for spec in (SWEEP, DE)]

        sweep_plan = build_plan(JobSpec.model_validate(SWEEP).normalised())
        assert sweep_plan.study.designs is not None
        sweep = evaluate(sweep_plan.study.designs, sweep_plan.study.roads[0].road, sweep_plan.settings)
        de_plan = build_plan(JobSpec.model_validate(DE).normalised())
        study = de_plan.study
        assert study.de is not None and study.bounds is not None
        de = study.de.build(study.bounds, study.seed)
        rounds = []
        while not de.done:   # the serial order, in this process
            batch = evaluate(de.ask(), study.roads[0].road, de_plan.settings)
            rounds.append(batch)
            de.tell(batch.fitness_m)

        jobs = [wait_done(client, job_id, timeout=300, poll=0.2) for job_id in ids]
        assert [job["state"] for job in jobs] == ["succeeded", "succeeded"], jobs
        items = _items(client, ids[0])
        assert [e["candidate"] for e in items] == list(range(len(sweep_plan.study.designs)))
        for i, item in enumerate(items):
            _assert_same_bits(item, sweep, i)
        items = _items(client, ids[1])
        assert len(items) == sum(len(b.status) for b in rounds) == de.n_evals
        for item in items:
            _assert_same_bits(item, rounds[item["step"]], item["candidate"])
        best = client.get(f"/v1/jobs/{ids[1]}/best").json()["roads"][0]["best"]
        assert best["fitness_m"] == de.best_f
        # the other-CPU node computed its share: its workers (alive while the scheduler is, the only
        # ones with its environment) took CPU time
        busy = _other_cpu_workers_cpu_s()
        assert busy > 0.3, f"the other node's workers used {busy:.2f} s of CPU"
    finally:
        server.terminate()
