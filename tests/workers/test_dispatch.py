"""The dispatcher: every source's ready work in flight up to capacity, fair turns, failures isolated."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from finaldrive.engine import BatchResult, Request, Road
from finaldrive.workers import ProcessExecutor, SerialExecutor
from finaldrive.workers.dispatch import Dispatcher, Work, in_flight_limit
from finaldrive.workers.evaluate import by_road
from tests.service.svc_helpers import toy_batch


def task(rows: np.ndarray, roads: Any, *_: Any) -> list[tuple[int, BatchResult]]:
    """The toy fitness; raises for a design with l2 > 0.15 (a bug in the worker)."""
    if (rows[:, 2] > 0.15).any():
        raise RuntimeError("boom")
    return [(road, toy_batch(x, roads[road])) for road, x in by_road(rows)]


def request(n: int, road: int = 0, run: int = 0, l2: float = 0.1, waited: bool = False) -> Request:
    designs = np.column_stack([np.linspace(0, 1, n), np.full(n, l2), np.full(n, 0.09)])
    return Request(run, 0, road, np.arange(n), designs, waited)


class Sink:
    def __init__(self) -> None:
        self.results: list[tuple[Request, BatchResult]] = []
        self.failures: list[tuple[Request, str]] = []

    def work(self, key: str, *requests: Request) -> Work:
        w = Work(key=key, shared=((Road(), Road.parse("sine:0.02:3")),),
                 on_result=lambda p, b: self.results.append((p, b)),
                 on_failure=lambda p, r: self.failures.append((p, r)))
        w.queue.extend(requests)
        return w


def drain(dispatcher: Dispatcher, *works: Work) -> None:
    while any(w.queue or w.alone for w in works) or dispatcher.in_flight():
        dispatcher.step(1.0)


def test_every_design_comes_back_once_in_any_batching() -> None:
    sink = Sink()
    dispatcher = Dispatcher(SerialExecutor(), task, batch_size=3)
    work = sink.work("a", request(10), request(7, road=1))
    dispatcher.add(work)
    drain(dispatcher, work)
    got = sorted((p.road, int(c)) for p, _ in sink.results for c in p.candidates)
    assert got == [(0, c) for c in range(10)] + [(1, c) for c in range(7)]
    for part, batch in sink.results:
        np.testing.assert_array_equal(batch.designs, part.designs)


def test_sources_take_turns_and_the_executor_stays_full() -> None:
    sink = Sink()
    with ProcessExecutor(num_workers=2) as executor:
        dispatcher = Dispatcher(executor, task, batch_size=1)
        a, b = sink.work("a", request(12)), sink.work("b", request(12))
        dispatcher.add(a)
        dispatcher.add(b)
        assert dispatcher.fill() == executor.capacity
        assert dispatcher.in_flight("a") == dispatcher.in_flight("b") == executor.capacity // 2
        drain(dispatcher, a, b)
    assert len(sink.results) == 24 and not sink.failures


def test_a_batch_that_raises_is_tried_again_design_by_design() -> None:
    sink = Sink()
    bad = request(6)
    bad.designs[4, 1] = 0.2  # one design makes the worker raise
    dispatcher = Dispatcher(SerialExecutor(), task, batch_size=6)
    work = sink.work("a", bad)
    dispatcher.add(work)
    drain(dispatcher, work)
    assert [int(p.candidates[0]) for p, _ in sink.failures] == [4]
    assert sink.failures[0][1] == "error in the worker: RuntimeError: boom"
    assert sorted(int(c) for p, _ in sink.results for c in p.candidates) == [0, 1, 2, 3, 5]


def test_removing_a_source_cancels_its_tasks_and_drops_its_queue() -> None:
    removed, kept = Sink(), Sink()
    with ProcessExecutor(num_workers=2) as executor:
        dispatcher = Dispatcher(executor, task, batch_size=1)
        a, b = removed.work("a", request(50)), kept.work("b", request(4))
        dispatcher.add(a)
        dispatcher.add(b)
        dispatcher.fill()
        dispatcher.remove("a")
        assert "a" not in dispatcher and not a.queue and dispatcher.in_flight("a") == 0
        drain(dispatcher, b)
    assert removed.results == [] and removed.failures == []
    assert sorted(int(p.candidates[0]) for p, _ in kept.results) == [0, 1, 2, 3]


def test_the_smallest_request_goes_first() -> None:
    """A DE generation (small, the next waits for it) overtakes a sweep's road (big, nothing waits)."""
    sink = Sink()
    dispatcher = Dispatcher(SerialExecutor(), task, batch_size=4)
    work = sink.work("a", request(40, road=0), request(6, road=1, run=1), request(5, road=1, run=2))
    dispatcher.add(work)
    drain(dispatcher, work)
    runs = [part.run for part, _ in sink.results]
    assert runs[:4] == [2, 2, 1, 1] and set(runs[4:]) == {0}
    assert sum(len(part) for part, _ in sink.results) == 51


def test_small_requests_share_a_task_up_to_the_batch_size() -> None:
    """DE generations of different runs ride in one task while the size leaves room (the per-task
    cost is paid once); each gets its own results back, on its own road."""
    sink = Sink()
    executor = SerialExecutor()
    submitted: list[int] = []
    submit = executor.submit
    executor.submit = lambda fn, rows, *shared, again=0: (  # type: ignore[method-assign]
        submitted.append(len(rows)) or submit(fn, rows, *shared, again=again))
    dispatcher = Dispatcher(executor, task, batch_size=10)
    work = sink.work("a", request(4, road=0, run=1), request(3, road=1, run=2), request(5, road=0, run=3))
    dispatcher.add(work)
    drain(dispatcher, work)
    assert submitted == [7, 5]  # 3 + 4 (the 5 does not fit beside them), then the 5
    assert [(part.run, len(part)) for part, _ in sink.results] == [(2, 3), (1, 4), (3, 5)]
    roads = (Road(), Road.parse("sine:0.02:3"))
    for part, batch in sink.results:
        expected = toy_batch(part.designs, roads[part.road])
        np.testing.assert_array_equal(batch.designs, part.designs)
        np.testing.assert_array_equal(batch.fitness_m, expected.fitness_m)


def test_waited_on_designs_count_queued_and_running() -> None:
    """Batching rule 5's round: the waited-on designs queued or in flight (a sweep's are not)."""
    sink = Sink()
    executor = SerialExecutor()
    dispatcher = Dispatcher(executor, task, batch_size=4)
    work = sink.work("a", request(6, run=1, waited=True), request(30, road=1), request(5, run=2, waited=True))
    dispatcher.add(work)
    assert work.next_request()[1] == 11
    dispatcher.fill()
    assert dispatcher.in_flight() > 0 and work.waited_in_flight == 11 - sum(len(q) for q in work.queue if q.waited)
    assert work.next_request()[1] == 11  # queued + running: the same round
    drain(dispatcher, work)
    assert work.waited_in_flight == 0 and sum(len(part) for part, _ in sink.results) == 41


def test_about_50_ms_of_work_waits_beyond_one_task_a_worker() -> None:
    """Executors start tasks first in, first out: a deep queue would hold a new generation behind it."""
    assert [in_flight_limit(n, 2 * n) for n in (1, 2, 16, 64, 256)] == [2, 4, 18, 72, 288]  # nothing measured
    assert in_flight_limit(256, 512, task_s=0.5) == 256 + 26  # 26 tasks of 0.5 s on 256 workers: 51 ms
    assert in_flight_limit(256, 512, task_s=0.1) == 256 + 128
    assert in_flight_limit(256, 512, task_s=0.01) == 512  # never beyond the executor's capacity
    assert in_flight_limit(2, 4, task_s=5.0) == 4  # at least two queued


def test_a_source_added_after_results_skips_the_probe() -> None:
    """A job arriving where others have run starts from their measurements (batching rule 1), not
    with one design a task: the first source probes, the second's first task is bigger."""
    sink = Sink()
    dispatcher = Dispatcher(SerialExecutor(), task)
    first = sink.work("a", request(40))
    dispatcher.add(first)
    dispatcher.fill()
    assert 40 - len(first.queue[0]) == dispatcher.in_flight("a")  # probes: one design a task
    drain(dispatcher, first)
    second = sink.work("b", request(40))
    dispatcher.add(second)
    assert second.sizer is not None and second.sizer.designs_done > 0
    dispatcher.fill()
    assert 40 - sum(len(q) for q in second.queue) > dispatcher.in_flight("b") > 0


def stall_once(rows: np.ndarray, roads: Any, marker: str) -> list[tuple[int, BatchResult]]:
    """``task``, but the first task holding the design with l2 = 0.12 hangs for a minute (a node that
    died: its task never comes back), once: the marker file says it did."""
    import os
    import time

    if (rows[:, 2] == 0.12).any() and not os.path.exists(marker):
        open(marker, "w").close()
        time.sleep(60.0)
    return task(rows, roads)


def test_a_task_far_overdue_is_run_again_and_delivered_once(tmp_path: Any) -> None:
    from functools import partial

    sink = Sink()
    slow = request(1, l2=0.12)
    with ProcessExecutor(num_workers=2) as executor:
        dispatcher = Dispatcher(executor, partial(stall_once, marker=str(tmp_path / "stalled")), batch_size=1)
        work = sink.work("a", request(40), slow)
        dispatcher.add(work)
        start = time.perf_counter()
        drain(dispatcher, work)
        took = time.perf_counter() - start
        load = dispatcher.load()
    assert dispatcher.hedged == 1 and took < 20.0, (dispatcher.hedged, took)
    got = sorted((p.road, float(p.designs[0, 1]), int(c)) for p, _ in sink.results for c in p.candidates)
    assert len(got) == 41 == len(set(got)) and not sink.failures
    stalled = next(b for p, b in sink.results if p.designs[0, 1] == 0.12)
    expected = toy_batch(slow.designs, Road())
    np.testing.assert_array_equal(stalled.values, expected.values)
    assert load.evaluations_per_s > 0 and load.tasks_per_s > 0 and load.in_flight_tasks == 0
    assert load.backlog_designs == 0 and 0.0 < load.busy_share <= 1.0


def slowed(rows: np.ndarray, roads: Any, factor_file: str) -> list[tuple[int, BatchResult]]:
    """``task``, taking 10 ms a design times the factor in ``factor_file`` (a machine slowed as a whole)."""
    import time
    from pathlib import Path

    time.sleep(0.01 * len(rows) * float(Path(factor_file).read_text()))
    return task(rows, roads)


def test_a_machine_slowed_down_as_a_whole_has_no_task_run_again(tmp_path: Any) -> None:
    """Every worker 10 times slower at once (an API under load beside them): a task then takes 10 times
    its designs' expected time, and it and the tasks queued behind it are on time against the pace of
    the others: no copy, where copies would take the slowed workers from other work."""
    from functools import partial

    factor = tmp_path / "factor"
    factor.write_text("1")
    sink = Sink()
    with ProcessExecutor(num_workers=2) as executor:
        dispatcher = Dispatcher(executor, partial(slowed, factor_file=str(factor)), batch_size=10)
        work = sink.work("a", request(300))
        dispatcher.add(work)
        slowed_at = hedged = None
        while work.queue or dispatcher.in_flight():
            dispatcher.step(1.0)
            if slowed_at is None and len(sink.results) >= 20:   # 200 designs at 10 ms, then 100 at 100 ms
                (tmp_path / "slow").write_text("10")
                (tmp_path / "slow").replace(factor)   # at once: no worker reads a file half written
                slowed_at, hedged = len(sink.results), dispatcher.hedged
    assert slowed_at is not None and len(sink.results) - slowed_at >= 6   # tasks of 1 s ran
    # (before: a worker process that starts late, its first task overdue against the other's, may be copied)
    assert dispatcher.hedged == hedged
    got = sorted(int(c) for p, _ in sink.results for c in p.candidates)
    assert got == list(range(300)) and not sink.failures


def test_load_counts_the_backlog_and_the_busy_share() -> None:
    dispatcher = Dispatcher(SerialExecutor(), task, batch_size=2)
    work = Sink().work("a", request(10))
    dispatcher.add(work)
    assert dispatcher.load().backlog_designs == 10
    dispatcher.step(1.0)
    load = dispatcher.load()
    assert load.tasks_per_s > 0 and load.evaluations_per_s == 2 * load.tasks_per_s   # tasks of 2 designs came back
    assert load.backlog_designs + 2 * load.in_flight_tasks < 10 and 0.0 < load.busy_share <= 1.0
