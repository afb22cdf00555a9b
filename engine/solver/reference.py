"""The paper's method, compiled: y = [q, q', u] (eqs. 60-61), q'' from the augmented Lagrangian
(57)-(58), trapezoidal start then ABM with under-relaxation (62)-(66).

The relaxation length sigma* of eq. (41) is evaluated after each accepted step from that
step's F_x and kappa' and held through the next step (closing the algebraic loop).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.model.constraints import phi
from finaldrive.engine.model.coordinates import ALPHA, BETA, N_CONSTRAINTS, N_COORDS, THETA, X1, X10, X11, Y10, Y11
from finaldrive.engine.model.forces import (
    AUX_DUDT,
    AUX_FX,
    AUX_FZ_FRONT,
    AUX_FZ_REAR,
    AUX_KAPPA,
    AUX_RE,
    N_AUX,
    applied_forces,
)
from finaldrive.engine.model.jit import jit
from finaldrive.engine.model.tyre import relaxation_length
from finaldrive.engine.outcome import CORRECTOR, FRONT_AIRBORNE, N_SERIES, NONFINITE, OK, REAR_AIRBORNE, RESIDUAL
from finaldrive.engine.solver.augmented_lagrangian import accelerations
from finaldrive.engine.solver.integrators import RHS_FAILED, make_steppers

N_STATE = 2 * N_COORDS + 1   # q, q', u
U = 2 * N_COORDS             # index of the tyre deformation state u in y
CHAIN_ROW = 29               # row of eq. (30): its multiplier is the chain tension

_AUX_RESID = N_AUX  # slot after the force outputs: max|Phi| of the last evaluation


@jit
def motorcycle_rhs(t, y, ctx, out) -> int:
    """y' = f(t, y) for the motorcycle; returns a failure code (0 = ok)."""
    p, kind, rp, M, qg, longitudinal, lam, sigma, aux, lam_tol, lam_max, qdd = ctx
    q = y[:N_COORDS]
    qd = y[N_COORDS:U]
    Q = np.empty(N_COORDS)
    applied_forces(q, qd, y[U], sigma[0], p, qg, longitudinal, Q, aux)
    resid, _ = accelerations(q, qd, Q, p, kind, rp, M, lam, lam_tol, lam_max, qdd)
    aux[_AUX_RESID] = resid
    out[:N_COORDS] = qd
    out[N_COORDS:U] = qdd
    out[U] = aux[AUX_DUDT]
    for i in range(N_STATE):
        if not math.isfinite(out[i]):
            return NONFINITE
    return OK


_trapezoidal_step, _abm_step = make_steppers(motorcycle_rhs)


@jit
def _record(row, t, y, lam, sigma, aux, out):
    q = y[:N_COORDS]
    out[row, 0] = t
    out[row, 1] = q[X1]
    out[row, 2] = q[THETA]
    out[row, 3] = lam[CHAIN_ROW]
    out[row, 4] = aux[AUX_FZ_REAR]
    out[row, 5] = aux[AUX_FZ_FRONT]
    out[row, 6] = aux[AUX_KAPPA]
    out[row, 7] = aux[AUX_FX]
    out[row, 8] = aux[AUX_RE]
    out[row, 9] = -y[N_COORDS + BETA]
    out[row, 10] = -y[N_COORDS + ALPHA]
    out[row, 11] = math.hypot(q[X10] - q[X11], q[Y10] - q[Y11])
    out[row, 12] = y[U]
    out[row, 13] = sigma
    out[row, 14] = aux[_AUX_RESID]


@jit
def run_reference(y0, p, kind, rp, M, qg, longitudinal, dt, n_steps, n_trap, nu, tol, max_iter,
                  lam_tol, lam_max, max_resid, max_air_steps, stride, keep_series):
    """Integrate n_steps from the state y0 at rest.

    Returns (code, failed_step, y_end, taut_min, taut_max, series, q_samples): series rows
    every `stride` steps (and the last), q_samples [q, q'] at those rows; both are empty
    unless keep_series.
    """
    lam = np.zeros(N_CONSTRAINTS)
    sigma = np.array([relaxation_length(0.0, 0.0, 1.0, p)])
    aux = np.zeros(N_AUX + 1)
    qdd = np.zeros(N_COORDS)
    ctx = (p, kind, rp, M, qg, longitudinal, lam, sigma, aux, lam_tol, lam_max, qdd)
    n_rows = (n_steps // stride + 2) if keep_series else 0
    series = np.zeros((n_rows, N_SERIES))
    q_samples = np.zeros((n_rows, U))
    hist = np.zeros((4, N_STATE))
    y = y0.copy()
    ynew = np.empty(N_STATE)
    fnew = np.empty(N_STATE)
    status = np.zeros(1, dtype=np.int64)
    taut_min = math.inf
    taut_max = -math.inf
    code = motorcycle_rhs(0.0, y, ctx, hist[0])
    if code != OK:
        return code, 0, y, taut_min, taut_max, series, q_samples
    taut_min = math.hypot(y[X10] - y[X11], y[Y10] - y[Y11])
    taut_max = taut_min
    row = 0
    if keep_series:
        _record(row, 0.0, y, lam, sigma[0], aux, series)
        q_samples[row] = y[:U]
        row += 1
    air_rear = 0
    air_front = 0
    t = 0.0
    for step in range(n_steps):
        if step < max(n_trap, 3):
            r = _trapezoidal_step(ctx, t, y, hist[0], dt, nu, tol, max_iter,
                                 N_COORDS, ynew, fnew, status)
        else:
            r = _abm_step(ctx, t, y, hist[0], hist[1], hist[2], hist[3], dt, nu,
                         tol, max_iter, N_COORDS, ynew, fnew, status)
        if r < 0:
            code = status[0] if r == RHS_FAILED else CORRECTOR
            return code, step + 1, y, taut_min, taut_max, series, q_samples
        for k in range(3, 0, -1):
            hist[k] = hist[k - 1]
        hist[0] = fnew
        y[:] = ynew
        t += dt
        # eq. (41) closed with the accepted step's values
        sigma[0] = relaxation_length(aux[AUX_FX], aux[AUX_KAPPA], aux[AUX_FZ_REAR], p)
        if aux[_AUX_RESID] > max_resid:
            return RESIDUAL, step + 1, y, taut_min, taut_max, series, q_samples
        air_rear = air_rear + 1 if aux[AUX_FZ_REAR] <= 0.0 else 0
        air_front = air_front + 1 if aux[AUX_FZ_FRONT] <= 0.0 else 0
        if air_rear > max_air_steps:
            return REAR_AIRBORNE, step + 1, y, taut_min, taut_max, series, q_samples
        if air_front > max_air_steps:
            return FRONT_AIRBORNE, step + 1, y, taut_min, taut_max, series, q_samples
        taut = math.hypot(y[X10] - y[X11], y[Y10] - y[Y11])
        taut_min = min(taut_min, taut)
        taut_max = max(taut_max, taut)
        if keep_series and ((step + 1) % stride == 0 or step + 1 == n_steps):
            _record(row, t, y, lam, sigma[0], aux, series)
            q_samples[row] = y[:U]
            row += 1
    return OK, n_steps, y, taut_min, taut_max, series[:row], q_samples[:row]


def constraint_residual(q: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray) -> np.ndarray:
    """Phi(q) as a new array."""
    out = np.empty(N_CONSTRAINTS)
    phi(q, p, kind, rp, out)
    return out
