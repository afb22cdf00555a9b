"""Small picklable task functions for executor tests (imported by worker processes too)."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from finaldrive.engine.api import BatchResult, SimResult


def toy_result(designs: np.ndarray, scale: float = 1.0) -> BatchResult:
    """A deterministic BatchResult: distance = scale * (a2 + 10 L2 + 100 R_WS)."""
    designs = np.asarray(designs, dtype=float).reshape(-1, 3)
    results = [
        SimResult.of("ok", "", distance_m=float(scale * (a2 + 10 * l2 + 100 * rws)), squat_ratio=a2, slack_m=l2,
                     fitness_m=0.0, chain_length_m=1.0, wall_s=0.0)
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


# ---------------------------------------------------------------------- for the executor interface tests
def mark_started(directory: str, batch: object) -> None:
    """Write ``<directory>/<batch>.pid`` (this process's pid), atomically: the task is running."""
    path = Path(directory) / f"{batch}.pid"
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(str(os.getpid()))
    tmp.rename(path)


def sleep_marked(batch: int, directory: str, seconds: float) -> int:
    """Mark the task started, sleep, return the batch."""
    mark_started(directory, batch)
    time.sleep(seconds)
    return batch


def spin_marked(batch: int, directory: str) -> bytes:
    """Mark the task started, then spin for minutes inside one compiled call (PBKDF2 in OpenSSL's C),
    which no Python-level signal or exception can interrupt."""
    import hashlib

    mark_started(directory, batch)
    return hashlib.pbkdf2_hmac("sha256", b"finaldrive", b"salt", 10**9)


def log_line(path: str, line: object) -> None:
    with open(path, "a") as f:
        f.write(f"{line}\n")


def crash_first_time(batch: int, directory: str, target: int) -> int:
    """2 x batch; the worker running ``target`` dies on its first attempt (a marker file remembers)."""
    log_line(str(Path(directory) / "attempts.log"), batch)
    marker = Path(directory) / "crashed"
    if batch == target and not marker.exists():
        marker.touch()
        os._exit(1)
    return 2 * batch


def log_then_crash(batch: object, path: str) -> None:
    log_line(path, os.getpid())
    os._exit(1)


def log_then_raise(batch: object, path: str) -> None:
    log_line(path, os.getpid())
    raise ValueError("bug in task")


def niceness(batch: object) -> int:
    return os.nice(0)


def sigint_state(batch: object) -> tuple[bool, bool]:
    """(SIGINT ignored, SIGINT blocked) in this process."""
    import signal

    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    return ignored, blocked


class CountPickling:
    """A shared value that counts its picklings (in the pickling process) and logs every
    unpickling (pid to a file)."""

    pickled = 0

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):  # type: ignore[no-untyped-def]
        CountPickling.pickled += 1
        return (_count_unpickled, (self.path,))


def _count_unpickled(path: str) -> CountPickling:
    log_line(path, os.getpid())
    return CountPickling(path)


def pid_with(batch: object, value: object) -> int:
    return os.getpid()


def held_keys(batch: object) -> tuple[int, list[int]]:
    """(pid, keys of the shared values this process-pool worker holds)."""
    from finaldrive.workers.process import held_keys

    return os.getpid(), held_keys()


def held_keys_after(batch: object, seconds: float) -> tuple[int, list[int]]:
    time.sleep(seconds)
    return held_keys(batch)


def runtime_started(batch: object) -> tuple[int, bool]:
    """(this worker's pid, whether numba's runtime was started in it before this task)."""
    jit = sys.modules.get("finaldrive.engine.jit.kernel")
    return os.getpid(), jit is not None and jit.start_runtime.cache_info().currsize == 1


def cpus_held(batch: object) -> int:
    """The CPUs the running task holds, as its executor said (workers.task.task_cpus)."""
    from finaldrive.workers.task import task_cpus

    return task_cpus()
