"""Execution backends for batches of simulations: serial, process pool, Ray.

``service`` and the CLI see only :class:`Executor`; Ray is imported only when
``make_executor("ray")`` is called.
"""

from __future__ import annotations

if __name__ != "finaldrive.workers":  # never importable as a top-level `workers` (it would shadow others)
    raise ImportError(f"this is finaldrive.workers; import it by that name, not as {__name__!r}")

from typing import Literal

from finaldrive.workers.base import Executor, WorkerLostError
from finaldrive.workers.evaluate import evaluate_all, evaluate_roads_stream, evaluate_stream
from finaldrive.workers.process import ProcessExecutor
from finaldrive.workers.serial import SerialExecutor

ExecutorKind = Literal["serial", "process", "ray"]

__all__ = [
    "Executor", "ExecutorKind", "WorkerLostError", "evaluate_all", "evaluate_roads_stream", "evaluate_stream",
    "make_executor",
]


def make_executor(
    kind: ExecutorKind = "serial",
    *,
    num_workers: int | None = None,
    max_retries: int = 3,
    address: str | None = None,
) -> Executor:
    """Build an executor.

    ``num_workers``: worker processes (process) or CPUs of a local Ray (ray); default: this
    machine's cores, or the cluster's CPUs when joining one; ignored by serial.
    ``max_retries``: re-runs of a batch whose worker died (worker loss), not of failed
    simulations. ``address``: Ray cluster to join (else ``RAY_ADDRESS``, else a local Ray);
    ignored by serial and process.
    """
    if kind == "serial":
        return SerialExecutor()
    if kind == "process":
        return ProcessExecutor(num_workers=num_workers, max_retries=max_retries)
    if kind == "ray":
        try:
            from finaldrive.workers.ray_executor import RayExecutor
        except ImportError as error:
            raise ImportError(
                "make_executor('ray') needs Ray: pip install ray "
                f"(import failed: {error})"
            ) from error
        return RayExecutor(num_workers=num_workers, max_retries=max_retries, address=address)
    raise ValueError(f"unknown executor kind {kind!r}: expected 'serial', 'process' or 'ray'")
