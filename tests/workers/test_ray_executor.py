"""Ray executor on one small local Ray shared by this module (num_cpus=2)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray")

from finaldrive import workers
from finaldrive.engine.api import BatchResult, SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.workers import make_executor
from finaldrive.workers.evaluate import run_engine_on_roads
from finaldrive.workers.serial import SerialExecutor
from tests.workers import toyfns
from tests.workers.streams import results, run_batches
from tests.workers.test_executors import assert_same

pytestmark = pytest.mark.slow

try:
    from finaldrive.engine import evaluate as engine_evaluate
except ImportError:
    engine_evaluate = None


@pytest.fixture(scope="module")
def ray_executor() -> Iterator[workers.Executor]:
    with pytest.MonkeyPatch.context() as env:
        env.delenv("RAY_ADDRESS", raising=False)   # start a local Ray, never join another
        executor = make_executor("ray", num_workers=2, max_retries=2)
    with executor:
        yield executor
    import ray

    assert not ray.is_initialized()


def test_every_batch_comes_back_once(ray_executor: workers.Executor) -> None:
    assert ray_executor.num_workers == 2
    batches = [list(range(i, i + 3)) for i in range(0, 30, 3)]
    expected = {i: [x + 100 for x in b] for i, b in enumerate(batches)}
    assert results(ray_executor, toyfns.add, batches, (100,)) == expected


def test_results_come_back_before_the_last_batch_finishes(ray_executor: workers.Executor) -> None:
    arrivals: list[float] = []
    run_batches(ray_executor, toyfns.sleep_then_add, [[i] for i in range(6)], (0.3,), arrivals=arrivals)
    assert arrivals[0] < arrivals[-1] - 0.4


def test_identical_results_serial_and_ray(ray_executor: workers.Executor) -> None:
    designs = toyfns.designs(30)

    def run(executor: workers.Executor) -> BatchResult:
        parts = results(executor, toyfns.toy_result, [designs[i:i + 7] for i in range(0, 30, 7)], (3.0,))
        return BatchResult.concat(list(parts.values()))

    assert_same(run(SerialExecutor()), run(ray_executor))


def test_task_error_propagates_unretried(ray_executor: workers.Executor) -> None:
    with pytest.raises(ValueError, match="bug in task"):
        results(ray_executor, toyfns.raise_value_error, [[1]])


def test_killed_worker_batch_is_evaluated_exactly_once(ray_executor: workers.Executor, tmp_path: Path) -> None:
    """A Ray worker exits in the middle of a batch; Ray retries it; every design appears once."""
    designs = toyfns.designs(24)
    marked = designs[9, 0]                         # batch 2 (rows 8-11), third design
    log = tmp_path / "evaluated.log"
    shared = (marked, str(tmp_path / "crashed"), str(log))
    parts = results(ray_executor, toyfns.crash_once, [designs[i:i + 4] for i in range(0, 24, 4)], shared)
    assert (tmp_path / "crashed").exists() and sorted(parts) == list(range(6))
    assert_same(BatchResult.concat(list(parts.values())), toyfns.toy_result(designs))
    evaluated = [float(a2) for a2 in log.read_text().split()]
    assert evaluated.count(designs[8, 0]) == 2      # evaluated before the crash, then again


def test_worker_lost_after_max_retries(ray_executor: workers.Executor) -> None:
    assert run_batches(ray_executor, toyfns.always_crash, [[1]])[0].lost


@pytest.mark.skipif(engine_evaluate is None, reason="finaldrive.engine.evaluate is not importable yet")
def test_real_engine_identical_across_executors(ray_executor: workers.Executor) -> None:
    designs = np.array([[np.pi / 4, 0.10, 0.08], [np.pi, 0.05, 0.10], [1.5 * np.pi, 0.15, 0.12]])
    road, settings = Road.parse("sine:0.04:3"), SimSettings(duration=0.2)
    rows = [np.column_stack([np.zeros(len(part)), part]) for part in (designs[:2], designs[2:])]  # road 0

    def run(executor: workers.Executor) -> BatchResult:  # the workers' task, two tasks
        parts = results(executor, run_engine_on_roads, rows, ((road,), settings, None))
        return BatchResult.concat([batch for i in sorted(parts) for _, batch in parts[i]])

    serial = run(SerialExecutor())
    assert len(serial) == 3
    with make_executor("process", num_workers=2) as pool:
        assert_same(serial, run(pool))
    assert_same(serial, run(ray_executor))


def test_a_wide_task_holds_its_cpus_and_returns_the_engine_s_results(ray_executor: workers.Executor) -> None:
    """``task_cpus=2`` on the 2-CPU Ray: one task at a time, holding both CPUs (Ray would run two 1-CPU
    tasks at once), told to its body, whose designs then run on two threads with the serial results."""
    from finaldrive.workers.ray_executor import RayExecutor

    designs = np.array([[np.pi / 4, 0.10, 0.08], [np.pi, 0.05, 0.10], [1.5 * np.pi, 0.15, 0.12], [0.3, 0.0, 0.09]])
    road, settings = Road.parse("sine:0.04:3"), SimSettings(duration=0.2)
    rows = [np.column_stack([np.zeros(len(designs)), designs])]
    with RayExecutor(task_cpus=2) as wide:   # on the module's Ray
        assert (wide.task_cpus, wide.num_workers, wide.capacity) == (2, 1, 2)
        assert list(results(wide, toyfns.cpus_held, [None]).values()) == [2]
        [(road_index, batch)] = results(wide, run_engine_on_roads, rows, ((road,), settings, None))[0]
    assert list(results(ray_executor, toyfns.cpus_held, [None]).values()) == [1]
    serial = run_engine_on_roads(rows[0], (road,), settings, None)[0][1]
    assert road_index == 0 and len(serial) == 4
    assert_same(serial, batch)
    with pytest.raises(ValueError, match="task_cpus 3 is more than any node's CPUs"):
        RayExecutor(task_cpus=3)
