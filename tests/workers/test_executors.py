"""Serial and process-pool executors."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from finaldrive import workers
from finaldrive.engine.api import BatchResult
from finaldrive.workers import make_executor
from finaldrive.workers.process import ProcessExecutor
from finaldrive.workers.serial import SerialExecutor
from finaldrive.workers.task import call_timed
from tests.workers import toyfns
from tests.workers.streams import results, run_batches


@pytest.fixture(scope="module")
def pool() -> Iterator[workers.Executor]:
    with make_executor("process", num_workers=2, max_retries=2) as executor:
        yield executor


def batches_of(n: int, size: int) -> list[list[int]]:
    return [list(range(i, min(n, i + size))) for i in range(0, n, size)]


def test_make_executor_kinds() -> None:
    assert isinstance(make_executor(), SerialExecutor)
    with make_executor("process", num_workers=3) as executor:
        assert isinstance(executor, ProcessExecutor) and executor.num_workers == 3
        assert isinstance(executor, workers.Executor)
    with pytest.raises(ValueError, match="unknown executor kind"):
        make_executor("threads")  # type: ignore[arg-type]


@pytest.fixture
def engine_compiling(monkeypatch: pytest.MonkeyPatch) -> Callable[[bool], None]:
    """Make make_executor see the engine compiled (True) or compiling for 0.5 s (False)."""
    import finaldrive.engine

    def set_compiled(compiled: bool) -> None:
        monkeypatch.setattr(finaldrive.engine, "is_compiled", lambda method: compiled)
        monkeypatch.setattr(finaldrive.engine, "compile_engine", lambda: lambda: 0.0 if compiled else time.sleep(0.5))
    return set_compiled


def test_while_the_engine_compiles_the_workers_start_numba_and_hide_those_tasks(
        engine_compiling: Callable[[bool], None], monkeypatch: pytest.MonkeyPatch) -> None:
    """Each worker's first task imports numba and starts its runtime: the first batches find it
    started; none of those tasks is reported to the executor's user."""
    engine_compiling(False)
    monkeypatch.setattr(workers, "WARM_UP_WAIT_S", 60.0)   # however slow the machine
    with make_executor("process", num_workers=2) as executor:
        assert executor.poll(0.2) == [] and executor.in_flight() == 0
        seen = dict(results(executor, toyfns.runtime_started, [None] * 4).values())
    assert len(seen) == 2 and all(seen.values())


def test_warm_up_tasks_not_done_in_time_are_cancelled_unseen(engine_compiling: Callable[[bool], None],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    engine_compiling(False)
    monkeypatch.setattr(workers, "WARM_UP_WAIT_S", 0.0)
    with make_executor("process", num_workers=2) as executor:
        assert executor.poll(0.2) == [] and executor.in_flight() == 0
        assert results(executor, toyfns.add, [[1], [2]], (10,)) == {0: [11], 1: [12]}


def test_with_the_engine_compiled_the_workers_start_nothing_beforehand(
        engine_compiling: Callable[[bool], None]) -> None:
    engine_compiling(True)
    with make_executor("process", num_workers=2) as executor:
        seen = dict(results(executor, toyfns.runtime_started, [None] * 2).values())
    assert not any(seen.values())


@pytest.mark.parametrize("kind", ["serial", "process"])
def test_every_batch_comes_back_once(kind: str, pool: workers.Executor) -> None:
    executor = SerialExecutor() if kind == "serial" else pool
    batches = batches_of(23, 4)
    assert results(executor, toyfns.add, batches, (100,)) == {i: [x + 100 for x in b] for i, b in enumerate(batches)}


def test_results_come_back_before_the_last_batch_finishes(pool: workers.Executor) -> None:
    arrivals: list[float] = []
    run_batches(pool, toyfns.sleep_then_add, [[i] for i in range(6)], (0.3,), arrivals=arrivals)
    assert arrivals[0] < arrivals[-1] - 0.4   # 6 x 0.3 s on 2 workers: >= 0.9 s in all


def test_shared_args_reach_each_worker_process_once(tmp_path: Path) -> None:
    log = tmp_path / "unpickled.log"
    with ProcessExecutor(num_workers=2) as executor:
        pids = set(results(executor, toyfns.uses_shared, batches_of(20, 1), (toyfns.LogOnUnpickle(str(log)),)).values())
    unpickled_in = log.read_text().split()
    assert len(unpickled_in) == len(set(unpickled_in)) <= 2
    assert pids <= set(map(int, unpickled_in))


def test_task_error_propagates_unretried(pool: workers.Executor) -> None:
    with pytest.raises(ValueError, match="bug in task"):
        results(pool, toyfns.raise_value_error, [[1], [2]])
    assert results(pool, toyfns.add, [[1]]) == {0: [1]}   # pool still usable


def test_identical_results_serial_and_process(pool: workers.Executor) -> None:
    designs = toyfns.designs(30)

    def run(executor: workers.Executor) -> BatchResult:
        parts = results(executor, toyfns.toy_result, [designs[i:i + 7] for i in range(0, 30, 7)], (3.0,))
        return BatchResult.concat(list(parts.values()))

    assert_same(run(SerialExecutor()), run(pool))


def assert_same(a: BatchResult, b: BatchResult) -> None:
    assert a.status == b.status and a.reason == b.reason
    for name in ("designs", "distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_warm_up_runs_once_per_process(tmp_path: Path) -> None:
    log = tmp_path / "warmup.log"
    with ProcessExecutor(num_workers=2) as executor:
        task = partial(call_timed, toyfns.pid, partial(toyfns.log_pid, str(log)))  # as the dispatcher's tasks
        pids = {timed.result for timed in results(executor, task, [[i] for i in range(12)]).values()}
    warmed = log.read_text().split()
    assert len(warmed) == len(set(warmed)) and set(map(int, warmed)) == pids


def test_killed_worker_batch_is_evaluated_exactly_once(tmp_path: Path) -> None:
    """A worker exits in the middle of a batch; the batch is rerun and every design appears once."""
    designs = toyfns.designs(24)
    marked = designs[9, 0]                         # batch 2 (rows 8-11), third design
    log = tmp_path / "evaluated.log"
    shared = (marked, str(tmp_path / "crashed"), str(log))
    with ProcessExecutor(num_workers=2, max_retries=2) as executor:
        parts = results(executor, toyfns.crash_once, [designs[i:i + 4] for i in range(0, 24, 4)], shared)
    assert (tmp_path / "crashed").exists() and sorted(parts) == list(range(6))
    result = BatchResult.concat(list(parts.values()))
    assert_same(result, toyfns.toy_result(designs))
    evaluated = [float(a2) for a2 in log.read_text().split()]
    assert evaluated.count(designs[8, 0]) == 2      # evaluated before the crash, then again


def test_released_values_are_dropped_by_the_workers() -> None:
    """A released value leaves every worker that held it: idle ones at once, busy ones with their next task."""
    with ProcessExecutor(num_workers=2) as executor:
        first, second = executor.share("a" * 100), executor.share(0.3)
        for i in range(4):                                   # both workers receive both values
            executor.submit(toyfns.held_keys_after, i, second)
            executor.submit(toyfns.uses_shared, i, first)
        held = dict(d.result for d in drain(executor) if isinstance(d.result, tuple))
        assert len(held) == 2 and all(second.key in keys for keys in held.values())
        executor.release(first)
        executor.release(second)
        keep = executor.share(0.05)
        for i in range(6):
            executor.submit(toyfns.held_keys_after, i, keep)
        after = [d.result for d in drain(executor)]
        assert {pid for pid, _ in after} == set(held)
        assert all(keys == [keep.key] for _, keys in after)


def drain(executor: workers.Executor) -> list[workers.Done]:
    done: list[workers.Done] = []
    deadline = time.monotonic() + 60
    while executor.in_flight():
        assert time.monotonic() < deadline
        done += executor.poll(1.0)
    return done


def test_worker_lost_after_max_retries() -> None:
    with ProcessExecutor(num_workers=1, max_retries=1) as executor:
        assert run_batches(executor, toyfns.always_crash, [[1]])[0].lost   # died 2 times: lost
        assert results(executor, toyfns.add, [[1]]) == {0: [1]}           # rebuilt, usable
