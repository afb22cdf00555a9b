"""Serial and process-pool executors, and the batching/streaming layer over them."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path

import numpy as np
import pytest

import finaldrive.workers.evaluate as evaluate
from finaldrive import workers
from finaldrive.engine.api import BatchResult, SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.workers import WorkerLostError, evaluate_all, evaluate_stream, make_executor
from finaldrive.workers.evaluate import stream_rows
from finaldrive.workers.process import ProcessExecutor
from finaldrive.workers.serial import SerialExecutor
from tests.workers import toyfns


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
        seen = dict(result for _, result in executor.map_batches(toyfns.runtime_started, [None] * 4))
    assert len(seen) == 2 and all(seen.values())


def test_warm_up_tasks_not_done_in_time_are_cancelled_unseen(engine_compiling: Callable[[bool], None],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    engine_compiling(False)
    monkeypatch.setattr(workers, "WARM_UP_WAIT_S", 0.0)
    with make_executor("process", num_workers=2) as executor:
        assert executor.poll(0.2) == [] and executor.in_flight() == 0
        assert dict(executor.map_batches(toyfns.add, [[1], [2]], shared=(10,))) == {0: [11], 1: [12]}


def test_with_the_engine_compiled_the_workers_start_nothing_beforehand(
        engine_compiling: Callable[[bool], None]) -> None:
    engine_compiling(True)
    with make_executor("process", num_workers=2) as executor:
        seen = dict(result for _, result in executor.map_batches(toyfns.runtime_started, [None] * 2))
    assert not any(seen.values())


@pytest.mark.parametrize("kind", ["serial", "process"])
def test_map_batches_yields_every_batch_once(kind: str, pool: workers.Executor) -> None:
    executor = SerialExecutor() if kind == "serial" else pool
    batches = batches_of(23, 4)
    got = dict(executor.map_batches(toyfns.add, batches, shared=(100,)))
    assert got == {i: [x + 100 for x in b] for i, b in enumerate(batches)}


def test_map_batches_pulls_batches_lazily(pool: workers.Executor) -> None:
    pulled: list[int] = []

    def source() -> Iterator[list[int]]:
        for i in range(20):
            pulled.append(i)
            yield [i]

    stream = pool.map_batches(toyfns.add, source())
    next(stream)
    assert len(pulled) < 20                       # only the in-flight window was pulled
    assert len(list(stream)) == 19


def test_results_stream_before_the_last_batch_finishes(pool: workers.Executor) -> None:
    start = time.perf_counter()
    stream = pool.map_batches(toyfns.sleep_then_add, [[0], [1], [2], [3], [4], [5]], shared=(0.3,))
    next(stream)
    first = time.perf_counter() - start
    list(stream)
    total = time.perf_counter() - start
    assert first < total - 0.4                    # 6 x 0.3 s on 2 workers: >= 0.9 s in all


def test_shared_args_reach_each_worker_process_once(tmp_path: Path) -> None:
    log = tmp_path / "unpickled.log"
    with ProcessExecutor(num_workers=2) as executor:
        pids = {pid for _, pid in executor.map_batches(
            toyfns.uses_shared, batches_of(20, 1), shared=(toyfns.LogOnUnpickle(str(log)),))}
    unpickled_in = log.read_text().split()
    assert len(unpickled_in) == len(set(unpickled_in)) <= 2
    assert pids <= set(map(int, unpickled_in))


def test_task_error_propagates_unretried(pool: workers.Executor) -> None:
    with pytest.raises(ValueError, match="bug in task"):
        list(pool.map_batches(toyfns.raise_value_error, [[1], [2]]))
    assert dict(pool.map_batches(toyfns.add, [[1]])) == {0: [1]}   # pool still usable


def test_closing_a_stream_early_leaves_the_executor_usable(pool: workers.Executor) -> None:
    stream = stream_rows(pool, toyfns.sleep_then_add, np.arange(20), (0.05,), batch_size=1)
    next(stream)
    stream.close()                                # cancels the batches not yet started
    assert dict(pool.map_batches(toyfns.add, [[1], [2]])) == {0: [1], 1: [2]}


@pytest.mark.parametrize("batch_size", [None, 3])
def test_stream_rows_covers_every_row_once(batch_size: int | None, pool: workers.Executor) -> None:
    designs = toyfns.designs(37)
    seen = []
    for rows, result in stream_rows(pool, toyfns.toy_result, designs, (2.0,), batch_size=batch_size):
        np.testing.assert_array_equal(result.designs, designs[rows])
        seen.extend(rows.tolist())
    assert sorted(seen) == list(range(37))


def test_identical_results_serial_and_process(pool: workers.Executor) -> None:
    designs = toyfns.designs(30)

    def run(executor: workers.Executor) -> BatchResult:
        parts = sorted(stream_rows(executor, toyfns.toy_result, designs, (3.0,)), key=lambda p: p[0][0])
        return BatchResult.concat([result for _, result in parts])

    assert_same(run(SerialExecutor()), run(pool))


def assert_same(a: BatchResult, b: BatchResult) -> None:
    assert a.status == b.status and a.reason == b.reason
    for name in ("designs", "distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_warm_up_runs_once_per_process(tmp_path: Path) -> None:
    log = tmp_path / "warmup.log"
    with ProcessExecutor(num_workers=2) as executor:
        pids = {pid for _, pid in stream_rows(
            executor, toyfns.pid, np.arange(12), batch_size=1, warmup=partial(toyfns.log_pid, str(log)))}
    warmed = log.read_text().split()
    assert len(warmed) == len(set(warmed)) and set(map(int, warmed)) == pids


def test_killed_worker_batch_is_evaluated_exactly_once(tmp_path: Path) -> None:
    """A worker exits in the middle of a batch; the batch is rerun and every design appears once."""
    designs = toyfns.designs(24)
    marked = designs[9, 0]                         # batch 2 (rows 8-11), third design
    log = tmp_path / "evaluated.log"
    shared = (marked, str(tmp_path / "crashed"), str(log))
    with ProcessExecutor(num_workers=2, max_retries=2) as executor:
        parts = list(stream_rows(executor, toyfns.crash_once, designs, shared, batch_size=4))
    assert (tmp_path / "crashed").exists()
    rows = np.concatenate([rows for rows, _ in parts])
    assert sorted(rows.tolist()) == list(range(24))
    result = BatchResult.concat([r for _, r in sorted(parts, key=lambda p: p[0][0])])
    assert_same(result, toyfns.toy_result(designs))
    evaluated = [float(a2) for a2 in log.read_text().split()]
    assert evaluated.count(designs[8, 0]) == 2      # evaluated before the crash, then again


def test_worker_lost_after_max_retries() -> None:
    with ProcessExecutor(num_workers=1, max_retries=1) as executor:
        with pytest.raises(WorkerLostError, match="died 2 times"):
            list(executor.map_batches(toyfns.always_crash, [[1]]))
        assert dict(executor.map_batches(toyfns.add, [[1]])) == {0: [1]}   # rebuilt, usable


@pytest.fixture
def toy_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    """Serial runs in-process, so the engine call can be replaced by a toy."""
    monkeypatch.setattr(evaluate, "run_engine", lambda d, road, settings, vehicle: toyfns.toy_result(d))
    monkeypatch.setattr(evaluate, "warm_up_engine", lambda *shared: None)


def test_evaluate_all_in_input_order_with_progress(toy_engine: None) -> None:
    designs = toyfns.designs(50)
    progress: list[tuple[int, int]] = []
    result = evaluate_all(
        SerialExecutor(), designs, Road(), SimSettings(), on_progress=lambda d, t: progress.append((d, t))
    )
    assert_same(result, toyfns.toy_result(designs))
    assert len(progress) > 1 and progress[-1] == (50, 50)
    assert [d for d, _ in progress] == sorted({d for d, _ in progress})


def test_evaluate_stream_validates_shape_and_handles_empty(toy_engine: None) -> None:
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        list(evaluate_stream(SerialExecutor(), np.zeros((4, 2)), Road(), SimSettings()))
    assert len(evaluate_all(SerialExecutor(), np.zeros((0, 3)), Road(), SimSettings())) == 0


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
