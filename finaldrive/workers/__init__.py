"""Execution backends for tasks (batches of simulations): serial, process pool, Ray.

``service`` and the CLI see only :class:`Executor` (fed by :mod:`finaldrive.workers.dispatch`).
Importing this package is light: no engine, numba or Ray (worker processes import it first);
Ray is imported only when ``make_executor("ray")`` is called.
"""

from __future__ import annotations

if __name__ != "finaldrive.workers":  # never importable as a top-level `workers` (it would shadow others)
    raise ImportError(f"this is finaldrive.workers; import it by that name, not as {__name__!r}")

import threading
import time
from typing import Literal

from finaldrive.workers.base import (
    IN_FLIGHT_PER_WORKER,
    Done,
    Executor,
    Shared,
    cancel_unseen,
)
from finaldrive.workers.cluster import ClusterTaken, NotOnCluster
from finaldrive.workers.process import ProcessExecutor
from finaldrive.workers.serial import SerialExecutor

ExecutorKind = Literal["serial", "process", "ray"]

__all__ = ["ClusterTaken", "Done", "Executor", "ExecutorKind", "NotOnCluster", "Shared", "make_executor"]

#: How long ``make_executor`` waits for the workers' first task (numba's import and runtime, ~0.4 s a
#: worker), from its start [s]; what is left then is cancelled.
WARM_UP_WAIT_S = 5.0


def make_executor(
    kind: ExecutorKind = "serial",
    *,
    num_workers: int | None = None,
    max_retries: int = 3,
    address: str | None = None,
    niceness: int = 0,
    standby: threading.Event | None = None,
    task_cpus: int | None = None,
) -> Executor:
    """Build an executor.

    ``num_workers``: worker processes (process) or CPUs of a local Ray (ray); default: this
    machine's cores, or the cluster's CPUs when joining one; ignored by serial.
    ``max_retries``: re-runs of a task whose worker died (worker loss), not of failed
    simulations. ``address``: Ray cluster to join (else ``RAY_ADDRESS``, else a local Ray);
    ignored by serial and process. ``niceness``: added to the worker processes' OS niceness
    (``os.nice``, once per process), so the calling process keeps its core; ignored by serial.
    ``standby`` (ray, joining a cluster): be the cluster's one finaldrive driver, waiting as a
    standby while another holds it, until it is free or ``standby`` is set (``ClusterTaken``).
    ``task_cpus`` (ray): CPUs each task holds, its designs on as many threads (default: 1 up to
    ``base.TASK_SLOTS`` CPUs, wider beyond: ``base.task_width``).

    For a process or Ray pool, the engine's compiled code is built once on this machine if it is
    not yet (``engine.compile_engine``, while the pool starts), so the workers only load it. While
    it compiles, the workers of a pool started here (not a cluster's, nor a Ray the caller started)
    import numba and start its runtime: one first task per worker (Ray may give one worker two),
    waited for up to ``WARM_UP_WAIT_S`` from their start, those not done by then cancelled.
    """
    if kind == "serial":
        return SerialExecutor()
    if kind not in ("process", "ray"):
        raise ValueError(f"unknown executor kind {kind!r}: expected 'serial', 'process' or 'ray'")
    from finaldrive.engine import compile_engine, is_compiled

    compiled = compile_engine()   # while the pool starts
    warm_up = not is_compiled("fast")   # the workers have time for it
    executor: Executor
    if kind == "process":
        executor = ProcessExecutor(num_workers=num_workers, max_retries=max_retries, niceness=niceness)
    else:
        try:
            from finaldrive.workers.ray_executor import RayExecutor
        except ImportError as error:
            raise ImportError(
                "make_executor('ray') needs Ray: pip install ray "
                f"(import failed: {error})"
            ) from error
        ray_executor = RayExecutor(num_workers=num_workers, max_retries=max_retries, address=address,
                                   niceness=niceness, exclusive=standby is not None, standby=standby,
                                   task_cpus=task_cpus)
        executor, warm_up = ray_executor, warm_up and ray_executor.local
    try:
        deadline = time.monotonic() + WARM_UP_WAIT_S
        warming = {executor.submit(_start_runtime, None)
                   for _ in range(executor.capacity // IN_FLIGHT_PER_WORKER if warm_up else 0)}
        compiled()
        if warming:
            _drain(executor, warming, deadline)
    except BaseException:
        executor.close()
        raise
    return executor


def _start_runtime(batch: None) -> None:
    """A worker's first task, while the engine compiles: import numba and start its runtime
    (``engine.start_runtime``), so that its first simulation only loads the compiled code."""
    from finaldrive.engine import start_runtime

    start_runtime()


def _drain(executor: Executor, tasks: set[int], deadline: float) -> None:
    """Wait until ``deadline`` (monotonic) for the tasks (their results and errors dropped: a worker
    whose start fails fails its first batch alike), then cancel those left unseen (cancel_unseen)."""
    left = set(tasks)
    while left and (seconds := deadline - time.monotonic()) > 0:
        left -= {done.task for done in executor.poll(seconds)}
    if left:
        cancel_unseen(executor, left)
