"""Small picklable task functions for executor tests (imported by worker processes too)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from finaldrive.engine.api import BatchResult, SimResult


def toy_result(designs: np.ndarray, scale: float = 1.0) -> BatchResult:
    """A deterministic BatchResult: distance = scale * (a2 + 10 L2 + 100 R_WS)."""
    designs = np.asarray(designs, dtype=float).reshape(-1, 3)
    results = [
        SimResult("ok", "", float(scale * (a2 + 10 * l2 + 100 * rws)), a2, l2, 0.0, 1.0, 0.0)
        for a2, l2, rws in designs
    ]
    return BatchResult.from_results(designs, results)


def designs(n: int) -> np.ndarray:
    """n distinct design rows."""
    i = np.arange(n, dtype=float)
    return np.column_stack([i * 0.01, i * 0.001, 0.05 + i * 1e-4])


def add(batch: list[int], offset: int = 0) -> list[int]:
    return [x + offset for x in batch]


def sleep_then_add(batch: list[int], seconds: float) -> list[int]:
    time.sleep(seconds)
    return list(batch)


def raise_value_error(batch: object) -> None:
    raise ValueError("bug in task")


def pid(batch: object) -> int:
    return os.getpid()


def log_pid(path: str) -> None:
    """Warm-up that records which process ran it."""
    with open(path, "a") as f:
        f.write(f"{os.getpid()}\n")


class LogOnUnpickle:
    """A shared argument that records every unpickling (once per worker process expected)."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (_unpickled, (self.path,))


def _unpickled(path: str) -> LogOnUnpickle:
    with open(path, "a") as f:
        f.write(f"{os.getpid()}\n")
    return LogOnUnpickle(path)


def uses_shared(batch: list[int], shared: LogOnUnpickle) -> int:
    return os.getpid()


def crash_once(designs: np.ndarray, marked_a2: float, marker: str, log: str) -> BatchResult:
    """toy_result, evaluated design by design; the process exits at the marked design
    the first time any process meets it (the marker file remembers)."""
    for a2, _, _ in designs:
        if a2 == marked_a2 and not Path(marker).exists():
            Path(marker).touch()
            os._exit(1)
        with open(log, "a") as f:
            f.write(f"{float(a2)!r}\n")
    return toy_result(designs)


def always_crash(batch: object) -> None:
    os._exit(1)
