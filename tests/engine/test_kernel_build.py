"""Building kernels in several processes at once: the trace of a plain-Python run (each call's form
and the types numba compiles it for) and the claim-and-mark protocol between the builders."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from finaldrive.engine.model import kernel_build
from finaldrive.engine.model.jit import CALLEE, PYTHON, jit, traced
from finaldrive.engine.model.kernel_build import Task, build, plan


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
        _top(v)   # from Python with a default omitted: numba compiles for the values given
        _both(1.0)
    array = types.Array(types.float64, 1, "C")
    calls = {(kernel.py_func.__name__, form, types_) for kernel, form, types_ in trace.calls}
    assert calls == {("_top", PYTHON, (array, types.int64)), ("_top", PYTHON, (array,)),
                     ("_middle", CALLEE, (array, types.int64)), ("_leaf", CALLEE, (types.float64, types.float64)),
                     ("_leaf", CALLEE, (types.float64, types.int64)), ("_both", PYTHON, (types.float64,))}
    top = next(call for call in trace.calls if call[0] is _top)
    assert [call[0] for call in trace.callees[top]] == [_middle, _both]
    assert _top._dispatcher is None   # nothing compiled: the trace ran as plain Python


@jit
def _planned_leaf(x):
    return x * 2.0


@jit
def _planned_top(v):
    return _planned_leaf(v[0]) + _planned_leaf(1.0)


def test_the_plan_compiles_what_numba_then_uses(tmp_path: Path) -> None:
    """Built from the trace, the kernels are those compiled code calls: running them compiles nothing more."""
    from numba import float64
    from numba.core import event

    v = np.ones(2)
    with traced() as trace:
        _planned_top(v)
    tasks = plan(trace)
    assert [task.name.split(".")[-2] for task in tasks] == [CALLEE, PYTHON]   # the longer chain first
    assert tasks[1].callees == (tasks[0].name,) and tasks[0].callees == ()
    assert sorted(build(tasks, tmp_path)) == sorted(task.name for task in tasks)
    with event.install_recorder("numba:compile") as recorder:
        assert _planned_top(v) == 4.0
    assert recorder.buffer == []
    assert _planned_leaf.callee.signatures == [(float64,)]


def _tasks(log: list[tuple[str, str, float]], graph: dict[str, tuple[str, ...]], seconds: float = 0.02) -> list[Task]:
    def compile_(name: str) -> None:
        log.append(("start", name, time.monotonic()))
        time.sleep(seconds)
        log.append(("end", name, time.monotonic()))
    return [Task(name, lambda name=name: compile_(name), callees) for name, callees in graph.items()]


_GRAPH = {"top": ("a", "b"), "a": ("c",), "b": ("c", "d"), "c": (), "d": (), "e": ()}


def test_builders_compile_every_task_once_callees_first(tmp_path: Path) -> None:
    log: list[tuple[str, str, float]] = []
    compiled: list[list[str]] = [[], []]

    def builder(i: int) -> None:
        compiled[i] = build(_tasks(log, _GRAPH), tmp_path)

    threads = [threading.Thread(target=builder, args=(i,)) for i in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    assert sorted(compiled[0] + compiled[1]) == sorted(_GRAPH) and all(compiled)   # once each; both worked
    end = {name: t for kind, name, t in log if kind == "end"}
    for kind, name, t in log:
        if kind == "start":
            assert all(end[callee] <= t for callee in _GRAPH[name]), name


def test_a_task_claimed_by_a_dead_builder_is_taken_over(tmp_path: Path) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / "c.claimed").write_text(str(dead.pid))
    log: list[tuple[str, str, float]] = []
    assert sorted(build(_tasks(log, _GRAPH, 0.0), tmp_path)) == sorted(_GRAPH)


def test_a_builder_waits_for_a_task_a_live_builder_has_claimed(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernel_build, "_POLL_S", 0.001)
    (tmp_path / "c.claimed").write_text(str(os.getpid()))   # this process: alive
    threading.Timer(0.2, lambda: (tmp_path / "c.done").touch()).start()
    log: list[tuple[str, str, float]] = []
    start = time.monotonic()
    assert "c" not in build(_tasks(log, _GRAPH, 0.0), tmp_path)
    first_caller = min(t for kind, name, t in log if kind == "start" and name in ("a", "b"))
    assert first_caller - start >= 0.2


def test_a_cycle_of_calls_does_not_stall_the_build(tmp_path: Path) -> None:
    log: list[tuple[str, str, float]] = []
    assert sorted(build(_tasks(log, {"f": ("g",), "g": ("f",)}, 0.0), tmp_path)) == ["f", "g"]
