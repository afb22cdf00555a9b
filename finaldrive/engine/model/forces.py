"""Generalized applied forces Q in the 39 natural coordinates: the force elements of
engine.model.elements projected by virtual work, plus the constant gravity forces.

Forces on mixed coordinates enter directly as generalized forces (virtual work F * d(coord)):
suspensions on rs and fs (34)-(35), tyre radial forces on rt and ft (36)-(37), the drive torque
on alpha with its reaction on theta. The longitudinal force acts horizontally at the rear contact
point (point 14, directly below the axle): it pushes the axle (x_6) and turns the wheel (beta)
with its lever arm (engine.model.tyre.lever_arm).
"""

from __future__ import annotations

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import ALPHA, BETA, FS, FT, RS, RT, THETA, X6
from finaldrive.engine.model.elements import (
    AUX_ALPHA_DOT,
    AUX_P_DAMP,
    drive_torque,
    front_tyre,
    rear_tyre,
    spring_damper,
)


@jit(allocates=True, one_form=True)
def applied_forces(q: np.ndarray, qd: np.ndarray, u: float, sigma: float, p: np.ndarray,
                   qg: np.ndarray, longitudinal: bool, out: np.ndarray, aux: np.ndarray) -> None:
    """Q(q, q-dot, u) into out; the elements' outputs into aux (engine.model.elements)."""
    out[:] = qg
    aux[AUX_P_DAMP] = 0.0
    out[RS] += spring_damper(q[RS], qd[RS], p[P.K_RS], p[P.C_RS], p[P.S_RS], p[P.RS_BUMP], p, aux)      # (35)
    out[FS] += spring_damper(q[FS], qd[FS], p[P.K_FS], p[P.C_FS], p[P.S_FS], p[P.FS_BUMP], p, aux)      # (34)
    omega = -qd[BETA]                                                                          # (40)
    fz_rear, fx, lever = rear_tyre(q[RT], qd[RT], qd[X6], omega, u, sigma, p, longitudinal, aux)  # (36), (38)-(52)
    out[RT] += fz_rear
    out[FT] += front_tyre(q[FT], qd[FT], p, aux)                                               # (37)
    torque = drive_torque(qd[THETA], qd[ALPHA], p, aux)  # after rear_tyre: the launch drive reads its load
    out[ALPHA] -= torque  # drive torque turns the engine sprocket forward (alpha decreasing) ...
    out[THETA] += torque  # ... and its reaction acts on the chassis
    aux[AUX_ALPHA_DOT] = qd[ALPHA]
    out[X6] += fx
    out[BETA] += fx * lever
