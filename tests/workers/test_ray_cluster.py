"""Joining an existing cluster as a user would: a Ray head and a client, each its own process.

The head gets its own --temp-dir, so no other ``ray.init()`` on this machine finds it, and
it is stopped by signalling its own process: ``ray stop`` would kill every Ray process on
the machine, including other test modules' and other users' clusters. Token authentication
is on, with a token of its own (``RAY_AUTH_TOKEN``): Ray 2.60 never enables it by itself
for an explicit address, so a client of a token cluster sets ``RAY_AUTH_MODE=token``. Ray
reads these variables when it is imported, so the client runs in a fresh process, and this
test process's environment is left untouched.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from finaldrive.service.machine import free_port

pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]


def processes_under(temp_dir: str) -> list[psutil.Process]:
    found = []
    for proc in psutil.process_iter(["cmdline"]):
        if any(temp_dir in part for part in proc.info["cmdline"] or ()):
            found.append(proc)
    return found


def _without_native_frames(stderr: str) -> str:
    """A failed Ray client's stderr without the C++ stack's frames, which would hide Ray's message."""
    return "\n".join(line for line in stderr.splitlines() if not re.search(r"\[0x[0-9a-f]+\]", line))


CLIENT = """
import json, os, ray
from tests.workers import toyfns
from tests.workers.streams import results as run
from finaldrive.service.machine import free_port
from finaldrive.workers import make_executor
with make_executor("ray") as executor:
    gcs = ray.get_runtime_context().gcs_address
    results = run(executor, toyfns.pid, [[i] for i in range(6)])
    print(json.dumps({"gcs": gcs, "num_workers": executor.num_workers, "driver": os.getpid(),
                      "results": results}))
print(json.dumps({"still_initialized": ray.is_initialized()}))
"""


@pytest.fixture
def cluster_env() -> dict[str, str]:
    """Environment of the head and its clients: the repo importable, a fresh auth token."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    return env


@pytest.fixture
def ray_head(cluster_env: dict[str, str]) -> Iterator[str]:
    """Start ``ray start --head --block`` on 127.0.0.1 and a free port; yield its address."""
    temp_dir = tempfile.mkdtemp(prefix="fdray", dir="/tmp")   # short: Ray's socket paths
    port = free_port()
    log = Path(temp_dir) / "head.log"
    with open(log, "w") as out:
        head = subprocess.Popen(
            [sys.executable, "-m", "ray.scripts.scripts", "start", "--head", "--block",
             "--node-ip-address=127.0.0.1", f"--port={port}", "--num-cpus=2",
             "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp_dir}"],
            cwd=REPO, env=cluster_env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
        )
    try:
        deadline = time.monotonic() + 60
        while "block forever" not in log.read_text():
            assert head.poll() is None, f"ray head exited:\n{log.read_text()}"
            assert time.monotonic() < deadline, f"ray head did not start:\n{log.read_text()}"
            time.sleep(0.2)
        yield f"127.0.0.1:{port}"
        assert head.poll() is None, "the client's close() must not stop the cluster"
    finally:
        head.send_signal(signal.SIGTERM)          # the head stops the processes it started
        try:
            head.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait(10)
        for proc in processes_under(temp_dir):   # stragglers of this head only
            proc.kill()
        shutil.rmtree(temp_dir, ignore_errors=True)


@pytest.mark.cluster   # a cluster of its own: beside another test's, a client failed to start (CI, Ray 2.40)
def test_ray_executor_joins_cluster_from_ray_address(ray_head: str, cluster_env: dict[str, str]) -> None:
    client = subprocess.run(
        [sys.executable, "-c", CLIENT], cwd=REPO, env={**cluster_env, "RAY_ADDRESS": ray_head},
        capture_output=True, text=True, timeout=120,
    )
    assert client.returncode == 0, _without_native_frames(client.stderr)[-4000:]
    run, closed = (json.loads(line) for line in client.stdout.strip().splitlines()[-2:])
    assert run["gcs"].endswith(":" + ray_head.rsplit(":", 1)[1])
    assert run["num_workers"] == 2                            # the cluster's CPUs
    assert sorted(map(int, run["results"])) == list(range(6))
    assert run["driver"] not in run["results"].values()       # ran in the cluster's workers
    assert closed == {"still_initialized": False}
