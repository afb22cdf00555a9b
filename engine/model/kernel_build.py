"""Compiling traced kernels in several processes at once, each kernel once.

numba compiles the kernels a kernel calls inside its own compilation, one after another: the fast
method's ~60 compilations ran on one core (docs/performance.md). Given the calls a plain-Python run
made (engine.model.jit.Trace), every process of a build runs :func:`build` on the same plan with
the same directory: each in turn claims a kernel whose traced callees are all compiled (by
creating a file exclusively, its pid inside), compiles it, numba loading those callees from its
on-disk cache whichever process compiled them, and marks it done; the kernels on the longest
chain of callers first. A kernel the trace did not see (a branch its run did not take) is compiled
inside its caller's compilation, as numba does. A kernel claimed by a process that has died is
taken over; a process left alone compiles whatever is left.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from finaldrive.engine.model.jit import Call, Trace

#: How often a process with nothing to compile looks at the others' progress [s].
_POLL_S = 0.01


@dataclass(frozen=True)
class Task:
    """One compilation: ``name`` (a file name, the same in every process), its traced callees' names."""

    name: str
    compile: Callable[[], None]
    callees: tuple[str, ...]


def _name(call: Call) -> str:
    kernel, form, types = call
    digest = hashlib.sha256(repr(types).encode()).hexdigest()[:12]
    return f"{kernel.py_func.__module__}.{kernel.py_func.__qualname__}.{form}.{digest}"


def _weight(call: Call) -> int:
    """A kernel's compile time, roughly: its bytecode's size."""
    return len(call[0].py_func.__code__.co_code)


def plan(trace: Trace) -> list[Task]:
    """The traced calls as tasks, the most urgent first: the largest weight of the kernel and its
    callers up its longest chain (what is left to compile after it, at the least)."""
    callers: dict[Call, list[Call]] = {call: [] for call in trace.calls}
    for caller, callees in trace.callees.items():
        for callee in callees:
            if callee != caller:
                callers[callee].append(caller)
    rank: dict[Call, int] = {}

    def rank_of(call: Call, chain: frozenset[Call]) -> int:
        if call not in rank:
            above = [rank_of(c, chain | {call}) for c in callers[call] if c not in chain]   # recursion: cut
            rank[call] = _weight(call) + max(above, default=0)
        return rank[call]

    order = sorted(trace.calls, key=lambda call: -rank_of(call, frozenset()))
    return [Task(_name(call), functools.partial(call[0].compile, call[1], call[2]),
                 tuple(_name(c) for c in trace.callees[call] if c != call)) for call in order]


def _alive(pid: int) -> bool:
    """Whether the process runs (a zombie, dead but not yet waited for, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    with contextlib.suppress(OSError):
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rfind(")") + 2] != "Z"
    return True


class _Board:
    """The build's directory: ``<task>.claimed`` (the claimant's pid) and ``<task>.done`` files."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._done: set[str] = set()

    def done(self, name: str) -> bool:
        if name not in self._done and (self.directory / f"{name}.done").exists():
            self._done.add(name)
        return name in self._done

    def mark_done(self, name: str) -> None:
        (self.directory / f"{name}.done").touch()
        self._done.add(name)

    def claim(self, name: str) -> bool:
        """Claim the task (True), unless it is done or a live process has claimed it."""
        path = self.directory / f"{name}.claimed"
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            if self.done(name) or self._claimant_alive(name):
                return False
            path.write_text(str(os.getpid()))   # its claimant died: taken over
            return True
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        return True

    def in_progress(self, name: str) -> bool:
        """Whether a live process has claimed the task and not finished it."""
        return not self.done(name) and self._claimant_alive(name)

    def _claimant_alive(self, name: str) -> bool:
        try:
            text = (self.directory / f"{name}.claimed").read_text()
        except FileNotFoundError:
            return False
        return not text or _alive(int(text))   # empty: being written


def build(tasks: list[Task], directory: Path) -> list[str]:
    """Compile the tasks with whichever processes build the same plan in ``directory``, until every
    task is done; return the names of those compiled here."""
    board, left, here = _Board(directory), list(tasks), []
    while left := [task for task in left if not board.done(task.name)]:
        task = next((t for t in left if all(board.done(c) for c in t.callees) and board.claim(t.name)), None)
        if task is None and not any(board.in_progress(t.name) for t in left):
            task = left[0]   # a cycle of calls: numba compiles the rest of it inside
        if task is None:
            time.sleep(_POLL_S)
            continue
        task.compile()
        board.mark_done(task.name)
        here.append(task.name)
    return here
