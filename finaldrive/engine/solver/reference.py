"""The paper's method, compiled: y = [q, q', u] (eqs. 60-61), q'' from the augmented Lagrangian
(57)-(58), trapezoidal start then ABM with under-relaxation (62)-(66).

The relaxation length sigma* of eq. (41) is evaluated after each accepted step from that
step's F_x and kappa' and held through the next step (closing the algebraic loop).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm
from finaldrive.engine.model.constraints import phi
from finaldrive.engine.model.coordinates import ALPHA, BETA, N_CONSTRAINTS, N_COORDS, THETA, X1, X10, X11, Y10, Y11
from finaldrive.engine.model.diagnostics import (
    N_POWERS,
    integrate_powers,
    powers,
    record_series,
    retune_sigma,
    start_records,
    track_interval,
    track_state,
)
from finaldrive.engine.model.elements import (
    AUX_DUDT,
    AUX_FX,
    AUX_FZ_FRONT,
    AUX_FZ_REAR,
    AUX_KAPPA,
    AUX_RESID,
    AUX_TAUT,
    AUX_TENSION,
    N_AUX,
)
from finaldrive.engine.model.forces import applied_forces
from finaldrive.engine.model.tyre import relaxation_length
from finaldrive.engine.outcome import (
    CORRECTOR,
    FRONT_AIRBORNE,
    NONFINITE,
    OK,
    PAUSED,
    REAR_AIRBORNE,
    RESIDUAL,
)
from finaldrive.engine.solver.augmented_lagrangian import accelerations
from finaldrive.engine.solver.integrators import RHS_FAILED, make_steppers

N_STATE = 2 * N_COORDS + 1   # q, q', u
U = 2 * N_COORDS             # index of the tyre deformation state u in y
CHAIN_ROW = 29               # row of eq. (30): its multiplier is the chain tension

# Slots of the loop's saved state (st): everything a paused run needs to continue exactly
# (with the arrays hist, lam, sigma and aux, which the loop updates in place).
S_STEP, S_T, S_AIR_REAR, S_AIR_FRONT, S_ROW, S_SIGMA_PREV, S_STARTED = range(7)
N_ST = 7


@jit(allocates=True)
def motorcycle_rhs(t, y, ctx, out) -> int:
    """y' = f(t, y) for the motorcycle; returns a failure code (0 = ok)."""
    p, kind, rp, M, qg, longitudinal, lam, sigma, aux, lam_tol, lam_max, qdd = ctx
    q = y[:N_COORDS]
    qd = y[N_COORDS:U]
    Q = np.empty(N_COORDS)
    applied_forces(q, qd, y[U], sigma[0], p, qg, longitudinal, Q, aux)
    resid, _ = accelerations(q, qd, Q, p, kind, rp, M, lam, lam_tol, lam_max, qdd)
    aux[AUX_RESID] = resid
    aux[AUX_TENSION] = lam[CHAIN_ROW]
    aux[AUX_TAUT] = libm.hypot(q[X10] - q[X11], q[Y10] - q[Y11])
    out[:N_COORDS] = qd
    out[N_COORDS:U] = qdd
    out[U] = aux[AUX_DUDT]
    for i in range(N_STATE):
        if not math.isfinite(out[i]):
            return NONFINITE
    return OK


_trapezoidal_step, _abm_step = make_steppers(motorcycle_rhs)


@jit(allocates=True)
def run_reference(y, p, kind, rp, M, qg, longitudinal, dt, n_steps, n_trap, nu, tol, max_iter,
                  lam_tol, lam_max, max_resid, max_air_steps, stride, keep_series,
                  st, hist, lam, sigma, aux, ext, led, series, q_samples, max_steps):
    """Integrate n_steps of dt from the state y at rest; returns a code.

    Resumable: the loop's state is y and the arrays st (N_ST), hist (4 x N_STATE: f at the last
    four steps), lam (the multipliers, warm start of eq. 58), sigma (1: sigma* of eq. 41), aux
    (N_AUX), ext and led (engine.model.diagnostics); after max_steps steps it returns PAUSED and,
    called again with the same arrays, continues exactly where it stopped. Series rows every
    `stride` steps and the last (series and q_samples [q, q'] are preallocated; unused unless
    keep_series). Extremes and the energy ledger are tracked at every step. Codes: OK, PAUSED,
    NONFINITE, RESIDUAL, CORRECTOR, REAR_AIRBORNE, FRONT_AIRBORNE; st[S_STEP] is the step reached.
    """
    qdd = np.zeros(N_COORDS)
    ctx = (p, kind, rp, M, qg, longitudinal, lam, sigma, aux, lam_tol, lam_max, qdd)
    ynew = np.empty(N_STATE)
    fnew = np.empty(N_STATE)
    aux0 = np.empty(N_AUX)
    pw0 = np.zeros(N_POWERS)
    pw1 = np.zeros(N_POWERS)
    status = np.zeros(1, dtype=np.int64)
    if st[S_STARTED] == 0.0:
        st[:] = 0.0
        lam[:] = 0.0
        hist[:, :] = 0.0
        sigma[0] = relaxation_length(0.0, 0.0, 1.0, p)
        st[S_SIGMA_PREV] = sigma[0]
        start_records(ext, led)
        code = motorcycle_rhs(0.0, y, ctx, hist[0])
        if code != OK:
            return code
        track_state(ext, aux, p)
        if keep_series:
            record_series(series, 0, 0.0, y[X1], y[THETA], -y[N_COORDS + BETA], -y[N_COORDS + ALPHA], y[U],
                          sigma[0], aux[AUX_RESID], aux)
            q_samples[0] = y[:U]
            st[S_ROW] = 1.0
        st[S_STARTED] = 1.0
    step = int(st[S_STEP])
    t = st[S_T]
    row = int(st[S_ROW])
    done = 0
    while step < n_steps:
        if done >= max_steps:
            st[S_STEP], st[S_T], st[S_ROW] = step, t, row
            return PAUSED
        # the state's powers with the step's sigma* (aux holds them with the previous one)
        aux0[:] = aux
        retune_sigma(aux0, y[U], st[S_SIGMA_PREV], sigma[0], p, longitudinal)
        powers(aux0, p, pw0)
        if step < max(n_trap, 3):
            r = _trapezoidal_step(ctx, t, y, hist[0], dt, nu, tol, max_iter,
                                 N_COORDS, ynew, fnew, status)
        else:
            r = _abm_step(ctx, t, y, hist[0], hist[1], hist[2], hist[3], dt, nu,
                         tol, max_iter, N_COORDS, ynew, fnew, status)
        if r < 0:
            st[S_STEP], st[S_T] = step + 1, t
            return status[0] if r == RHS_FAILED else CORRECTOR
        for k in range(3, 0, -1):
            hist[k] = hist[k - 1]
        hist[0] = fnew
        y[:] = ynew
        t += dt
        step += 1
        done += 1
        track_state(ext, aux, p)
        track_interval(ext, aux0[AUX_FZ_REAR], aux0[AUX_FZ_FRONT], aux0[AUX_TENSION], aux0[AUX_TENSION], dt)
        powers(aux, p, pw1)
        integrate_powers(led, pw0, pw1, dt)
        # eq. (41) closed with the accepted step's values
        st[S_SIGMA_PREV] = sigma[0]
        sigma[0] = relaxation_length(aux[AUX_FX], aux[AUX_KAPPA], aux[AUX_FZ_REAR], p)
        if aux[AUX_RESID] > max_resid:
            st[S_STEP], st[S_T] = step, t
            return RESIDUAL
        st[S_AIR_REAR] = st[S_AIR_REAR] + 1.0 if aux[AUX_FZ_REAR] <= 0.0 else 0.0
        st[S_AIR_FRONT] = st[S_AIR_FRONT] + 1.0 if aux[AUX_FZ_FRONT] <= 0.0 else 0.0
        if st[S_AIR_REAR] > max_air_steps or st[S_AIR_FRONT] > max_air_steps:
            st[S_STEP], st[S_T] = step, t
            return REAR_AIRBORNE if st[S_AIR_REAR] > max_air_steps else FRONT_AIRBORNE
        if keep_series and (step % stride == 0 or step == n_steps):
            record_series(series, row, t, y[X1], y[THETA], -y[N_COORDS + BETA], -y[N_COORDS + ALPHA], y[U],
                          sigma[0], aux[AUX_RESID], aux)
            q_samples[row] = y[:U]
            row += 1
    st[S_STEP], st[S_T], st[S_ROW] = step, t, row
    return OK


def constraint_residual(q: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray) -> np.ndarray:
    """Phi(q) as a new array."""
    out = np.empty(N_CONSTRAINTS)
    phi(q, p, kind, rp, out)
    return out
