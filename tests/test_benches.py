"""The benches that docs/performance.md and docs/optimisation.md quote still run (a bench that no longer runs
leaves its figures unreproducible: bench_time_to_answer broke when the executors' submit took a keyword)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench"


@pytest.mark.slow
def test_time_to_answer_runs_through_the_real_scheduler_on_the_virtual_cluster(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(BENCH / "bench_time_to_answer.py"), "--roads", "sine:0.04:3",
                           "--cpus", "4", "--repeat", "1", "--workers", "1", "--json"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    median = json.loads(done.stdout)["by_cpus"]["4"]["median"]
    assert median["state"] == "succeeded" and median["roads_missed"] == [] and median["time_to_1mm_s"] > 0
