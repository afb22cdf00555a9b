"""The two-run chain in the fast path (vehicle chain_runs = 2; docs/engine.md#chain-overrun).

The chain is a loop: the upper run (eqs. 24-31) and the lower run (the lower common tangent, the
mirror of eqs. 24-29) with the chain's free play between them. With e the engine sprocket's turn
beyond the upper run's engagement (engine.fast.minimal's state ZPLAY), the runs' gaps are

    g_u = R_ES e >= 0,   g_l = s(|D|) - R_ES e >= 0,   s(|D|) = L_loop - loop_length(|D|),

s the chain's length beyond the loop of its two taut runs (engine.model.kinematics.loop_length),
|D| the sprocket centre distance. A run carries tension only while its gap is closed. An engaged
run is released when its tension would turn negative (the engine sprocket then turns freely,
I alpha'' = -T); a free run re-engages when its gap closes, by a plastic impact along its
constraint: the impulse that stops the gap's rate, momentum conserved, the kinetic energy it takes
1/2 (G v)^2 / (G M^-1 G) booked in the energy ledger.
"""

from __future__ import annotations

import numpy as np

from finaldrive.engine.fast.bodies import G_P2_X, G_P2_Y, N_DOF, ZBETA, ZPHI, ZTHETA, mass_solve
from finaldrive.engine.fast.minimal import FREE, LOWER, UPPER, ZALPHA_DOT, ZPLAY, chain_terms
from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.kinematics import loop_length
from finaldrive.engine.model.linalg import dot

#: A run's gap may close by this much at the end of the step that locates its re-engagement [m].
GAP_TOL = 1.0e-7
#: An engaged run's tension may reach this far below zero at the end of the step that locates its
#: release [N].
TENSION_TOL = 1.0


@jit
def sprocket_centres(y: np.ndarray, p: np.ndarray, geo: np.ndarray) -> tuple[float, float, float, float]:
    """World offsets of points 2 and 6 from point 1 (eqs. 1-2, 9-10)."""
    st, ct = libm.sincos(y[ZTHETA])
    w2x, w2y = ct * geo[G_P2_X] - st * geo[G_P2_Y], st * geo[G_P2_X] + ct * geo[G_P2_Y]
    sp, cp = libm.sincos(y[ZPHI])
    return w2x, w2y, p[P.L_SA] * cp, p[P.L_SA] * sp


@jit
def slack(y: np.ndarray, p: np.ndarray, geo: np.ndarray) -> float:
    """s = g_u + g_l: the chain's length beyond the loop of its two taut runs at the state y [m]."""
    w2x, w2y, w6x, w6y = sprocket_centres(y, p, geo)
    return float(p[P.L_LOOP] - loop_length(libm.hypot(w6x - w2x, w6y - w2y), p[P.R_ES], p[P.R_WS]))


@jit
def gap(y: np.ndarray, run: int, p: np.ndarray, geo: np.ndarray) -> float:
    """The gap of run (UPPER or LOWER) at the state y [m]."""
    g_u = float(p[P.R_ES] * y[ZPLAY])
    return g_u if run == UPPER else slack(y, p, geo) - g_u


@jit
def run_tension(run: int, tension: float) -> float:
    """The tension of the engaged run from the chain's net pull T_upper - T_lower."""
    return tension if run == UPPER else -tension


@jit
def project(y: np.ndarray, run: int, alpha_dot: float, p: np.ndarray, geo: np.ndarray) -> None:
    """In an engaged mode e and alpha' follow from z, z': e = 0 (upper) or s / R_ES (lower)."""
    y[ZPLAY] = 0.0 if run == UPPER else slack(y, p, geo) / p[P.R_ES]
    y[ZALPHA_DOT] = alpha_dot


@jit
def closing_run(y: np.ndarray, p: np.ndarray, geo: np.ndarray) -> tuple[int, float]:
    """(run, gap) of the run whose gap is the smaller, in the FREE mode."""
    g_u = gap(y, UPPER, p, geo)
    g_l = gap(y, LOWER, p, geo)
    return (UPPER, g_u) if g_u <= g_l else (LOWER, g_l)


@jit(allocates=True)
def engage(y: np.ndarray, run: int, p: np.ndarray, geo: np.ndarray, ws: np.ndarray) -> float:
    """The plastic impact of run re-engaging at the state y (FREE mode; ws: its mass factors, the
    engine sprocket's inertia out of M). Returns the kinetic energy it takes [J].

    With v = (z', alpha') and M7 = diag(M(z), I), the run's gap rate is proportional to
    G v = alpha' - J_a z', J_a = d(alpha)/dz through the run (mirror of eqs. 24-29 for the lower).
    The impulse G Lambda with G v+ = 0: Lambda = -G v / (G M7^-1 G), z'+ = z' - M^-1 J_a^T Lambda,
    alpha'+ = alpha' + Lambda / I; the loss 1/2 (G v)^2 / (G M7^-1 G).
    """
    w2x, w2y, w6x, w6y = sprocket_centres(y, p, geo)
    wt, wp, wb = y[N_DOF + ZTHETA], y[N_DOF + ZPHI], y[N_DOF + ZBETA]
    ja_t, ja_p, _, _, _, alpha_rate = chain_terms(w2x, w2y, w6x, w6y, wt, wp, wb, p, float(run))
    ja = np.zeros(N_DOF)
    ja[ZTHETA], ja[ZPHI], ja[ZBETA] = ja_t, ja_p, p[P.R_WS] / p[P.R_ES]
    x = np.zeros(N_DOF)
    mass_solve(geo, ws, ja, x)
    closing = y[ZALPHA_DOT] - alpha_rate                       # G v
    compliance = dot(ja, x) + 1.0 / p[P.I_SPROCKET]         # G M7^-1 G
    impulse = -closing / compliance
    for i in range(N_DOF):
        y[N_DOF + i] -= x[i] * impulse
    project(y, run, y[ZALPHA_DOT] + impulse / p[P.I_SPROCKET], p, geo)
    return float(0.5 * closing * closing / compliance)


@jit
def released(run: int, tension: float) -> int:
    """The mode after an engaged run's tension (net pull: tension) is checked: FREE if it would push."""
    return FREE if run != FREE and run_tension(run, tension) < 0.0 else run
