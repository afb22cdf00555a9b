"""Small dense linear algebra for the compiled model, without BLAS or LAPACK: loops in a fixed order of
IEEE operations, the same bits on every CPU (OpenBLAS picks its kernels by the CPU: issue 30). None
allocates."""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit


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


@jit
def solve(A: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
    """Solve A x = b (A square; A is overwritten by its LU factors): Gaussian elimination with
    partial pivoting, as LAPACK's unblocked dgetf2 and dgetrs, in a fixed order of IEEE operations,
    so the same x on every CPU (LAPACK's kernels are chosen by the CPU, issue 30). Raises numpy's
    LinAlgError for a non-finite entry or a singular A, as np.linalg.solve."""
    n = b.shape[0]
    for i in range(n):
        for j in range(n):
            if not math.isfinite(A[i, j]):
                raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
        if not math.isfinite(b[i]):
            raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
        x[i] = b[i]
    for k in range(n):
        pivot = k
        for i in range(k + 1, n):
            if abs(A[i, k]) > abs(A[pivot, k]):
                pivot = i
        if A[pivot, k] == 0.0:
            raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
        if pivot != k:
            for j in range(n):
                A[k, j], A[pivot, j] = A[pivot, j], A[k, j]
            x[k], x[pivot] = x[pivot], x[k]
        for i in range(k + 1, n):
            f = A[i, k] / A[k, k]
            for j in range(k + 1, n):
                A[i, j] -= f * A[k, j]
            x[i] -= f * x[k]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= A[i, j] * x[j]
        x[i] = s / A[i, i]


@jit
def cholesky(A: np.ndarray, L: np.ndarray) -> None:
    """A = L L^T (A symmetric positive definite; its lower triangle read), in a fixed order of IEEE
    operations (LAPACK's dpotrf is chosen by the CPU). Raises numpy's LinAlgError if A is not
    positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            raise np.linalg.LinAlgError("Matrix is not positive definite")
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0


@jit(plain_from_python=True)
def dot(a: np.ndarray, b: np.ndarray) -> float:
    """a . b, summed in order (BLAS's ddot is chosen by the CPU and sums in its own order)."""
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@jit
def matvec(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out = A x, each row summed in order."""
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s


@jit
def rmatvec(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out = A^T x, each column summed in order."""
    for j in range(A.shape[1]):
        out[j] = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[j] += A[i, j] * x[i]


@jit
def matmul(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """out = A B, each entry summed in order."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            s = 0.0
            for k in range(A.shape[1]):
                s += A[i, k] * B[k, j]
            out[i, j] = s
