"""Accelerations by the augmented Lagrangian formulation, eqs. (57)-(58).

(M + alpha Phi_q^T Phi_q) q'' = Q - Phi_q^T [lambda_i + alpha (Phi_q' q' + 2 xi omega Phi' + omega^2 Phi)]
lambda_{i+1} = lambda_i + alpha (Phi'' + 2 xi omega Phi' + omega^2 Phi)

The leading matrix is factorised once per evaluation (Cholesky) and the multipliers are
iterated to convergence, warm-started from the previous evaluation's lambda.
"""

from __future__ import annotations

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import params as P
from finaldrive.engine.model.constraints import jacobian, phi, phiq_dot_qdot
from finaldrive.engine.model.coordinates import N_CONSTRAINTS, N_COORDS
from finaldrive.engine.model.linalg import cholesky, cholesky_solve, matvec, rmatvec


@jit(allocates=True)
def accelerations(q: np.ndarray, qd: np.ndarray, Q: np.ndarray, p: np.ndarray, kind: int,
                  rp: np.ndarray, M: np.ndarray, lam: np.ndarray, tol: float, max_iter: int,
                  qdd: np.ndarray) -> tuple[float, int]:
    """q'' into qdd, lambda updated in place. Returns (max|Phi|, iterations; -1 if not converged)."""
    res = np.empty(N_CONSTRAINTS)
    J = np.empty((N_CONSTRAINTS, N_COORDS))
    pdq = np.empty(N_CONSTRAINTS)
    phi(q, p, kind, rp, res)
    jacobian(q, p, kind, rp, J)
    phiq_dot_qdot(q, qd, p, kind, rp, pdq)
    alpha, xi, omega = p[P.AL_ALPHA], p[P.AL_XI], p[P.AL_OMEGA]
    # products by loops in a fixed order (engine.model.linalg), not BLAS's CPU-chosen kernels
    stab = np.empty(N_CONSTRAINTS)
    matvec(J, qd, stab)
    for i in range(N_CONSTRAINTS):            # Phi_q' q' + 2 xi w Phi' + w^2 Phi
        stab[i] = pdq[i] + 2.0 * xi * omega * stab[i] + omega * omega * res[i]
    A = np.empty((N_COORDS, N_COORDS))        # (57) leading matrix M + alpha Phi_q^T Phi_q
    for i in range(N_COORDS):
        for j in range(i + 1):
            s = 0.0
            for k in range(N_CONSTRAINTS):
                s += J[k, i] * J[k, j]
            A[i, j] = M[i, j] + alpha * s
    L = np.empty((N_COORDS, N_COORDS))
    cholesky(A, L)
    base = np.empty(N_COORDS)
    rmatvec(J, stab, base)
    for i in range(N_COORDS):
        base[i] = Q[i] - alpha * base[i]
    rhs = np.empty(N_COORDS)
    jq = np.empty(N_CONSTRAINTS)
    old = np.empty(N_COORDS)
    iters = -1
    for it in range(max_iter):
        old[:] = qdd
        rmatvec(J, lam, rhs)
        for i in range(N_COORDS):
            rhs[i] = base[i] - rhs[i]
        cholesky_solve(L, rhs, qdd)                                    # (57)
        matvec(J, qdd, jq)
        for i in range(N_CONSTRAINTS):
            lam[i] += alpha * (jq[i] + stab[i])                        # (58)
        change = 0.0
        scale = 1.0
        for i in range(N_COORDS):
            change = max(change, abs(qdd[i] - old[i]))
            scale = max(scale, abs(qdd[i]))
        if it > 0 and change <= tol * scale:
            iters = it + 1
            break
    return np.max(np.abs(res)), iters

