"""What both solvers record at every accepted step: the extremes of a run and its energy ledger; and a
row of the output series (record_series), written here once for both.

Both integrator loops call these on their own steps (never on the output series), so a peak is
the same whatever the series stride. ``ext`` holds the extremes and durations, ``led`` the
integrated powers (trapezoidal rule on the integrator's steps); engine.simulation names them.

The tyre's powers (docs/engine.md#the-tyres-energy-ledger): the longitudinal force takes from
the motorcycle the slip power P_slip = -F_x V_sx (with the lever arm R_e; another lever arm r adds
F_x omega (R_e - r), which no one supplied). With eqs. (42)-(43), exactly,
    (1 + a) P_slip = F_x u' + |V_x| F_x kappa',      a = |V_x| K_vlow / K_xk >= 0,
so P_slip = dE_c/dt + D with the carcass's stored energy rate dE_c/dt = F_x u' / (1 + a) and the
dissipation D = |V_x| F_x kappa' / (1 + a) >= 0, because F_x has the sign of kappa' (eq. 45 with
E_x < 1 over the load range). Above V_low, a = 0 and D = |V_x| F_x u / sigma*.
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import params as P
from finaldrive.engine.model.elements import (
    AUX_DUDT,
    AUX_FT,
    AUX_FX,
    AUX_FZ_FRONT,
    AUX_FZ_REAR,
    AUX_KAPPA,
    AUX_LEVER,
    AUX_OMEGA,
    AUX_P_DAMP,
    AUX_P_DRIVE,
    AUX_RE,
    AUX_RT,
    AUX_SLOPE,
    AUX_TAUT,
    AUX_TENSION,
    AUX_TORQUE,
    AUX_VSX,
    AUX_VX,
)
from finaldrive.engine.model.tyre import low_speed_factor, magic_formula_slope

# Extremes and durations of a run (ext).
(E_TENSION_MAX, E_TENSION_MIN, E_FZ_REAR_MAX, E_FZ_REAR_MIN, E_FZ_FRONT_MAX, E_FZ_FRONT_MIN, E_SLIP_MAX,
 E_AIRBORNE_REAR, E_AIRBORNE_FRONT, E_COMPRESSION_REAR, E_COMPRESSION_FRONT, E_CHAIN_COMPRESSION, E_TAUT_MIN,
 E_TAUT_MAX) = range(14)
N_EXT = 14

# Integrated powers of the ledger [J] (led), the smallest tyre dissipation rate seen [W], and the
# kinetic energy the two-run chain's re-engagement impacts took [J] (engine.fast.chain_runs).
L_DRIVE, L_DAMPERS, L_SLIP, L_CARCASS, L_TYRE_DISSIPATION, L_LEVER, L_DISSIPATION_MIN, L_IMPACT = range(8)
N_LED = 8
# Powers at one state (pw), in the ledger's order.
N_POWERS = 6


@jit(allocates=True)
def start_records(ext: np.ndarray, led: np.ndarray) -> None:
    """Empty extremes (max -inf, min +inf), zero durations and integrals."""
    ext[:] = 0.0
    for k in (E_TENSION_MAX, E_FZ_REAR_MAX, E_FZ_FRONT_MAX, E_SLIP_MAX, E_COMPRESSION_REAR,
              E_COMPRESSION_FRONT, E_TAUT_MAX):
        ext[k] = -math.inf
    for k in (E_TENSION_MIN, E_FZ_REAR_MIN, E_FZ_FRONT_MIN, E_TAUT_MIN):
        ext[k] = math.inf
    led[:] = 0.0
    led[L_DISSIPATION_MIN] = math.inf


@jit
def track_state(ext: np.ndarray, aux: np.ndarray, p: np.ndarray) -> None:
    """Extremes at an accepted state (forces, slip, tyre compressions, taut run)."""
    ext[E_TENSION_MAX] = max(ext[E_TENSION_MAX], aux[AUX_TENSION])
    ext[E_TENSION_MIN] = min(ext[E_TENSION_MIN], aux[AUX_TENSION])
    ext[E_FZ_REAR_MAX] = max(ext[E_FZ_REAR_MAX], aux[AUX_FZ_REAR])
    ext[E_FZ_REAR_MIN] = min(ext[E_FZ_REAR_MIN], aux[AUX_FZ_REAR])
    ext[E_FZ_FRONT_MAX] = max(ext[E_FZ_FRONT_MAX], aux[AUX_FZ_FRONT])
    ext[E_FZ_FRONT_MIN] = min(ext[E_FZ_FRONT_MIN], aux[AUX_FZ_FRONT])
    ext[E_SLIP_MAX] = max(ext[E_SLIP_MAX], abs(aux[AUX_KAPPA]))
    ext[E_COMPRESSION_REAR] = max(ext[E_COMPRESSION_REAR], p[P.RT0] - aux[AUX_RT])
    ext[E_COMPRESSION_FRONT] = max(ext[E_COMPRESSION_FRONT], p[P.FT0] - aux[AUX_FT])
    ext[E_TAUT_MIN] = min(ext[E_TAUT_MIN], aux[AUX_TAUT])
    ext[E_TAUT_MAX] = max(ext[E_TAUT_MAX], aux[AUX_TAUT])


@jit
def track_interval(ext: np.ndarray, fz_rear: float, fz_front: float, tension: float, tension_end: float,
                   h: float) -> None:
    """Durations over a step of length h: a wheel off the road (F_z <= 0), judged at the step's start;
    the upper chain run in compression (tension < 0), with the tension linear between its values at
    the start and the end (tension_end = tension: judged at the start)."""
    if fz_rear <= 0.0:
        ext[E_AIRBORNE_REAR] += h
    if fz_front <= 0.0:
        ext[E_AIRBORNE_FRONT] += h
    if tension < 0.0 and tension_end < 0.0:
        ext[E_CHAIN_COMPRESSION] += h
    elif tension < 0.0 or tension_end < 0.0:
        below = tension / (tension - tension_end)        # where the tension crosses zero
        ext[E_CHAIN_COMPRESSION] += h * (below if tension < 0.0 else 1.0 - below)


@jit
def powers(aux: np.ndarray, p: np.ndarray, pw: np.ndarray) -> None:
    """The ledger's powers at a state [W]: drive, dampers, tyre slip, carcass storage rate,
    tyre dissipation, and the work rate of the lever arm (zero when it is R_e)."""
    fx = aux[AUX_FX]
    a = low_speed_factor(aux[AUX_VX], aux[AUX_FZ_REAR], p)
    pw[L_DRIVE] = aux[AUX_P_DRIVE]
    pw[L_DAMPERS] = aux[AUX_P_DAMP]
    pw[L_SLIP] = -fx * aux[AUX_VSX]
    pw[L_CARCASS] = fx * aux[AUX_DUDT] / (1.0 + a)
    pw[L_TYRE_DISSIPATION] = abs(aux[AUX_VX]) * fx * aux[AUX_KAPPA] / (1.0 + a)
    pw[L_LEVER] = fx * aux[AUX_OMEGA] * (aux[AUX_RE] - aux[AUX_LEVER])


@jit
def integrate_powers(led: np.ndarray, pw0: np.ndarray, pw1: np.ndarray, h: float) -> None:
    """Trapezoidal rule over one step; the smallest tyre dissipation rate at either end."""
    for k in range(N_POWERS):
        led[k] += 0.5 * h * (pw0[k] + pw1[k])
    led[L_DISSIPATION_MIN] = min(led[L_DISSIPATION_MIN], pw0[L_TYRE_DISSIPATION], pw1[L_TYRE_DISSIPATION])


@jit
def retune_sigma(aux: np.ndarray, u: float, old_sigma: float, new_sigma: float, p: np.ndarray,
                 longitudinal: bool) -> float:
    """Move the tyre's outputs in aux from sigma* = old_sigma to new_sigma at the same state
    (eq. 41's loop closed at the start of a step: kappa', F_x, dF_x/dkappa', u'); returns the
    change of F_x."""
    kappa = aux[AUX_KAPPA] + u * (1.0 / new_sigma - 1.0 / old_sigma)
    fx, slope = magic_formula_slope(aux[AUX_FZ_REAR], kappa, p) if longitudinal else (0.0, 0.0)
    dfx = fx - aux[AUX_FX]
    aux[AUX_KAPPA] = kappa
    aux[AUX_FX] = fx
    aux[AUX_SLOPE] = slope
    aux[AUX_DUDT] -= abs(aux[AUX_VX]) * u * (1.0 / new_sigma - 1.0 / old_sigma)
    return dfx


@jit
def record_series(out: np.ndarray, row: int, t: float, x1: float, theta: float, wheel_speed: float,
                  sprocket_speed: float, u: float, sigma: float, residual: float, aux: np.ndarray) -> None:
    """Row ``row`` of the time series (engine.outcome.SERIES_COLUMNS, in its order): the state's values
    the solver passes (its own coordinates) and the force elements' outputs in aux."""
    out[row, 0] = t
    out[row, 1] = x1
    out[row, 2] = theta
    out[row, 3] = aux[AUX_TENSION]
    out[row, 4] = aux[AUX_FZ_REAR]
    out[row, 5] = aux[AUX_FZ_FRONT]
    out[row, 6] = aux[AUX_KAPPA]
    out[row, 7] = aux[AUX_FX]
    out[row, 8] = aux[AUX_RE]
    out[row, 9] = wheel_speed
    out[row, 10] = sprocket_speed
    out[row, 11] = aux[AUX_TAUT]
    out[row, 12] = u
    out[row, 13] = sigma
    out[row, 14] = residual
    out[row, 15] = aux[AUX_TORQUE]
