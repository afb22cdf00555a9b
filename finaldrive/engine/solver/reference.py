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

#: A reference run's settings (the record ``settings``), each given by the caller; SimSettings' names.
REFERENCE_SETTINGS = Record(
    ("tyre_longitudinal", np.bool_, None),        # the rear tyre's longitudinal force on
    ("dt", np.float64, None),                     # [s] the step
    ("n_steps", np.int64, None),                  # the steps of the run
    ("trapezoidal_steps", np.int64, None),        # trapezoidal steps at its start (eq. 62)
    ("under_relaxation", np.float64, None),       # nu of eq. (66)
    ("corrector_tol", np.float64, None),          # the corrector's (eqs. 63-65)
    ("corrector_max_iter", np.int64, None),
    ("lambda_tol", np.float64, None),             # the augmented Lagrangian's (eq. 58)
    ("lambda_max_iter", np.int64, None),
    ("max_constraint_residual", np.float64, None),  # [m] max|Phi| beyond which the run fails
    ("max_airborne_steps", np.int64, None),       # the most steps a wheel may be off the road
    ("series_stride", np.int64, None),            # a series row every this many steps
    ("keep_series", np.bool_, None),              # the series and states recorded
    ("chunk_steps", np.int64, None),              # steps after which the loop pauses
)
#: A reference run's saved state (the record ``state``): everything a paused run needs to continue
#: exactly, with the arrays hist, lam and aux.
REFERENCE_STATE = Record(
    ("started", np.bool_, False),    # the start done: the others below hold the run's
    ("step", np.int64, 0),           # the steps taken
    ("t", np.float64, 0.0),          # [s] the time reached
    ("row", np.int64, 0),            # the next series row
    ("air_rear", np.int64, 0),       # steps the rear wheel has been off the road
    ("air_front", np.int64, 0),      # the front wheel
    ("sigma", np.float64, 0.0),      # [m] sigma* of eq. (41) for the next step (set at the start)
    ("sigma_prev", np.float64, 0.0),  # [m] the last step's
)


@jit(allocates=True)
def motorcycle_rhs(t, y, ctx, out) -> int:
    """y' = f(t, y) for the motorcycle; returns a failure code (0 = ok)."""
    p, kind, rp, M, qg, settings, state, lam, aux, qdd = ctx
    q = y[:N_COORDS]
    qd = y[N_COORDS:U]
    Q = np.empty(N_COORDS)
    applied_forces(q, qd, y[U], state.sigma, p, qg, settings.tyre_longitudinal, Q, aux)
    resid, _ = accelerations(q, qd, Q, p, kind, rp, M, lam, settings.lambda_tol, settings.lambda_max_iter, qdd)
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
def run_reference(y, p, kind, rp, M, qg, settings, state, tracked, hist, lam, aux, series, q_samples):
    """Integrate settings.n_steps of settings.dt from the state y at rest; returns a code.

    Its records (engine.jit.records), each a one-element array: ``settings``
    (:data:`REFERENCE_SETTINGS`), ``state`` (:data:`REFERENCE_STATE`) and ``tracked``
    (engine.model.diagnostics.TRACKED), the last two fresh from their ``new()`` at the start.
    Resumable: the loop's state is y, state, tracked and the arrays hist (4 x N_STATE: f at the last
    four steps), lam (the multipliers, warm start of eq. 58) and aux (N_AUX), both set at the start;
    after settings.chunk_steps steps it returns PAUSED and, called again with the same records and
    arrays, continues exactly where it stopped. Series rows every settings.series_stride steps and the
    last (series and q_samples [q, q'] are preallocated; unused unless settings.keep_series). Extremes
    and the energy ledger are tracked at every step. Codes: OK, PAUSED, NONFINITE, RESIDUAL, CORRECTOR,
    REAR_AIRBORNE, FRONT_AIRBORNE; state.step is the step reached.
    """
    settings, state, tracked = settings[0], state[0], tracked[0]   # views: what the loop writes is in the arrays
    qdd = np.zeros(N_COORDS)
    ctx = (p, kind, rp, M, qg, settings, state, lam, aux, qdd)
    ynew = np.empty(N_STATE)
    fnew = np.empty(N_STATE)
    aux0 = np.empty(N_AUX)
    status = np.zeros(1, dtype=np.int64)
    # the settings the loop reads at every step, as locals (the compiler keeps them in registers)
    dt, n_steps, nu, tol = settings.dt, settings.n_steps, settings.under_relaxation, settings.corrector_tol
    max_iter, max_air = settings.corrector_max_iter, settings.max_airborne_steps
    n_trap = max(settings.trapezoidal_steps, 3)
    if not state.started:
        lam[:] = 0.0
        hist[:, :] = 0.0
        state.sigma = relaxation_length(0.0, 0.0, 1.0, p)
        state.sigma_prev = state.sigma
        code = motorcycle_rhs(0.0, y, ctx, hist[0])
        if code != OK:
            return code
        track_state(tracked, aux, p)
        if settings.keep_series:
            record_series(series, 0, 0.0, y[X1], y[THETA], -y[N_COORDS + BETA], -y[N_COORDS + ALPHA], y[U],
                          state.sigma, aux[AUX_RESID], aux)
            q_samples[0] = y[:U]
            state.row = 1
        state.started = True
    step, t, row = state.step, state.t, state.row
    done = 0
    while step < n_steps:
        if done >= settings.chunk_steps:
            _save(state, step, t, row)
            return PAUSED
        # the state's powers with the step's sigma* (aux holds them with the previous one)
        aux0[:] = aux
        retune_sigma(aux0, y[U], state.sigma_prev, state.sigma, p, settings.tyre_longitudinal)
        pw0 = powers(aux0, p)
        if step < n_trap:
            r = _trapezoidal_step(ctx, t, y, hist[0], dt, nu, tol, max_iter,
                                 N_COORDS, ynew, fnew, status)
        else:
            r = _abm_step(ctx, t, y, hist[0], hist[1], hist[2], hist[3], dt, nu,
                         tol, max_iter, N_COORDS, ynew, fnew, status)
        if r < 0:
            _save(state, step + 1, t, row)
            return status[0] if r == RHS_FAILED else CORRECTOR
        for k in range(3, 0, -1):
            hist[k] = hist[k - 1]
        hist[0] = fnew
        y[:] = ynew
        t += dt
        step += 1
        done += 1
        track_state(tracked, aux, p)
        track_interval(tracked, aux0[AUX_FZ_REAR], aux0[AUX_FZ_FRONT], aux0[AUX_TENSION], aux0[AUX_TENSION], dt)
        integrate_powers(tracked, pw0, powers(aux, p), dt)
        # eq. (41) closed with the accepted step's values
        state.sigma_prev = state.sigma
        state.sigma = relaxation_length(aux[AUX_FX], aux[AUX_KAPPA], aux[AUX_FZ_REAR], p)
        if aux[AUX_RESID] > settings.max_constraint_residual:
            _save(state, step, t, row)
            return RESIDUAL
        state.air_rear = state.air_rear + 1 if aux[AUX_FZ_REAR] <= 0.0 else 0
        state.air_front = state.air_front + 1 if aux[AUX_FZ_FRONT] <= 0.0 else 0
        if state.air_rear > max_air or state.air_front > max_air:
            _save(state, step, t, row)
            return REAR_AIRBORNE if state.air_rear > max_air else FRONT_AIRBORNE
        if settings.keep_series and (step % settings.series_stride == 0 or step == n_steps):
            record_series(series, row, t, y[X1], y[THETA], -y[N_COORDS + BETA], -y[N_COORDS + ALPHA], y[U],
                          state.sigma, aux[AUX_RESID], aux)
            q_samples[row] = y[:U]
            row += 1
    _save(state, step, t, row)
    return OK


@jit
def _save(state, step, t, row):
    """The loop's carried values into its state record (a failed run's too: its step is the one reached)."""
    state.step, state.t, state.row = step, t, row


def constraint_residual(q: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray) -> np.ndarray:
    """Phi(q) as a new array."""
    out = np.empty(N_CONSTRAINTS)
    phi(q, p, kind, rp, out)
    return out
