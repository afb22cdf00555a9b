"""Process-pool lifecycle: orphaned workers exit; the workers' task: warm-up, tasks spanning roads."""

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
from tests.workers import toyfns

REPO = Path(__file__).resolve().parents[2]

PARENT = """
import sys, time
from tests.workers import toyfns
from finaldrive.workers.process import ProcessExecutor
executor = ProcessExecutor(num_workers=2)
delay = executor.share(60.0)
for i in range(4):
    executor.submit(toyfns.sleep_then_add, [i], delay)
import threading
threading.Thread(target=lambda: executor.poll(300.0), daemon=True).start()
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


def test_warm_up_simulates_briefly(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[float] = []
    monkeypatch.setattr(evaluate, "run_engine",
                        lambda d, road, settings, vehicle: calls.append(settings.duration) or toyfns.toy_result(d))
    evaluate.warm_up_engine((Road(),), SimSettings(), None)
    assert calls == [evaluate.WARM_UP_DURATION_S]


def test_a_task_spanning_roads_runs_each_road_on_its_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """The workers' task: rows (road index, design) in runs of one road; each run is simulated on its
    own road and comes back in order with its road index."""
    scale = {Road(): 1.0, Road.parse("sine:0.04:3"): 2.0, Road.parse("bump:0.04:0.2"): 3.0}
    monkeypatch.setattr(evaluate, "run_engine",
                        lambda d, road, settings, vehicle: toyfns.toy_result(d, scale[road]))
    roads = tuple(scale)
    designs = toyfns.designs(9)
    index = np.array([0, 0, 0, 2, 2, 2, 2, 1, 1])
    out = evaluate.run_engine_on_roads(np.column_stack([index, designs]), roads, SimSettings(), None)
    assert [(road, len(batch)) for road, batch in out] == [(0, 3), (2, 4), (1, 2)]
    start = 0
    for road, batch in out:
        part = designs[start:start + len(batch)]
        np.testing.assert_array_equal(batch.designs, part)
        np.testing.assert_array_equal(batch.distance_m, toyfns.toy_result(part, scale[roads[road]]).distance_m)
        start += len(batch)
