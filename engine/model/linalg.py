"""Small dense linear algebra for the compiled model (no allocation)."""

from __future__ import annotations

import numpy as np

from finaldrive.engine.model.jit import jit


@jit
def cholesky_solve(L: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
    """Solve L L^T x = b (L lower triangular)."""
    n = b.shape[0]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * x[k]
        x[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
