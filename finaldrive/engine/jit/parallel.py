"""Compiling traced kernels in several processes at once, each traced kernel once.

numba compiles the kernels a kernel calls inside its own compilation, one after another: the fast
method's ~60 compilations ran on one core (docs/performance-log.md). Given the calls a plain-Python run
made (engine.jit.kernel.Trace), every process of a build runs :func:`build` on the same plan with
the same directory: each in turn claims a kernel whose traced callees are all compiled (an
exclusive lock on ``<task>.claimed``, held while it compiles: the system releases it if the
process dies, and another takes the task over), compiles it, numba loading those callees from its
on-disk cache whichever process compiled them, and marks it done (``<task>.done``, written before
the lock is released); the kernels on the longest chain of callers first. A kernel the trace did
not see (a branch its run did not take) is compiled inside its caller's compilation, as numba
does, and so perhaps inside two callers' at once. Locks are POSIX (``fcntl.flock``).
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from finaldrive.engine.jit.kernel import Call, Trace

#: How often a process with nothing to compile looks at the others' progress [s].
_POLL_S = 0.02


@dataclass(frozen=True)
class Task:
    """One compilation: ``name`` (a file name, the same in every process), the names of the tasks
    it waits for (its traced callees; and an earlier signature of the same kernel's form, which
    numba caches in the same index)."""

    name: str
    compile: Callable[[], None]
    after: tuple[str, ...]


def _name(call: Call) -> str:
    kernel, form, types = call
    digest = hashlib.sha256(str(types).encode()).hexdigest()[:12]
    return f"{kernel.py_func.__module__}.{kernel.py_func.__qualname__}.{form}.{digest}"


def _weight(call: Call) -> int:
    """A kernel's compile time, roughly: its bytecode's size."""
    return len(call[0].py_func.__code__.co_code)


def _acyclic_callees(trace: Trace) -> dict[Call, list[Call]]:
    """The traced callees without the calls that close a cycle (recursion), found depth first."""
    kept: dict[Call, list[Call]] = {}
    open_: set[Call] = set()

    def visit(call: Call) -> None:
        open_.add(call)
        kept[call] = []
        for callee in trace.callees[call]:
            if callee in open_:
                continue
            if callee not in kept:
                visit(callee)
            kept[call].append(callee)
        open_.discard(call)

    for call in trace.calls:
        if call not in kept:
            visit(call)
    return kept


def plan(trace: Trace) -> list[Task]:
    """The traced calls as tasks, the most urgent first: the largest weight of the kernel and its
    callers up its longest chain (what is left to compile after it, at the least)."""
    callees = _acyclic_callees(trace)
    callers: dict[Call, list[Call]] = {call: [] for call in callees}
    for caller, called in callees.items():
        for callee in called:
            callers[callee].append(caller)

    @functools.cache
    def rank(call: Call) -> int:
        return _weight(call) + max((rank(caller) for caller in callers[call]), default=0)

    earlier: dict[tuple[object, str], str] = {}   # the previous signature's task of a kernel's form
    tasks = []
    for call in sorted(callees, key=lambda call: -rank(call)):
        name, form = _name(call), (call[0], call[1])
        after = tuple(_name(callee) for callee in callees[call]) + ((earlier[form],) if form in earlier else ())
        earlier[form] = name
        tasks.append(Task(name, functools.partial(call[0].compile, call[1], call[2]), after))
    return tasks


class _Board:
    """The build's directory: ``<task>.claimed`` (locked by the process compiling it) and ``<task>.done``."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.done: set[str] = set()

    def look(self) -> None:
        """Read which tasks are done (one listing of the directory)."""
        self.done.update(name[:-5] for name in os.listdir(self.directory) if name.endswith(".done"))

    def claim(self, name: str) -> int | None:
        """Lock the task's claim and return its descriptor, unless another process holds it or the
        task is done meanwhile."""
        fd = os.open(self.directory / f"{name}.claimed", os.O_CREAT | os.O_RDWR)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        if (self.directory / f"{name}.done").exists():   # finished between the listing and the lock
            self.done.add(name)
            os.close(fd)
            return None
        return fd

    def finish(self, name: str, fd: int) -> None:
        """Mark the task done, then release its claim."""
        (self.directory / f"{name}.done").touch()
        self.done.add(name)
        os.close(fd)


def build(tasks: list[Task], directory: Path, waiting: Callable[[], None] = lambda: None,
          progress: Callable[[int, int], None] | None = None) -> list[str]:
    """Compile the tasks with whichever processes build the same plan in ``directory``, until every
    task is done; return the names of those compiled here. ``waiting`` is called whenever this
    process has nothing to compile for a while (it may raise, to give up); ``progress(done, total)``
    whenever the number of tasks done (by any process) has changed."""
    board, here, told = _Board(directory), list[str](), -1
    while True:
        board.look()
        left = [task for task in tasks if task.name not in board.done]
        if progress is not None and len(tasks) - len(left) != told:
            told = len(tasks) - len(left)
            progress(told, len(tasks))
        if not left:
            return here
        for task in left:
            if all(name in board.done for name in task.after) and (fd := board.claim(task.name)) is not None:
                try:
                    task.compile()
                except BaseException:
                    os.close(fd)
                    raise
                board.finish(task.name, fd)
                here.append(task.name)
                break
        else:
            waiting()
            time.sleep(_POLL_S)
