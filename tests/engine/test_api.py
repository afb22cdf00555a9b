"""The engine's result values."""

from __future__ import annotations

import numpy as np

from finaldrive.engine import STATUS_FAILED, BatchResult


def test_a_failed_batch_names_the_reason_for_every_design() -> None:
    batch = BatchResult.failed(np.array([[0.1, 0.02, 0.09], [0.2, 0.03, 0.1]]), "worker lost")
    assert batch.status == (STATUS_FAILED, STATUS_FAILED) and batch.reason == ("worker lost",) * 2
    assert np.isnan(batch.fitness_m).all() and not batch.ok.any() and batch.designs.shape == (2, 3)
