"""The paper's method, compiled: y = [q, q', u] (eqs. 60-61), q'' from the augmented Lagrangian
(57)-(58), trapezoidal start then ABM with under-relaxation (62)-(66).

The relaxation length sigma* of eq. (41) is evaluated after each accepted step from that
step's F_x and kappa' and held through the next step (closing the algebraic loop).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.jit.records import Record
from finaldrive.engine.model import libm
from finaldrive.engine.model.constraints import phi
from finaldrive.engine.model.coordinates import ALPHA, BETA, N_CONSTRAINTS, N_COORDS, THETA, X1, X10, X11, Y10, Y11
from finaldrive.engine.model.diagnostics import (
    integrate_powers,
    powers,
    record_series,
    retune_sigma,
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

#: A run's settings (the record ``run``): name, type (each given by the caller). ``dt`` [s] the step,
#: ``n_steps`` the steps of the run, ``n_trap`` the trapezoidal steps at its start, ``nu`` the
#: under-relaxation of eq. (66), ``tol`` and ``max_iter`` the corrector's (eqs. 62-65), ``lam_tol`` and
#: ``lam_max`` the augmented Lagrangian's (eq. 58), ``max_resid`` [m] the largest constraint residual,
#: ``max_air_steps`` the most steps a wheel may be off the road, a series row every ``stride`` steps
#: when ``keep_series``, ``chunk_steps`` the steps after which the loop pauses.
REFERENCE_RUN = Record(
    ("longitudinal", np.bool_, None), ("dt", np.float64, None), ("n_steps", np.int64, None),
    ("n_trap", np.int64, None), ("nu", np.float64, None), ("tol", np.float64, None), ("max_iter", np.int64, None),
    ("lam_tol", np.float64, None), ("lam_max", np.int64, None), ("max_resid", np.float64, None),
    ("max_air_steps", np.int64, None), ("stride", np.int64, None), ("keep_series", np.bool_, None),
    ("chunk_steps", np.int64, None),
)
#: The loop's saved state (the record ``state``): everything a paused run needs to continue exactly,
#: with the arrays hist, lam and aux, which the loop updates in place. ``step`` the steps taken, ``t``
#: [s] the time reached, ``row`` the next series row, ``air_rear``/``air_front`` the steps each wheel
#: has been off the road, ``sigma`` [m] sigma* of eq. (41) for the next step, ``sigma_prev`` [m] the
#: one of the last.
REFERENCE_STATE = Record(
    ("started", np.bool_, False), ("step", np.int64, 0), ("t", np.float64, 0.0), ("row", np.int64, 0),
    ("air_rear", np.int64, 0), ("air_front", np.int64, 0), ("sigma", np.float64, 0.0),
    ("sigma_prev", np.float64, 0.0),
)


@jit(allocates=True)
def motorcycle_rhs(t, y, ctx, out) -> int:
    """y' = f(t, y) for the motorcycle; returns a failure code (0 = ok)."""
    p, kind, rp, M, qg, run, state, lam, aux, qdd = ctx
    q = y[:N_COORDS]
    qd = y[N_COORDS:U]
    Q = np.empty(N_COORDS)
    applied_forces(q, qd, y[U], state.sigma, p, qg, run.longitudinal, Q, aux)
    resid, _ = accelerations(q, qd, Q, p, kind, rp, M, lam, run.lam_tol, run.lam_max, qdd)
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
def run_reference(y, p, kind, rp, M, qg, settings, saved, tracked, hist, lam, aux, series, q_samples):
    """Integrate run.n_steps of run.dt from the state y at rest; returns a code.

    Its records, each a one-element array (engine.jit.records): ``settings`` the run's (``run``, a
    :data:`REFERENCE_RUN`), ``saved`` the loop's state (``state``, :data:`REFERENCE_STATE`), ``tracked``
    what it tracks (``out``, engine.model.diagnostics.TRACKED). Resumable: the loop's state is y, those
    records and the arrays hist (4 x N_STATE: f at the last four steps), lam
    (the multipliers, warm start of eq. 58) and aux (N_AUX); after run.chunk_steps steps it returns
    PAUSED and, called again with the same records and arrays, continues exactly where it stopped.
    Series rows every run.stride steps and the last (series and q_samples [q, q'] are preallocated;
    unused unless run.keep_series). Extremes and the energy ledger are tracked at every step. Codes:
    OK, PAUSED, NONFINITE, RESIDUAL, CORRECTOR, REAR_AIRBORNE, FRONT_AIRBORNE; state.step is the step
    reached.
    """
    run, state, out = settings[0], saved[0], tracked[0]   # views: what the loop writes is in the arrays
    qdd = np.zeros(N_COORDS)
    ctx = (p, kind, rp, M, qg, run, state, lam, aux, qdd)
    ynew = np.empty(N_STATE)
    fnew = np.empty(N_STATE)
    aux0 = np.empty(N_AUX)
    status = np.zeros(1, dtype=np.int64)
    dt, n_steps, nu, tol, max_iter = run.dt, run.n_steps, run.nu, run.tol, run.max_iter
    if not state.started:
        lam[:] = 0.0
        hist[:, :] = 0.0
        state.sigma = relaxation_length(0.0, 0.0, 1.0, p)
        state.sigma_prev = state.sigma
        code = motorcycle_rhs(0.0, y, ctx, hist[0])
        if code != OK:
            return code
        track_state(out, aux, p)
        if run.keep_series:
            record_series(series, 0, 0.0, y[X1], y[THETA], -y[N_COORDS + BETA], -y[N_COORDS + ALPHA], y[U],
                          state.sigma, aux[AUX_RESID], aux)
            q_samples[0] = y[:U]
            state.row = 1
        state.started = True
    step, t, row = state.step, state.t, state.row
    done = 0
    while step < n_steps:
        if done >= run.chunk_steps:
            state.step, state.t, state.row = step, t, row
            return PAUSED
        # the state's powers with the step's sigma* (aux holds them with the previous one)
        aux0[:] = aux
        retune_sigma(aux0, y[U], state.sigma_prev, state.sigma, p, run.longitudinal)
        pw0 = powers(aux0, p)
        if step < max(run.n_trap, 3):
            r = _trapezoidal_step(ctx, t, y, hist[0], dt, nu, tol, max_iter,
                                 N_COORDS, ynew, fnew, status)
        else:
            r = _abm_step(ctx, t, y, hist[0], hist[1], hist[2], hist[3], dt, nu,
                         tol, max_iter, N_COORDS, ynew, fnew, status)
        if r < 0:
            state.step, state.t = step + 1, t
            return status[0] if r == RHS_FAILED else CORRECTOR
        for k in range(3, 0, -1):
            hist[k] = hist[k - 1]
        hist[0] = fnew
        y[:] = ynew
        t += dt
        step += 1
        done += 1
        track_state(out, aux, p)
        track_interval(out, aux0[AUX_FZ_REAR], aux0[AUX_FZ_FRONT], aux0[AUX_TENSION], aux0[AUX_TENSION], dt)
        integrate_powers(out, pw0, powers(aux, p), dt)
        # eq. (41) closed with the accepted step's values
        state.sigma_prev = state.sigma
        state.sigma = relaxation_length(aux[AUX_FX], aux[AUX_KAPPA], aux[AUX_FZ_REAR], p)
        if aux[AUX_RESID] > run.max_resid:
            state.step, state.t = step, t
            return RESIDUAL
        state.air_rear = state.air_rear + 1 if aux[AUX_FZ_REAR] <= 0.0 else 0
        state.air_front = state.air_front + 1 if aux[AUX_FZ_FRONT] <= 0.0 else 0
        if state.air_rear > run.max_air_steps or state.air_front > run.max_air_steps:
            state.step, state.t = step, t
            return REAR_AIRBORNE if state.air_rear > run.max_air_steps else FRONT_AIRBORNE
        if run.keep_series and (step % run.stride == 0 or step == n_steps):
            record_series(series, row, t, y[X1], y[THETA], -y[N_COORDS + BETA], -y[N_COORDS + ALPHA], y[U],
                          state.sigma, aux[AUX_RESID], aux)
            q_samples[row] = y[:U]
            row += 1
    state.step, state.t, state.row = step, t, row
    return OK


def constraint_residual(q: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray) -> np.ndarray:
    """Phi(q) as a new array."""
    out = np.empty(N_CONSTRAINTS)
    phi(q, p, kind, rp, out)
    return out
