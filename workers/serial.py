"""In-process executor: the default, the test double, and the debugging mode."""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterable
from typing import Any

from finaldrive.workers.base import ClosingMixin


class SerialExecutor(ClosingMixin):
    """Runs batches one after another in the calling process."""

    num_workers: int = 1

    def map_batches(
        self, fn: Callable[..., Any], batches: Iterable[Any], shared: tuple[Any, ...] = ()
    ) -> Generator[tuple[int, Any], None, None]:
        for index, batch in enumerate(batches):
            yield index, fn(batch, *shared)

    def close(self) -> None:
        """Nothing to release."""
