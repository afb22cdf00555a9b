"""A scheduler off the Ray cluster is refused at once, naming the rule (issue 30): Ray itself
waits 60 s for a raylet of that cluster on this machine, then fails with a ConnectionError."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from finaldrive.service.machine import free_port
from finaldrive.workers.cluster import NotOnCluster, check_on_cluster, local_gcs_addresses

pytest.importorskip("ray")


def test_addresses_without_a_node_here_are_refused_by_name() -> None:
    port = free_port()   # no Ray listens there, so no raylet of this machine names it
    assert all(not gcs.endswith(f":{port}") for gcs in local_gcs_addresses() or ())
    with pytest.raises(NotOnCluster, match=rf"127.0.0.1:{port}.*must run on the cluster's head or on a node"):
        check_on_cluster(f"127.0.0.1:{port}")
    with pytest.raises(NotOnCluster, match="Ray Client address"):
        check_on_cluster("ray://10.0.0.1:10001")
    check_on_cluster("auto")


@pytest.mark.slow
def test_finaldrive_scheduler_off_the_cluster_exits_within_5_s(tmp_path: Path) -> None:
    address = f"127.0.0.1:{free_port()}"
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "finaldrive.service.cli", "scheduler", "--executor", "ray",
                           "--db", f"sqlite:///{tmp_path / 'store.db'}"],
                          env={"PATH": "/usr/bin:/bin", "RAY_ADDRESS": address, "HOME": str(tmp_path)},
                          capture_output=True, text=True, timeout=60)
    took = time.monotonic() - start
    assert done.returncode == 2, done.stderr[-3000:]
    assert f"cannot join the Ray cluster at {address}" in done.stderr and "Traceback" not in done.stderr
    assert took < 5.0, took
