"""Rear tyre longitudinal force: Pacejka's fully nonlinear transient model, eqs. (38)-(52).

Sign convention: kappa' > 0 and F_x > 0 when driving (the wheel spins faster than it rolls).
Two corrections to the printed text (docs/engine.md#reading-notes-extraction-faults): eq. (43)
uses K_vlow * V_sx / K_xk, and pKx1 is 25.939. The algebraic loop of eq. (41) (sigma* needs F_x
and kappa', which need sigma*) is closed with the values of the last accepted step: sigma* is
held through each step.
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.model import params as P
from finaldrive.engine.model.jit import jit

#: Below this vertical load [N] the tyre is off the road: no longitudinal force.
FZ_CONTACT_MIN = 1.0e-6


@jit
def effective_radius(rt: float, p: np.ndarray) -> float:
    """R_e = 2/3 rt0 + 1/3 rt, eq. (38)."""
    return 2.0 / 3.0 * p[P.RT0] + rt / 3.0


@jit
def slip_stiffness(fz: float, p: np.ndarray) -> float:
    """K_xk, eq. (50), with df_z from eq. (52)."""
    dfz = (fz - p[P.FZ0]) / p[P.FZ0]
    return fz * (p[P.PKX1] + p[P.PKX2] * dfz) * math.exp(p[P.PKX3] * dfz)


@jit
def magic_formula(fz: float, kappa: float, p: np.ndarray) -> float:
    """Steady-state longitudinal force F_x(F_z, kappa), eqs. (45)-(52)."""
    if fz <= FZ_CONTACT_MIN:
        return 0.0
    dfz = (fz - p[P.FZ0]) / p[P.FZ0]                                      # (52)
    cx = p[P.PCX1]                                                        # (46)
    mux = p[P.PDX1] + p[P.PDX2] * dfz                                     # (48)
    dx = mux * fz                                                         # (47)
    sgn = 1.0 if kappa > 0.0 else (-1.0 if kappa < 0.0 else 0.0)
    ex = (p[P.PEX1] + p[P.PEX2] * dfz + p[P.PEX3] * dfz * dfz) * (1.0 - p[P.PEX4] * sgn)  # (49)
    kxk = slip_stiffness(fz, p)                                           # (50)
    bx = kxk / (cx * dx)                                                  # (51)
    bk = bx * kappa
    return dx * math.sin(cx * math.atan(bk - ex * (bk - math.atan(bk))))  # (45)


@jit
def magic_formula_slope(fz: float, kappa: float, p: np.ndarray) -> tuple[float, float]:
    """(F_x, dF_x/dkappa) of eq. (45), for linearly implicit steps."""
    if fz <= FZ_CONTACT_MIN:
        return 0.0, 0.0
    dfz = (fz - p[P.FZ0]) / p[P.FZ0]
    cx = p[P.PCX1]
    dx = (p[P.PDX1] + p[P.PDX2] * dfz) * fz
    sgn = 1.0 if kappa > 0.0 else (-1.0 if kappa < 0.0 else 0.0)
    ex = (p[P.PEX1] + p[P.PEX2] * dfz + p[P.PEX3] * dfz * dfz) * (1.0 - p[P.PEX4] * sgn)
    bx = slip_stiffness(fz, p) / (cx * dx)
    bk = bx * kappa
    arg = bk - ex * (bk - math.atan(bk))
    angle = cx * math.atan(arg)
    darg = bx - ex * (bx - bx / (1.0 + bk * bk))
    return dx * math.sin(angle), dx * math.cos(angle) * cx / (1.0 + arg * arg) * darg


@jit
def low_speed_damping(vx: float, p: np.ndarray) -> float:
    """K_vlow, eq. (44)."""
    avx = abs(vx)
    if avx > p[P.V_LOW]:
        return 0.0
    return 0.5 * p[P.K_VLOW0] * (1.0 + math.cos(math.pi * avx / p[P.V_LOW]))


@jit
def transient_slip(u: float, sigma: float, vsx: float, vx: float, fz: float, p: np.ndarray) -> float:
    """kappa' = u / sigma* - K_vlow V_sx / K_xk, eq. (43) as corrected."""
    kappa = u / sigma
    if fz > FZ_CONTACT_MIN:
        kappa -= low_speed_damping(vx, p) * vsx / slip_stiffness(fz, p)
    return kappa


@jit
def relaxation_length(fx: float, kappa: float, fz: float, p: np.ndarray) -> float:
    """sigma*_kappa, eq. (41); sigma_k0 when the tyre is off the road."""
    if fz <= FZ_CONTACT_MIN:
        return p[P.SIGMA_K0]
    kxk = slip_stiffness(fz, p)
    eps = p[P.EPS_F]
    s = p[P.SIGMA_K0] / kxk * (abs(fx) + kxk * eps) / (abs(kappa) + eps)
    return max(s, p[P.SIGMA_MIN])


@jit
def deformation_rate(u: float, sigma: float, vsx: float, vx: float) -> float:
    """du/dt = -V_sx - |V_x| u / sigma*, eq. (42)."""
    return -vsx - abs(vx) * u / sigma
