"""Building kernels in several processes at once: the trace of a plain-Python run (each call's form
and the types numba compiles it for) and the claim-and-mark protocol between the builders."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from finaldrive.engine.jit import parallel as kernel_build
from finaldrive.engine.jit.kernel import CALLEE, PYTHON, jit, traced
from finaldrive.engine.jit.parallel import Task, build, plan


@jit
def _leaf(x, k=2.0):
    return x * k


@jit
def _middle(v, i):
    return _leaf(v[i]) + _leaf(v[i], 3)   # the default filled in; a constant as its plain type


@jit(one_form=True)
def _both(x):
    return x + 1.0


@jit
def _top(v, n=1):
    acc = 0.0
    for i in range(n):
        acc += _middle(v, i) + _both(acc)
    return acc


def test_a_trace_records_each_call_once_in_the_form_and_types_numba_compiles() -> None:
    from numba import types

    v = np.arange(3.0)
    with traced() as trace:
        assert _top(v, 2) == (0.0 + 1.0) + (5.0 + 2.0)   # (middle + both) for i = 0, 1, as plain Python
        _top(v)   # from Python with a default left out: numba compiles it as omitted
        _both(1.0)
    array = types.Array(types.float64, 1, "C")
    calls = {(kernel.py_func.__name__, form, types_) for kernel, form, types_ in trace.calls}
    assert calls == {("_top", PYTHON, (array, types.int64)), ("_top", PYTHON, (array, types.Omitted(1))),
                     ("_middle", CALLEE, (array, types.int64)), ("_leaf", CALLEE, (types.float64, types.float64)),
                     ("_leaf", CALLEE, (types.float64, types.int64)), ("_both", PYTHON, (types.float64,))}
    top = next(call for call in trace.calls if call[0] is _top)
    assert [call[0] for call in trace.callees[top]] == [_middle, _both]
    assert _top._dispatcher is None   # nothing compiled: the trace ran as plain Python


@jit
def _planned_leaf(x):
    return x * 2.0


@jit
def _planned_top(v, k=1.0):
    return _planned_leaf(v[0]) + _planned_leaf(k)


def test_the_plan_compiles_what_numba_then_uses(tmp_path: Path) -> None:
    """Built from the trace, the kernels are those numba compiles for the calls: making them again
    compiles nothing (a default left out from Python included)."""
    from numba import float64
    from numba.core import event

    v = np.ones(2)
    with traced() as trace:
        _planned_top(v)
    tasks = plan(trace)
    assert [task.name.split(".")[-2] for task in tasks] == [CALLEE, PYTHON]   # the longer chain first
    assert tasks[1].after == (tasks[0].name,) and tasks[0].after == ()
    assert sorted(build(tasks, tmp_path)) == sorted(task.name for task in tasks)
    with event.install_recorder("numba:compile") as recorder:
        assert _planned_top(v) == 4.0
    assert recorder.buffer == []
    assert _planned_leaf.callee.signatures == [(float64,)]


@jit
def _even(n):
    return True if n == 0 else _odd(n - 1)


@jit
def _odd(n):
    return False if n == 0 else _even(n - 1)


def test_a_plan_of_recursive_kernels_has_no_cycle_to_wait_on(tmp_path: Path) -> None:
    with traced() as trace:
        assert _even(4)
    tasks = plan(trace)
    assert len(tasks) == 3   # _even from Python; _odd and _even from compiled code
    order = [task.name for task in tasks]
    assert all(order.index(name) > order.index(after) for name in order for after in tasks[order.index(name)].after)
    assert sorted(build([replace(task, compile=lambda: None) for task in tasks], tmp_path)) == sorted(order)


def _tasks(log: list[tuple[str, str, float]], graph: dict[str, tuple[str, ...]], seconds: float = 0.02) -> list[Task]:
    def compile_(name: str) -> None:
        log.append(("start", name, time.monotonic()))
        time.sleep(seconds)
        log.append(("end", name, time.monotonic()))
    return [Task(name, lambda name=name: compile_(name), after) for name, after in graph.items()]


_GRAPH = {"top": ("a", "b"), "a": ("c",), "b": ("c", "d"), "c": (), "d": (), "e": ()}


def _in_threads(n: int, fn: Callable[[int], None]) -> None:
    threads = [threading.Thread(target=fn, args=(i,), daemon=True) for i in range(n)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    assert not any(thread.is_alive() for thread in threads)


def test_builders_compile_every_task_once_callees_first(tmp_path: Path) -> None:
    for attempt in range(20):   # the builders' timing differs from run to run
        directory = tmp_path / str(attempt)
        directory.mkdir()
        log: list[tuple[str, str, float]] = []
        compiled: list[list[str]] = [[], []]

        def builder(i: int) -> None:
            compiled[i] = build(_tasks(log, _GRAPH, 0.002), directory)   # noqa: B023

        _in_threads(2, builder)
        assert sorted(compiled[0] + compiled[1]) == sorted(_GRAPH)   # once each
        end = {name: t for kind, name, t in log if kind == "end"}
        for kind, name, t in log:
            if kind == "start":
                assert all(end[callee] <= t for callee in _GRAPH[name]), name


def _hold(path: Path) -> int:
    fd = os.open(path, os.O_CREAT | os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


def test_a_task_claimed_by_a_builder_that_died_is_taken_over(tmp_path: Path) -> None:
    """Killed and not yet waited for (a zombie), or gone: the system released its lock either way."""
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, os, sys, time; "
                               "fd = os.open(sys.argv[1], os.O_CREAT | os.O_RDWR); fcntl.flock(fd, fcntl.LOCK_EX); "
                               "print('held', flush=True); time.sleep(60)", str(tmp_path / "c.claimed")],
                              stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline() == "held\n"
    holder.kill()
    time.sleep(0.2)   # dead, not yet waited for
    log: list[tuple[str, str, float]] = []
    assert sorted(build(_tasks(log, _GRAPH, 0.0), tmp_path)) == sorted(_GRAPH)
    holder.wait()


def test_a_builder_waits_for_a_task_a_live_builder_compiles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernel_build, "_POLL_S", 0.001)
    fd = _hold(tmp_path / "c.claimed")   # another builder compiling c

    def finish() -> None:
        (tmp_path / "c.done").touch()
        os.close(fd)

    start = time.monotonic()
    threading.Timer(0.2, finish).start()
    log: list[tuple[str, str, float]] = []
    waits: list[float] = []
    assert "c" not in build(_tasks(log, _GRAPH, 0.0), tmp_path, lambda: waits.append(time.monotonic()))
    first_caller = min(t for kind, name, t in log if kind == "start" and name in ("a", "b"))
    assert first_caller - start >= 0.2 and waits


def test_a_builder_gives_up_when_waiting_says_so(tmp_path: Path) -> None:
    fd = _hold(tmp_path / "c.claimed")

    def waiting() -> None:
        raise TimeoutError("no progress")

    with pytest.raises(TimeoutError):
        build(_tasks([], _GRAPH, 0.0), tmp_path, waiting)
    os.close(fd)
