"""Linearly implicit integration of the minimal-coordinate model, with step-size control.

Two Rosenbrock-W methods; high_order (the one place that chooses) takes ROS34PW2 (order 3,
engine.fast.wstep) on smooth roads (flat, sine, bump) with the paper's single chain run, and ROS2
elsewhere: on piecewise-linear profiles, whose slope kinks inside a step ROS34PW2's embedded
estimate does not see (it does not converge there), and with the two-run chain, whose events are
located in ROS2's loop below (ros2_only, SimSettings.fast_ros2: ROS2 everywhere, for verification).

ROS2 (Verwer, Spee, Blom & Hundsdorfer 1999), a Rosenbrock-W method: L-stable and of order 2
for any matrix W = I - gamma h J, gamma = 1 + 1/sqrt(2):
    W k1 = f(y_n),   W k2 = f(y_n + h k1) - 2 k1,   y_{n+1} = y_n + h (3/2 k1 + 1/2 k2).
J holds only the fast tyre terms (the paper's stiffness, section 3.2): d(u')/du = -|V_x|/sigma*,
d(u')/dz' (through V_sx), and dz''/du = M^-1 b dF_x/du. W is then solved in closed form.

The relaxation length sigma* of eq. (41) is evaluated at the start of each step from F_x and
kappa' of that state (computed with the previous sigma*) and held through the step.
Step size: local error estimate y_{n+1} - (y_n + h k1) (ROS2's embedded first-order
solution) against a tolerance; steps shrink in the slip transients after a wheel lands and
grow to h_max elsewhere.

With the two-run chain (a state of N_STATE_TWO_RUNS, engine.fast.chain_runs) each step is taken in
one mode of the chain; a step whose end would see the engaged run push, or the free sprocket close a
gap, is shortened (secant on the tension or the gap) until it ends at the event; the run is then
released at the start of the next step, or re-engaged by its impact at the end of this one. The elastic
chain (chain_compliance = 1) has the same state in one mode, ELASTIC, throughout: no events.
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.fast.bodies import N_DOF, N_WS, W_B, W_C, ZBETA, ZTHETA, ZX1, design_constants, mass_solve
from finaldrive.engine.fast.chain_runs import (
    GAP_TOL,
    TENSION_TOL,
    closing_run,
    engage,
    gap,
    project,
    released,
    run_tension,
)
from finaldrive.engine.fast.minimal import (
    ELASTIC,
    FREE,
    LOWER,
    N_STATE,
    N_STATE_TWO_RUNS,
    UPPER,
    ZALPHA_DOT,
    ZPLAY,
    ZU,
    fast_rhs,
)
from finaldrive.engine.fast.wstep import ERROR_ORDER, N_STAGES, attempt, w_solve
from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.jit.records import Record
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.diagnostics import (
    integrate_powers,
    powers,
    record_series,
    retune_sigma,
    track_interval,
    track_state,
)
from finaldrive.engine.model.elements import (
    AUX_ALPHA_DOT,
    AUX_DUDT,
    AUX_FX,
    AUX_FZ_FRONT,
    AUX_FZ_REAR,
    AUX_KAPPA,
    AUX_SLOPE,
    AUX_TAUT,
    AUX_TAUT_RATE,
    AUX_TENSION,
    AUX_VX,
    N_AUX,
)
from finaldrive.engine.model.road import PROFILE
from finaldrive.engine.model.tyre import relaxation_length
from finaldrive.engine.outcome import FRONT_AIRBORNE, NONFINITE, OK, PAUSED, REAR_AIRBORNE

GAMMA = 1.0 + 1.0 / math.sqrt(2.0)
#: Step-size control limits.
MAX_GROWTH = 2.0
MIN_SHRINK = 0.2
MIN_STEP = 1.0e-7
#: First step tried [s] (the control adapts it at once).
FIRST_STEP = 1.0e-3

#: Shortened tries of one step that locate a chain event before the step is taken as it is.
MAX_EVENT_TRIES = 40

#: A fast run's settings (the record ``settings``), each given by the caller; SimSettings' names.
FAST_SETTINGS = Record(
    ("tyre_longitudinal", np.bool_, None),   # the rear tyre's longitudinal force on
    ("duration", np.float64, None),          # [s] the run's end
    ("dt_out", np.float64, None),            # [s] the series' interval
    ("fast_tolerance", np.float64, None),    # the local error's tolerance
    ("fast_max_step", np.float64, None),     # [s] ROS34PW2's largest step (ROS2: half)
    ("fast_ros2", np.bool_, None),           # ROS2 on every road
    ("max_airborne_time", np.float64, None),  # [s] the longest a wheel may be off the road
    ("keep_series", np.bool_, None),         # the series and states recorded
    ("chunk_steps", np.int64, None),         # accepted steps after which the loop pauses
)
#: A fast run's saved state (the record ``state``): everything a paused run needs to continue exactly.
FAST_STATE = Record(
    ("started", np.bool_, False),   # the start done: the others below hold the run's
    ("t", np.float64, 0.0),         # [s] the time reached
    ("h", np.float64, 0.0),         # [s] the next step's size (set at the start)
    ("sigma", np.float64, 0.0),     # [m] sigma* of eq. (41) (set at the start)
    ("prev_taut", np.float64, 0.0),  # [m] the taut run's length at t
    ("prev_rate", np.float64, 0.0),  # [m/s] and its rate
    ("air_rear", np.float64, 0.0),  # [s] how long the rear wheel has been off the road
    ("air_front", np.float64, 0.0),  # [s] the front wheel
    ("row", np.int64, 0),           # the next series row
    ("mode", np.int64, 0),          # the chain's (engine.fast.minimal: UPPER, LOWER, FREE, ELASTIC; set at the start)
)


@jit
def high_order(kind: int, two_runs: bool) -> bool:
    """Whether run_fast steps with ROS34PW2 (else ROS2, with half its largest step h_max): on a
    smooth road (not a piecewise-linear profile) without the two-run chain's events."""
    return kind != PROFILE and not two_runs


@jit
def _store(states, row, y):
    """A row of the recorded states: z, z' and, in a third column block of one, the two-run or the elastic
    chain's e."""
    for i in range(2 * N_DOF):   # a loop, not a slice: no compiled shape check
        states[row, i] = y[i]
    if states.shape[1] > 2 * N_DOF:
        states[row, 2 * N_DOF] = y[ZPLAY]


@jit
def _error_norm(e, scale, n):
    """Weighted RMS of the local error estimate e over its first n components (absolute scales)."""
    acc = 0.0
    for i in range(n):
        r = e[i] / scale[i]
        acc += r * r
    return math.sqrt(acc / n)


@jit
def _taut_extremes(tracked, l0, r0, l1, r1, h):
    """Extremes of L_taut inside a step, from its values l and rates r at both ends: the stationary
    points of their cubic Hermite interpolant l(s), s in (0, 1) (l'(s) = a s^2 + b s + c)."""
    a = 6.0 * (l0 - l1) + 3.0 * h * (r0 + r1)
    b = -6.0 * (l0 - l1) - h * (4.0 * r0 + 2.0 * r1)
    c = h * r0
    if a == 0.0:
        if b == 0.0:
            return
        roots = (-c / b, -1.0)
    else:
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return
        q = -0.5 * (b + math.copysign(math.sqrt(disc), b))  # the stable pair of roots
        roots = (q / a, c / q if q != 0.0 else -1.0)
    for s in roots:
        if 0.0 < s < 1.0:
            extreme = ((1.0 + 2.0 * s) * (1.0 - s) ** 2 * l0 + s * (1.0 - s) ** 2 * h * r0
                       + s * s * (3.0 - 2.0 * s) * l1 + s * s * (s - 1.0) * h * r1)
            tracked.taut_min_m = min(tracked.taut_min_m, extreme)
            tracked.taut_max_m = max(tracked.taut_max_m, extreme)


@jit
def _hermite(y0, f0, y1, f1, h, s, out):
    """Cubic Hermite interpolation inside a step at the fraction s (dense output, 3rd order)."""
    h00 = (1.0 + 2.0 * s) * (1.0 - s) * (1.0 - s)
    h10 = s * (1.0 - s) * (1.0 - s)
    h01 = s * s * (3.0 - 2.0 * s)
    h11 = s * s * (s - 1.0)
    for i in range(y0.shape[0]):
        out[i] = h00 * y0[i] + h10 * h * f0[i] + h01 * y1[i] + h11 * h * f1[i]


@jit
def _event_fraction(y, ynew, mode, tension, tension_end, p, geo):
    """Two-run chain: the fraction of a step to try instead when its end passes a chain event (the
    engaged run pushing beyond TENSION_TOL, a free run's gap closing beyond GAP_TOL), by the secant
    through the event function's values at both ends; 1 when the step may be taken."""
    if mode != FREE:
        t0, t1 = run_tension(mode, tension), run_tension(mode, tension_end)
        return t0 / (t0 - t1) if t1 < -TENSION_TOL else 1.0
    run, g1 = closing_run(ynew, p, geo)
    if g1 >= -GAP_TOL:
        return 1.0
    g0 = gap(y, run, p, geo)
    return g0 / (g0 - g1)


@jit(allocates=True)
def run_fast(y, p, kind, rp, settings, state, tracked, series, states):
    """Integrate y = (z, z', u), or (z, z', u, e, alpha') with the two-run or the elastic chain, from rest to
    settings.duration with step-size control; returns a code.

    Its records (engine.jit.records), each a one-element array: ``settings`` (:data:`FAST_SETTINGS`),
    ``state`` (:data:`FAST_STATE`) and ``tracked`` (engine.model.diagnostics.TRACKED), the last two
    fresh from their ``new()`` at the start. Resumable: every quantity the loop carries between steps
    is in y, state, tracked, series and states; after settings.chunk_steps accepted steps the loop
    returns PAUSED and, called again with the same records and arrays, continues exactly where it
    stopped (the result is bit-identical to an uninterrupted run). Steps never land on output times:
    the series rows, every dt_out, come from cubic Hermite interpolation inside the steps (dense
    output), so the series changes nothing of the run. The step is ROS34PW2's where
    high_order(kind, two_runs) and not settings.fast_ros2, else ROS2's. The local error estimate
    (ROS34PW2: engine.fast.wstep; ROS2: y_{n+1} - (y_n + h k1), its embedded first-order solution,
    and steps of at most fast_max_step / 2) is measured in a weighted RMS norm with absolute scales
    fast_tolerance * (1 m, 1 m, 1 rad, 1 rad, 1 m, 1 rad; x 10 /s for rates; 1 for u; with a free
    engine sprocket also 1 rad for e, 10 /s for alpha'). Extremes and the energy ledger are tracked
    at every accepted step (the extremes of L_taut also inside steps, from its rate at both ends).
    Codes: OK, PAUSED, NONFINITE, REAR_AIRBORNE, FRONT_AIRBORNE; state.t is the time reached.
    """
    settings, state, tracked = settings[0], state[0], tracked[0]   # views: what the loop writes is in the arrays
    geo = design_constants(p)
    n_state = y.shape[0]
    # the elastic chain: the state of the two runs (the caller sizes it), one mode, no events
    elastic = p[P.CHAIN_COMPLIANCE] == 1.0 and n_state == N_STATE_TWO_RUNS
    two_runs = n_state == N_STATE_TWO_RUNS and not elastic
    # the settings the loop reads at every step, as locals (the compiler keeps them in registers)
    longitudinal, t_end, dt_out = settings.tyre_longitudinal, settings.duration, settings.dt_out
    tol, max_air_time, chunk_steps = settings.fast_tolerance, settings.max_airborne_time, settings.chunk_steps
    order3 = high_order(kind, two_runs) and not settings.fast_ros2
    h_max = settings.fast_max_step if order3 else 0.5 * settings.fast_max_step  # ROS2's: half of ROS34PW2's
    stages = np.zeros((N_STAGES, n_state))
    ws = np.zeros(N_WS)
    c_row = np.zeros(N_DOF)
    v = np.zeros(N_DOF)
    aux = np.zeros(N_AUX)
    f1 = np.zeros(n_state)
    f2 = np.zeros(n_state)
    k1 = np.zeros(n_state)
    k2 = np.zeros(n_state)
    y2 = np.zeros(n_state)
    ynew = np.zeros(n_state)
    y_old = np.zeros(n_state)
    f_old = np.zeros(n_state)
    err = np.zeros(n_state)
    # scratch for the dense output's evaluations and the two-run chain's event checks
    yi = np.zeros(n_state)
    fi = np.zeros(n_state)
    auxi = np.zeros(N_AUX)
    wsi = np.zeros(N_WS)
    scale = np.full(n_state, tol)
    for i in range(N_DOF, ZU):
        scale[i] = 10.0 * tol
    if n_state == N_STATE_TWO_RUNS:
        scale[ZALPHA_DOT] = 10.0 * tol
    n_rows = series.shape[0] if settings.keep_series else 0
    if not state.started:
        state.mode = ELASTIC if elastic else UPPER
        state.sigma = relaxation_length(0.0, 0.0, 1.0, p)
        state.h = min(h_max, FIRST_STEP)
        if fast_rhs(y, p, geo, kind, rp, state.sigma, longitudinal, f1, aux, ws, state.mode) != OK:
            return NONFINITE
        track_state(tracked, aux, p)
        state.prev_taut, state.prev_rate = aux[AUX_TAUT], aux[AUX_TAUT_RATE]
        if n_rows > 0:
            record_series(series, 0, 0.0, y[ZX1], y[ZTHETA], -y[N_DOF + ZBETA], -aux[AUX_ALPHA_DOT], y[ZU],
                          state.sigma, 0.0, aux)  # no constraint residual in minimal coordinates
            _store(states, 0, y)
            state.row = 1
        state.started = True
    elif fast_rhs(y, p, geo, kind, rp, state.sigma, longitudinal, f1, aux, ws, state.mode) != OK:
        return NONFINITE  # not reached: the same evaluation succeeded before the pause
    t, h, sigma, row, mode = state.t, state.h, state.sigma, state.row, state.mode
    steps = 0
    while t < t_end:
        if steps >= chunk_steps:
            _save(state, t, h, sigma, row, mode)
            return PAUSED
        if two_runs and released(mode, aux[AUX_TENSION]) != mode:   # the engaged run would push: it goes slack
            mode = FREE
            if fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, f1, aux, ws, mode) != OK:
                _save(state, t, h, sigma, row, mode)
                return NONFINITE
        # eq. (41) closed with this state's values; f1 and the tyre's outputs moved to the new sigma*
        new_sigma = relaxation_length(aux[AUX_FX], aux[AUX_KAPPA], aux[AUX_FZ_REAR], p)
        mass_solve(geo, ws, ws, v, W_B)               # M^-1 b
        for i in range(N_DOF):
            c_row[i] = ws[W_C + i]
        if new_sigma != sigma:
            dfx = retune_sigma(aux, y[ZU], sigma, new_sigma, p, longitudinal)
            for i in range(N_DOF):
                f1[N_DOF + i] += v[i] * dfx
            f1[ZU] = aux[AUX_DUDT]
            sigma = new_sigma
        a_uu = -abs(aux[AUX_VX]) / sigma
        fx_u = aux[AUX_SLOPE] / sigma if longitudinal else 0.0
        for i in range(N_DOF):
            v[i] *= fx_u                                  # dz''/du = M^-1 b dF_x/du
        pw0 = powers(aux, p)
        fz_rear, fz_front, tension = aux[AUX_FZ_REAR], aux[AUX_FZ_FRONT], aux[AUX_TENSION]
        n_err = N_STATE if mode in (UPPER, LOWER) else n_state   # the sprocket's own e and alpha' too
        tries = 0
        while True:
            h = min(h, h_max, t_end - t)
            if order3:
                if attempt(y, f1, h, sigma, v, c_row, a_uu, p, geo, kind, rp, longitudinal, stages, y2, f2, aux,
                           ws, ynew, err, mode) != OK:
                    _save(state, t, h, sigma, row, mode)
                    return NONFINITE
                e = _error_norm(err, scale, n_err)
                factor = 0.9 * libm.pow_positive(max(e, 1e-10), -1.0 / ERROR_ORDER)
            else:
                gh = GAMMA * h
                w_solve(f1, gh, v, c_row, a_uu, k1)
                for i in range(n_state):
                    y2[i] = y[i] + h * k1[i]
                if fast_rhs(y2, p, geo, kind, rp, sigma, longitudinal, f2, aux, ws, mode) != OK:
                    _save(state, t, h, sigma, row, mode)
                    return NONFINITE
                for i in range(n_state):
                    f2[i] -= 2.0 * k1[i]
                w_solve(f2, gh, v, c_row, a_uu, k2)
                for i in range(n_state):
                    ynew[i] = y[i] + h * (1.5 * k1[i] + 0.5 * k2[i])
                    err[i] = 0.5 * h * (k1[i] + k2[i])
                e = _error_norm(err, scale, n_err)
                factor = 0.9 / math.sqrt(max(e, 1e-10))
            if e > 1.0 and h > MIN_STEP:
                h *= max(MIN_SHRINK, factor)
                continue
            if two_runs and tries < MAX_EVENT_TRIES and h > MIN_STEP:
                fast_rhs(ynew, p, geo, kind, rp, sigma, longitudinal, fi, auxi, wsi, mode)
                fraction = _event_fraction(y, ynew, mode, tension, auxi[AUX_TENSION], p, geo)
                if fraction < 1.0:
                    h = max(h * fraction, MIN_STEP)
                    tries += 1
                    continue
            break
        h_done = h
        t_old = t
        t = t_end if t_end - (t + h) <= 1e-12 * t_end else t + h
        h *= min(MAX_GROWTH, factor)
        steps += 1
        for i in range(n_state):
            y_old[i] = y[i]
            f_old[i] = f1[i]
            y[i] = ynew[i]
        if fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, f1, aux, ws, mode) != OK:
            _save(state, t, h, sigma, row, mode)
            return NONFINITE
        # records at the new state and over the step
        track_state(tracked, aux, p)
        track_interval(tracked, fz_rear, fz_front, tension, aux[AUX_TENSION], h_done)
        integrate_powers(tracked, pw0, powers(aux, p), h_done)
        _taut_extremes(tracked, state.prev_taut, state.prev_rate, aux[AUX_TAUT], aux[AUX_TAUT_RATE], h_done)
        state.prev_taut, state.prev_rate = aux[AUX_TAUT], aux[AUX_TAUT_RATE]
        # dense output: the series rows inside (t_old, t]
        while row < n_rows and (row * dt_out <= t + 1e-9 * dt_out or (row == n_rows - 1 and t >= t_end)):
            t_row = min(row * dt_out, t_end)
            if t - t_row <= 1e-9 * dt_out:
                record_series(series, row, t_row, y[ZX1], y[ZTHETA], -y[N_DOF + ZBETA], -aux[AUX_ALPHA_DOT],
                              y[ZU], sigma, 0.0, aux)
                _store(states, row, y)
            else:
                _hermite(y_old, f_old, y, f1, h_done, (t_row - t_old) / h_done, yi)
                fast_rhs(yi, p, geo, kind, rp, sigma, longitudinal, fi, auxi, wsi, mode)
                record_series(series, row, t_row, yi[ZX1], yi[ZTHETA], -yi[N_DOF + ZBETA], -auxi[AUX_ALPHA_DOT],
                              yi[ZU], sigma, 0.0, auxi)
                _store(states, row, yi)
            row += 1
        if two_runs:
            mode = _chain_after_step(y, mode, h_done, p, geo, ws, aux, tracked)
            if fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, f1, aux, ws, mode) != OK:
                _save(state, t, h, sigma, row, mode)
                return NONFINITE
            state.prev_taut, state.prev_rate = aux[AUX_TAUT], aux[AUX_TAUT_RATE]
        state.air_rear = state.air_rear + h_done if fz_rear <= 0.0 else 0.0
        state.air_front = state.air_front + h_done if fz_front <= 0.0 else 0.0
        if state.air_rear > max_air_time or state.air_front > max_air_time:
            _save(state, t, h, sigma, row, mode)
            return REAR_AIRBORNE if state.air_rear > max_air_time else FRONT_AIRBORNE
    _save(state, t, h, sigma, row, mode)
    return OK


@jit
def _save(state, t, h, sigma, row, mode):
    """The loop's carried values into its state record (a failed run's too: its t is the time reached)."""
    state.t, state.h, state.sigma, state.row, state.mode = t, h, sigma, row, mode


@jit(allocates=True)
def _chain_after_step(y, mode, h, p, geo, ws, aux, tracked):
    """Two-run chain, after a step of length h taken in mode: a free step counts as overrun and ends
    in the impact of a run whose gap closed (its loss into tracked.chain_impacts_j); an engaged step's e and
    alpha' are projected onto the run. Returns the mode for the next step."""
    if mode != FREE:
        project(y, mode, aux[AUX_ALPHA_DOT], p, geo)
        return mode
    tracked.chain_compression_s += h
    run, g = closing_run(y, p, geo)
    if g >= 0.0:
        return FREE
    tracked.chain_impacts_j += engage(y, run, p, geo, ws)
    return run
