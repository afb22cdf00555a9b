"""Generalized applied forces Q: gravity, suspensions (34)-(35), tyre radial springs (36)-(37),
the drive torque and the rear tyre's longitudinal force (38)-(52).

Forces on mixed coordinates enter directly as generalized forces (virtual work F * d(coord)).
The longitudinal force acts horizontally at the rear contact point (point 14, directly below
the axle): it pushes the axle (x_6) and turns the wheel with the loaded radius rt as lever arm.
"""

from __future__ import annotations

import numpy as np

from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import ALPHA, BETA, FS, FT, RS, RT, THETA, X6
from finaldrive.engine.model.jit import jit
from finaldrive.engine.model.tyre import deformation_rate, effective_radius, magic_formula, transient_slip

# Slots of the auxiliary output vector filled by applied_forces.
AUX_FX, AUX_FZ_REAR, AUX_FZ_FRONT, AUX_KAPPA, AUX_VSX, AUX_RE, AUX_DUDT = range(7)
N_AUX = 7


@jit
def radial_tyre_force(r: float, rdot: float, r0: float, k: float, c: float) -> float:
    """One-sided tyre spring-damper, eqs. (36)-(37): zero when the tyre is off the road."""
    if r >= r0:
        return 0.0
    return -k * (r - r0) - c * rdot


@jit
def applied_forces(q: np.ndarray, qd: np.ndarray, u: float, sigma: float, p: np.ndarray,
                   qg: np.ndarray, longitudinal: bool, out: np.ndarray, aux: np.ndarray) -> None:
    """Q(q, q-dot, u) into out; tyre quantities (F_x, F_z, kappa', V_sx, R_e, du/dt) into aux."""
    out[:] = qg
    out[RS] += -p[P.K_RS] * (q[RS] - p[P.S_RS]) - p[P.C_RS] * qd[RS]           # (35)
    out[FS] += -p[P.K_FS] * (q[FS] - p[P.S_FS]) - p[P.C_FS] * qd[FS]           # (34)
    fz_rear = radial_tyre_force(q[RT], qd[RT], p[P.RT0], p[P.K_RT], p[P.C_RT])  # (36)
    fz_front = radial_tyre_force(q[FT], qd[FT], p[P.FT0], p[P.K_FT], p[P.C_FT])  # (37)
    out[RT] += fz_rear
    out[FT] += fz_front
    out[ALPHA] -= p[P.TORQUE]  # drive torque turns the engine sprocket forward (alpha decreasing)
    out[THETA] += p[P.TORQUE]  # ... and its reaction acts on the chassis
    vx = qd[X6]                                                              # (39)
    re = effective_radius(q[RT], p)                                          # (38)
    vsx = vx + re * qd[BETA]                                                 # (40), omega = -beta'
    kappa = transient_slip(u, sigma, vsx, vx, fz_rear, p)                    # (43)
    fx = magic_formula(fz_rear, kappa, p) if longitudinal else 0.0           # (45)
    out[X6] += fx
    out[BETA] += fx * q[RT]
    aux[AUX_FX] = fx
    aux[AUX_FZ_REAR] = fz_rear
    aux[AUX_FZ_FRONT] = fz_front
    aux[AUX_KAPPA] = kappa
    aux[AUX_VSX] = vsx
    aux[AUX_RE] = re
    aux[AUX_DUDT] = deformation_rate(u, sigma, vsx, vx)                     # (42)
