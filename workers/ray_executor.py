"""Ray executor: the only module that imports Ray.

Local by default (``ray.init(address="local")`` with ``num_workers`` CPUs); joins an existing
cluster when ``address`` or ``RAY_ADDRESS`` is set. If Ray is already initialised in this
process, the executor uses that session and leaves it running on ``close()``.

Ray 2.60's ``ray.init`` sets ``RAY_AUTH_MODE=token`` in this process's environment when
token authentication applies (a local start, or a token in ``~/.ray/auth_token``); ``close()``
restores the previous value so the setting does not outlive the executor.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import ray
from ray.exceptions import LocalRayletDiedError, NodeDiedError, OutOfMemoryError, WorkerCrashedError

from finaldrive.workers.base import IN_FLIGHT_PER_WORKER, ClosingMixin, WorkerLostError

_AUTH_MODE = "RAY_AUTH_MODE"

#: Ray errors that mean the batch's worker (or node) was lost after all retries.
_WORKER_LOSS = (WorkerCrashedError, NodeDiedError, OutOfMemoryError, LocalRayletDiedError)


@ray.remote
def _run_batch(fn: Callable[..., Any], batch: Any, *shared: Any) -> Any:
    return fn(batch, *shared)


class RayExecutor(ClosingMixin):
    """One Ray task per batch, with ``max_retries`` for worker loss; shared args ``ray.put`` once."""

    def __init__(
        self, num_workers: int | None = None, max_retries: int = 3, address: str | None = None
    ) -> None:
        if max_retries < 0:
            raise ValueError("max_retries must be >= 0")
        self.max_retries = max_retries
        self._started = not ray.is_initialized()
        self._auth_mode_before = os.environ.get(_AUTH_MODE)
        if self._started:
            address = address or os.environ.get("RAY_ADDRESS") or None
            options: dict[str, Any] = {
                "include_dashboard": False, "ignore_reinit_error": True, "log_to_driver": False,
            }
            if address:
                ray.init(address=address, **options)
            else:
                ray.init(address="local", num_cpus=num_workers or os.cpu_count() or 1, **options)
        self.num_workers = num_workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._task = _run_batch.options(max_retries=max_retries, retry_exceptions=False)

    def map_batches(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
    ) -> Iterator[tuple[int, Any]]:
        shared_refs = [ray.put(value) for value in shared]
        source = enumerate(batches)
        pending: dict[ray.ObjectRef, int] = {}
        limit = IN_FLIGHT_PER_WORKER * self.num_workers

        def fill() -> None:
            while len(pending) < limit and (item := next(source, None)) is not None:
                index, batch = item
                pending[self._task.remote(fn, batch, *shared_refs)] = index

        try:
            fill()
            while pending:
                ready, rest = ray.wait(list(pending), num_returns=1)
                if rest:
                    more, _ = ray.wait(rest, num_returns=len(rest), timeout=0)
                    ready += more
                try:
                    values = ray.get(ready)
                except _WORKER_LOSS as error:
                    raise WorkerLostError(
                        f"a batch's worker died more than max_retries={self.max_retries} times: {error}"
                    ) from error
                finished = [(pending.pop(ref), value) for ref, value in zip(ready, values)]
                fill()
                yield from finished
        finally:
            if ray.is_initialized():
                for ref in pending:
                    ray.cancel(ref)

    def close(self) -> None:
        """Shut Ray down if this executor started it; idempotent."""
        if self._started and ray.is_initialized():
            ray.shutdown()
            if self._auth_mode_before is None:
                os.environ.pop(_AUTH_MODE, None)
            else:
                os.environ[_AUTH_MODE] = self._auth_mode_before
        self._started = False
