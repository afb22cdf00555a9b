"""Small dense linear algebra for the compiled model (no allocation)."""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.model.jit import jit


@jit
def cholesky_in_place(A: np.ndarray) -> None:
    """A (symmetric positive definite, upper triangle filled) -> its lower Cholesky factor."""
    n = A.shape[0]
    for j in range(n):
        for i in range(j + 1, n):
            A[i, j] = A[j, i]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        A[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / A[j, j]
        for i in range(j):
            A[i, j] = 0.0


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
