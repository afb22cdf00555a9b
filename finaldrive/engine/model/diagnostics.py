"""What both solvers record at every accepted step: the extremes of a run and its energy ledger; and a
row of the output series (record_series), written here once for both.

Both integrator loops call these on their own steps (never on the output series), so a peak is
the same whatever the series stride. They track into one record (:data:`TRACKED`: the extremes,
durations and the ledger's integrated powers), which engine.simulation turns into the result's
diagnostics.

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
from typing import NamedTuple

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.jit.records import Record
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

#: What both loops track over a run (the record ``tracked``). A name that is a result value
#: (engine.record) means what that value means; the others are the loops' own. Extremes start empty
#: (max -inf, min +inf), durations and the ledger's integrals (trapezoidal rule on the integrator's
#: steps) at 0.
TRACKED = Record(
    ("chain_tension_max_n", np.float64, -math.inf),
    ("chain_tension_min_n", np.float64, math.inf),
    ("fz_rear_max_n", np.float64, -math.inf),
    ("fz_rear_min_n", np.float64, math.inf),
    ("fz_front_max_n", np.float64, -math.inf),
    ("fz_front_min_n", np.float64, math.inf),
    ("slip_max", np.float64, -math.inf),
    ("airborne_rear_s", np.float64, 0.0),
    ("airborne_front_s", np.float64, 0.0),
    ("chain_compression_s", np.float64, 0.0),
    ("tyre_compression_rear_max_m", np.float64, -math.inf),
    ("tyre_compression_front_max_m", np.float64, -math.inf),
    ("taut_min_m", np.float64, math.inf),    # the taut upper run's shortest length (the slack, eq. 68)
    ("taut_max_m", np.float64, -math.inf),   # and its longest
    ("drive_work_j", np.float64, 0.0),
    ("dampers_j", np.float64, 0.0),          # what the suspension and tyre dampers dissipated
    ("tyre_slip_work_j", np.float64, 0.0),
    ("tyre_carcass_energy_j", np.float64, 0.0),
    ("tyre_dissipation_j", np.float64, 0.0),
    ("tyre_lever_work_j", np.float64, 0.0),
    ("tyre_dissipation_min_w", np.float64, math.inf),
    ("chain_impacts_j", np.float64, 0.0),    # the kinetic energy the two-run chain's re-engagements took
)


class Powers(NamedTuple):
    """The ledger's powers at one state [W]."""

    drive: float
    dampers: float
    slip: float             # P_slip = dE_c/dt + D
    carcass: float          # the carcass's stored energy rate dE_c/dt
    tyre_dissipation: float  # D >= 0
    lever: float            # the work rate of a lever arm other than R_e


@jit
def track_state(tracked, aux: np.ndarray, p: np.ndarray) -> None:
    """Extremes at an accepted state (forces, slip, tyre compressions, taut run)."""
    tracked.chain_tension_max_n = max(tracked.chain_tension_max_n, aux[AUX_TENSION])
    tracked.chain_tension_min_n = min(tracked.chain_tension_min_n, aux[AUX_TENSION])
    tracked.fz_rear_max_n = max(tracked.fz_rear_max_n, aux[AUX_FZ_REAR])
    tracked.fz_rear_min_n = min(tracked.fz_rear_min_n, aux[AUX_FZ_REAR])
    tracked.fz_front_max_n = max(tracked.fz_front_max_n, aux[AUX_FZ_FRONT])
    tracked.fz_front_min_n = min(tracked.fz_front_min_n, aux[AUX_FZ_FRONT])
    tracked.slip_max = max(tracked.slip_max, abs(aux[AUX_KAPPA]))
    tracked.tyre_compression_rear_max_m = max(tracked.tyre_compression_rear_max_m, p[P.RT0] - aux[AUX_RT])
    tracked.tyre_compression_front_max_m = max(tracked.tyre_compression_front_max_m, p[P.FT0] - aux[AUX_FT])
    tracked.taut_min_m = min(tracked.taut_min_m, aux[AUX_TAUT])
    tracked.taut_max_m = max(tracked.taut_max_m, aux[AUX_TAUT])


@jit
def track_interval(tracked, fz_rear: float, fz_front: float, tension: float, tension_end: float, h: float) -> None:
    """Durations over a step of length h: a wheel off the road (F_z <= 0), judged at the step's start;
    the upper chain run in compression (tension < 0), with the tension linear between its values at
    the start and the end (tension_end = tension: judged at the start)."""
    if fz_rear <= 0.0:
        tracked.airborne_rear_s += h
    if fz_front <= 0.0:
        tracked.airborne_front_s += h
    if tension < 0.0 and tension_end < 0.0:
        tracked.chain_compression_s += h
    elif tension < 0.0 or tension_end < 0.0:
        below = tension / (tension - tension_end)        # where the tension crosses zero
        tracked.chain_compression_s += h * (below if tension < 0.0 else 1.0 - below)


@jit
def powers(aux: np.ndarray, p: np.ndarray) -> Powers:
    """The ledger's powers at a state: drive, dampers, tyre slip, carcass storage rate, tyre
    dissipation, and the work rate of the lever arm (zero when it is R_e)."""
    fx = aux[AUX_FX]
    a = low_speed_factor(aux[AUX_VX], aux[AUX_FZ_REAR], p)
    return Powers(aux[AUX_P_DRIVE], aux[AUX_P_DAMP], -fx * aux[AUX_VSX], fx * aux[AUX_DUDT] / (1.0 + a),
                  abs(aux[AUX_VX]) * fx * aux[AUX_KAPPA] / (1.0 + a),
                  fx * aux[AUX_OMEGA] * (aux[AUX_RE] - aux[AUX_LEVER]))


@jit
def integrate_powers(tracked, pw0: Powers, pw1: Powers, h: float) -> None:
    """Trapezoidal rule over one step; the smallest tyre dissipation rate at either end."""
    half = 0.5 * h
    tracked.drive_work_j += half * (pw0.drive + pw1.drive)
    tracked.dampers_j += half * (pw0.dampers + pw1.dampers)
    tracked.tyre_slip_work_j += half * (pw0.slip + pw1.slip)
    tracked.tyre_carcass_energy_j += half * (pw0.carcass + pw1.carcass)
    tracked.tyre_dissipation_j += half * (pw0.tyre_dissipation + pw1.tyre_dissipation)
    tracked.tyre_lever_work_j += half * (pw0.lever + pw1.lever)
    tracked.tyre_dissipation_min_w = min(tracked.tyre_dissipation_min_w, pw0.tyre_dissipation, pw1.tyre_dissipation)


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
