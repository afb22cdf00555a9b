"""A fake evaluation stream: instant, deterministic, and failing where told to."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from finaldrive.engine.api import BatchResult, SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.engine.vehicle import Vehicle

TERMINAL = {"succeeded", "failed", "cancelled"}


class FakeStream:
    """fitness = 20 - (a2 - 1)^2 - 10 (l2 - 0.1)^2 - 100 (rws - 0.09)^2 - road height;
    designs with l2 > ``fail_above_l2`` fail with reason "fake divergence"."""

    def __init__(self, *, batch_size: int = 4, fail_above_l2: float | None = None, delay: float = 0.0) -> None:
        self.batch_size = batch_size
        self.fail_above_l2 = fail_above_l2
        self.delay = delay
        self.simulated = 0
        self.gate = threading.Event()
        self.gate.set()

    def __call__(
        self, designs: np.ndarray, road: Road, settings: SimSettings, vehicle: Vehicle | None
    ) -> Iterator[tuple[np.ndarray, BatchResult]]:
        for start in range(0, len(designs), self.batch_size):
            self.gate.wait()
            if self.delay:
                threading.Event().wait(self.delay)
            rows = np.arange(start, min(start + self.batch_size, len(designs)))
            yield rows, self.batch(designs[rows], road)

    def batch(self, x: np.ndarray, road: Road) -> BatchResult:
        self.simulated += len(x)
        fitness = 20 - (x[:, 0] - 1) ** 2 - 10 * (x[:, 1] - 0.1) ** 2 - 100 * (x[:, 2] - 0.09) ** 2 - road.height
        failed = np.zeros(len(x), bool) if self.fail_above_l2 is None else x[:, 1] > self.fail_above_l2
        fitness = np.where(failed, np.nan, fitness)
        n = len(x)
        return BatchResult(
            designs=x, distance_m=fitness + 0.5, squat_ratio=np.full(n, 0.9), slack_m=np.full(n, 0.001),
            fitness_m=fitness, chain_length_m=np.full(n, 1.2), wall_s=np.full(n, 0.01),
            status=tuple("failed" if f else "ok" for f in failed),
            reason=tuple("fake divergence" if f else "" for f in failed),
        )


def wait_done(client: Any, job_id: int, timeout: float = 20.0, poll: float = 0.02) -> dict[str, Any]:
    """Poll GET /v1/jobs/{id} until the job reaches a terminal state."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["state"] in TERMINAL:
            return job
        time.sleep(poll)
    raise AssertionError(f"job {job_id} did not finish: {job}")


SWEEP = {"kind": "sweep", "roads": ["flat", "sine:0.025:3"], "grid": "a2_deg=0:90:30,l2=0.05|0.1|0.15,rws=0.09"}
DE = {"kind": "de", "roads": ["flat"], "de": {"np": 6, "iters": 4}, "seed": 3}
