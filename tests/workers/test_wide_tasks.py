"""Wide tasks: how many CPUs a task holds on a cluster (workers.base.task_width), and a wide task's
designs on threads (workers.evaluate.run_engine_on_roads) with the serial results, in order."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from finaldrive.engine import VALUES, Road, SimSettings
from finaldrive.workers import evaluate
from finaldrive.workers.base import MAX_TASK_CPUS, TASK_SLOTS, task_width
from finaldrive.workers.evaluate import run_engine_on_roads
from finaldrive.workers.task import hold_cpus, task_cpus


@pytest.mark.parametrize(("nodes", "fixed", "expected"), [
    ([2], None, (1, 2)),                  # a laptop: a CPU a task, as ever
    ([TASK_SLOTS], None, (1, TASK_SLOTS)),
    ([TASK_SLOTS + 1], None, (2, 8)),      # one CPU more: two a task, the odd one idle
    ([64] * 4, None, (16, 16)),           # 256 CPUs: 16 tasks at once
    ([8] * 32, None, (8, 32)),            # no wider than a node
    ([64] * 16, None, (MAX_TASK_CPUS, 64)),  # 1,024 CPUs: the widest task, 64 at once
    ([0, 32, 32], None, (4, 16)),         # a head without CPUs takes no task
    ([64] * 4 + [2], None, (16, 16)),     # a small node does not narrow every task: it stays idle
    ([64] + [8] * 32, None, (8, 40)),     # ... unless the small nodes hold most of the CPUs
    ([2], 2, (2, 1)),
    ([4, 2], 3, (3, 1)),                  # only the node that has 3 takes tasks
])
def test_task_width(nodes: list[int], fixed: int | None, expected: tuple[int, int]) -> None:
    assert task_width(nodes, fixed) == expected


def test_task_width_of_some_of_a_cluster_s_cpus() -> None:
    """``num_workers`` on a cluster: the CPUs to use in all, the width still one that its nodes hold."""
    assert task_width([4] * 32, cpus=128) == (4, 32)
    assert task_width([64] * 4, cpus=16) == (1, 16)
    assert task_width([64] * 4, cpus=100) == (7, 14)


def test_a_width_no_node_has_is_refused() -> None:
    with pytest.raises(ValueError, match="task_cpus 4 is more than any node's CPUs \\(at most 2\\)"):
        task_width([2, 1], 4)


@pytest.fixture
def two_cpus() -> Iterator[None]:
    hold_cpus(2)
    yield
    hold_cpus(1)


ROADS = (Road.parse("sine:0.04:3"), Road.parse("flat"))
_WALL = VALUES.index("wall_s")


def _rows(n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([np.repeat([0.0, 1.0, 0.0], [n // 3, n // 3, n - 2 * (n // 3)]),
                            rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 0.3, n), rng.uniform(0.07, 0.12, n)])


def test_a_wide_task_gives_the_serial_results_in_order(two_cpus: None) -> None:
    """Every value but the wall time bit for bit, the runs of roads kept (three runs: 0, 1, 0)."""
    rows, settings = _rows(24), SimSettings(duration=0.3)
    assert task_cpus() == 2
    wide = run_engine_on_roads(rows, ROADS, settings, None)
    hold_cpus(1)
    serial = run_engine_on_roads(rows, ROADS, settings, None)
    assert [road for road, _ in wide] == [road for road, _ in serial] == [0, 1, 0]
    for (_, a), (_, b) in zip(wide, serial, strict=True):
        assert a.status == b.status and a.reason == b.reason
        np.testing.assert_array_equal(a.designs, b.designs)
        np.testing.assert_array_equal(np.delete(a.values, _WALL, axis=1), np.delete(b.values, _WALL, axis=1))
    assert sum(int(b.ok.sum()) for _, b in serial) > 0


def test_a_wide_task_runs_its_designs_on_its_threads_at_once(two_cpus: None, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two designs that each wait for the other can only finish on two threads at once."""
    both = threading.Barrier(2, timeout=10)
    seen: list[str] = []
    real = evaluate.run_engine

    def meeting(designs: np.ndarray, *args: object) -> object:
        seen.append(threading.current_thread().name)
        both.wait()
        return real(designs, *args)

    monkeypatch.setattr(evaluate, "run_engine", meeting)
    out = run_engine_on_roads(_rows(2)[:2] * [0, 1, 1, 1], ROADS, SimSettings(duration=0.05), None)
    assert [len(b) for _, b in out] == [2] and len(set(seen)) == 2


def test_a_design_that_raises_fails_the_wide_task_and_stops_its_threads(two_cpus: None,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []

    def broken(designs: np.ndarray, *args: object) -> object:
        calls.append(1)
        time.sleep(0.01)
        raise RuntimeError("a bug")

    monkeypatch.setattr(evaluate, "run_engine", broken)
    with pytest.raises(RuntimeError, match="a bug"):
        run_engine_on_roads(_rows(40), ROADS, SimSettings(duration=0.05), None)
    assert len(calls) <= 4   # each thread stops at the next design once one failed
