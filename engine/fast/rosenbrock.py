"""Linearly implicit integration of the minimal-coordinate model, with step-size control.

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
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.fast.minimal import (
    A_ALPHA_DOT,
    A_FX,
    A_FX_U,
    A_FZ_FRONT,
    A_FZ_REAR,
    A_KAPPA,
    A_RE,
    A_TAUT,
    A_TAUT_RATE,
    A_TENSION,
    N_AUX,
    N_DOF,
    N_STATE,
    ZBETA,
    ZPHI,
    ZTHETA,
    ZU,
    ZX1,
    design_constants,
    fast_rhs,
)
from finaldrive.engine.model.jit import jit
from finaldrive.engine.model.linalg import cholesky_solve
from finaldrive.engine.model.tyre import magic_formula, relaxation_length
from finaldrive.engine.outcome import FRONT_AIRBORNE, N_SERIES, NONFINITE, OK, REAR_AIRBORNE

GAMMA = 1.0 + 1.0 / math.sqrt(2.0)
#: Step-size control limits.
MAX_GROWTH = 2.0
MIN_SHRINK = 0.2
MIN_STEP = 1.0e-7


@jit
def _w_solve(r, gh, v, c_row, a_uu, k):
    """k = W^-1 r for W = I - gh J with J's nonzero blocks dz''/du = v, du'/dz' = c_row,
    du'/du = a_uu (rows of z: identity)."""
    k[:N_DOF] = r[:N_DOF]
    cr = 0.0
    cv = 0.0
    for i in range(N_DOF):
        cr += c_row[i] * r[N_DOF + i]
        cv += c_row[i] * v[i]
    ku = (r[ZU] + gh * cr) / (1.0 - gh * a_uu - gh * gh * cv)
    for i in range(N_DOF):
        k[N_DOF + i] = r[N_DOF + i] + gh * v[i] * ku
    k[ZU] = ku


@jit
def _record(row, t, y, aux, sigma, out):
    out[row, 0] = t
    out[row, 1] = y[ZX1]
    out[row, 2] = y[ZTHETA]
    out[row, 3] = aux[A_TENSION]
    out[row, 4] = aux[A_FZ_REAR]
    out[row, 5] = aux[A_FZ_FRONT]
    out[row, 6] = aux[A_KAPPA]
    out[row, 7] = aux[A_FX]
    out[row, 8] = aux[A_RE]
    out[row, 9] = -y[N_DOF + ZBETA]
    out[row, 10] = -aux[A_ALPHA_DOT]
    out[row, 11] = aux[A_TAUT]
    out[row, 12] = y[ZU]
    out[row, 13] = sigma
    out[row, 14] = 0.0  # no constraint residual in minimal coordinates


@jit
def _error_norm(e, y, scale):
    """Weighted RMS of the local error estimate e (per-component absolute scales)."""
    acc = 0.0
    for i in range(N_STATE):
        r = e[i] / scale[i]
        acc += r * r
    return math.sqrt(acc / N_STATE)


@jit
def run_fast(y0, p, kind, rp, longitudinal, dt_out, n_out, tol, h_max, max_air_time, stride, keep_series):
    """Integrate n_out intervals of dt_out from y0 = (z, z', u) at rest, with step-size control.

    The step lands on every output time t_k = k dt_out (the series, slack sampling and
    airborne checks use those times and every accepted step). The local error estimate is
    y_{n+1} - (y_n + h k1), ROS2's embedded first-order solution, in a weighted RMS norm with
    absolute scales tol * (1 m, 1 m, 1 rad, 1 rad, 1 m, 1 rad; x 10 /s for rates; 1 for u).
    Returns (code, t reached, y, taut_min, taut_max, series, states (z, z')): the shape of
    run_reference except that the second item is a time. The extremes of L_taut include
    those inside steps (from its rate at both ends).
    """
    geo = design_constants(p)
    L = np.zeros((N_DOF, N_DOF))
    ws = np.zeros((6, N_DOF))
    b = np.zeros(N_DOF)
    c_row = np.zeros(N_DOF)
    v = np.zeros(N_DOF)
    aux = np.zeros(N_AUX)
    f1 = np.zeros(N_STATE)
    f2 = np.zeros(N_STATE)
    k1 = np.zeros(N_STATE)
    k2 = np.zeros(N_STATE)
    y2 = np.zeros(N_STATE)
    ynew = np.zeros(N_STATE)
    err = np.zeros(N_STATE)
    prev_taut = 0.0
    prev_rate = 0.0
    scale = np.full(N_STATE, tol)
    for i in range(N_DOF, ZU):
        scale[i] = 10.0 * tol
    y = y0.copy()
    n_rows = (n_out // stride + 2) if keep_series else 0
    series = np.zeros((n_rows, N_SERIES))
    states = np.zeros((n_rows, 2 * N_DOF))
    sigma = relaxation_length(0.0, 0.0, 1.0, p)
    taut_min = math.inf
    taut_max = -math.inf
    air_rear = 0.0
    air_front = 0.0
    row = 0
    t = 0.0
    h = min(h_max, dt_out)
    k_out = 0
    h_done = 0.0
    code = fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, True, f1, aux, L, b, c_row, ws)
    while True:
        if code != OK:
            return NONFINITE, t, y, taut_min, taut_max, series[:row], states[:row]
        taut, rate = aux[A_TAUT], aux[A_TAUT_RATE]
        taut_min = min(taut_min, taut)
        taut_max = max(taut_max, taut)
        if t > 0.0 and (prev_rate > 0.0) != (rate > 0.0):
            # an extreme of L_taut inside the last step: derivative linear in time
            extreme = prev_taut + 0.5 * prev_rate * h_done * prev_rate / (prev_rate - rate)
            taut_min = min(taut_min, extreme)
            taut_max = max(taut_max, extreme)
        prev_taut, prev_rate = taut, rate
        on_grid = abs(t - k_out * dt_out) <= 1e-9 * dt_out
        if on_grid:
            if keep_series and (k_out % stride == 0 or k_out == n_out):
                _record(row, k_out * dt_out, y, aux, sigma, series)
                states[row] = y[:2 * N_DOF]
                row += 1
            if k_out == n_out:
                break
            k_out += 1
        # eq. (41) closed with this state's values; f1 moved to the new sigma*
        new_sigma = relaxation_length(aux[A_FX], aux[A_KAPPA], aux[A_FZ_REAR], p)
        cholesky_solve(L, b, v)                     # M^-1 b
        vx = y[N_DOF + ZX1] + b[ZPHI] * y[N_DOF + ZPHI]
        if new_sigma != sigma:
            u = y[ZU]
            kappa_new = aux[A_KAPPA] + u * (1.0 / new_sigma - 1.0 / sigma)
            dfx = (magic_formula(aux[A_FZ_REAR], kappa_new, p) - aux[A_FX]) if longitudinal else 0.0
            for i in range(N_DOF):
                f1[N_DOF + i] += v[i] * dfx
            f1[ZU] -= abs(vx) * u * (1.0 / new_sigma - 1.0 / sigma)
            sigma = new_sigma
        a_uu = -abs(vx) / sigma
        for i in range(N_DOF):
            v[i] *= aux[A_FX_U]                           # dz''/du = M^-1 b dF_x/du
        fz_rear, fz_front = aux[A_FZ_REAR], aux[A_FZ_FRONT]
        t_next = k_out * dt_out
        while True:
            h = min(h, h_max, t_next - t)
            gh = GAMMA * h
            _w_solve(f1, gh, v, c_row, a_uu, k1)
            for i in range(N_STATE):
                y2[i] = y[i] + h * k1[i]
            code = fast_rhs(y2, p, geo, kind, rp, sigma, longitudinal, False, f2, aux, L, b, c_row, ws)
            if code != OK:
                return NONFINITE, t, y, taut_min, taut_max, series[:row], states[:row]
            for i in range(N_STATE):
                f2[i] -= 2.0 * k1[i]
            _w_solve(f2, gh, v, c_row, a_uu, k2)
            for i in range(N_STATE):
                ynew[i] = y[i] + h * (1.5 * k1[i] + 0.5 * k2[i])
                err[i] = 0.5 * h * (k1[i] + k2[i])
            e = _error_norm(err, y, scale)
            factor = 0.9 / math.sqrt(max(e, 1e-10))
            if e <= 1.0 or h <= MIN_STEP:
                t = t_next if t_next - (t + h) <= 1e-9 * dt_out else t + h
                y[:] = ynew
                h_done = h
                h *= min(MAX_GROWTH, factor)
                break
            h *= max(MIN_SHRINK, factor)
        air_rear = air_rear + h_done if fz_rear <= 0.0 else 0.0
        air_front = air_front + h_done if fz_front <= 0.0 else 0.0
        if air_rear > max_air_time:
            return REAR_AIRBORNE, t, y, taut_min, taut_max, series[:row], states[:row]
        if air_front > max_air_time:
            return FRONT_AIRBORNE, t, y, taut_min, taut_max, series[:row], states[:row]
        code = fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, True, f1, aux, L, b, c_row, ws)
    return OK, t, y, taut_min, taut_max, series[:row], states[:row]
