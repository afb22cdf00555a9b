"""Process-pool lifecycle: orphaned workers exit, one stream at a time, warm-up, multi-road streams."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import finaldrive.workers.evaluate as evaluate
from finaldrive.engine.api import SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.workers import evaluate_roads_stream
from finaldrive.workers.process import ProcessExecutor
from finaldrive.workers.serial import SerialExecutor
from tests.workers import toyfns

REPO = Path(__file__).resolve().parents[2]

PARENT = """
import sys, time
from tests.workers import toyfns
from finaldrive.workers.process import ProcessExecutor
executor = ProcessExecutor(num_workers=2)
stream = executor.map_batches(toyfns.sleep_then_add, [[i] for i in range(4)], shared=(60.0,))
import threading
threading.Thread(target=lambda: list(stream), daemon=True).start()
while len(executor.worker_pids()) < 2:
    time.sleep(0.05)
time.sleep(1.0)                                   # workers initialised and inside their batches
print(" ".join(str(pid) for pid in executor.worker_pids()), flush=True)
time.sleep(120)
"""


def alive(pid: int) -> bool:
    """Running (a zombie waiting for a reaper counts as gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")
def test_workers_exit_when_the_parent_is_killed() -> None:
    parent = subprocess.Popen([sys.executable, "-c", PARENT], cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        pids = [int(p) for p in parent.stdout.readline().split()]
        assert len(pids) == 2 and all(alive(p) for p in pids)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + 5.0
        while any(alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(alive(p) for p in pids), "orphaned workers still running"
    finally:
        parent.kill()


def test_one_stream_at_a_time() -> None:
    with ProcessExecutor(num_workers=1) as executor:
        first = executor.map_batches(toyfns.add, [[1], [2]])
        next(first)
        with pytest.raises(RuntimeError, match="one map_batches stream at a time"):
            next(executor.map_batches(toyfns.add, [[3]]))
        first.close()
        assert dict(executor.map_batches(toyfns.add, [[3]])) == {0: [3]}


def test_warm_up_simulates_briefly(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[float] = []
    monkeypatch.setattr(evaluate, "run_engine",
                        lambda d, road, settings, vehicle: calls.append(settings.duration) or toyfns.toy_result(d))
    evaluate.warm_up_engine((Road(),), SimSettings(), None)
    assert calls == [evaluate.WARM_UP_DURATION_S]


def test_roads_stream_maps_rows_back_to_each_road(monkeypatch: pytest.MonkeyPatch) -> None:
    """A batch may span roads; every (road, row) comes back once with its own road's scale."""
    scale = {Road(): 1.0, Road.parse("sine:0.04:3"): 2.0, Road.parse("bump:0.04:0.2"): 3.0}
    monkeypatch.setattr(evaluate, "run_engine",
                        lambda d, road, settings, vehicle: toyfns.toy_result(d, scale[road]))
    monkeypatch.setattr(evaluate, "warm_up_engine", lambda *shared: None)
    plan = [(road, toyfns.designs(n)) for road, n in zip(scale, (5, 0, 7), strict=True)]
    seen: dict[int, list[int]] = {0: [], 1: [], 2: []}
    for r, rows, result in evaluate_roads_stream(SerialExecutor(), plan, SimSettings(), batch_size=4):
        road, designs = plan[r]
        np.testing.assert_array_equal(result.designs, designs[rows])
        np.testing.assert_array_equal(result.distance_m, toyfns.toy_result(designs[rows], scale[road]).distance_m)
        seen[r].extend(rows.tolist())
    assert seen == {0: list(range(5)), 1: [], 2: list(range(7))}
