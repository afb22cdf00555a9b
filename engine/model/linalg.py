"""Small dense linear algebra for the compiled model (no allocation in cholesky_solve)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from finaldrive.engine.model.jit import Kernel, jit

#: LAPACK's dgesv as numba binds it for np.linalg.solve (numba.np.linalg), and the type of its
#: pivot indices: set by _bind_gesv when solve is first compiled (importing numba).
_GESV: Any = None
_PIVOT: Any = None
_DOUBLE = ord("d")


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


def _bind_gesv() -> None:
    global _GESV, _PIVOT
    from numba import types
    from numba.np.linalg import _LAPACK, F_INT_nptype, ensure_lapack

    ensure_lapack()
    _GESV, _PIVOT = _LAPACK().numba_xgesv(types.float64), F_INT_nptype


def _solve(A: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
    n = b.shape[0]
    for i in range(n):
        for j in range(n):
            if not math.isfinite(A[i, j]):
                raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
        if not math.isfinite(b[i]):
            raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
    a = np.empty((n, n)).T   # Fortran order, as LAPACK reads it
    for i in range(n):
        x[i] = b[i]
        for j in range(n):
            a[i, j] = A[i, j]
    pivots = np.empty(n, dtype=_PIVOT)
    if _GESV(_DOUBLE, n, 1, a.ctypes, n, pivots.ctypes, x.ctypes, n) != 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")


def _solve_python(A: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
    x[:] = np.linalg.solve(A, b)


#: Solve A x = b (A square, x contiguous) as np.linalg.solve does in compiled code, by the same
#: LAPACK call (the same x, bit for bit), and raise numpy's LinAlgError where it does (a non-finite
#: entry, a singular A), but without the array checks whose compiled error messages were a sixth
#: of the fast method's compilation. Plain numpy inside engine.model.jit.interpreted.
solve = Kernel(_solve, prepare=_bind_gesv, python=_solve_python, allocates=True)
