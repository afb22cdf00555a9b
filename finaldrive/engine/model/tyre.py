"""The tyres, described once for both solvers: radial spring-damper with the rear bump stop
(eqs. 36-37), the rear tyre's longitudinal force by Pacejka's fully nonlinear transient model
(eqs. 38-52) with its load range, and the lever arm of that force on the wheel.

Sign convention: kappa' > 0 and F_x > 0 when driving (the wheel spins faster than it rolls).
Two corrections to the printed text (docs/engine.md#reading-notes-extraction-faults): eq. (43)
uses K_vlow * V_sx / K_xk, and pKx1 is 25.939. The algebraic loop of eq. (41) (sigma* needs F_x
and kappa', which need sigma*) is closed with the values of the last accepted step: sigma* is
held through each step.

Choices where the paper is silent (docs/engine.md): eqs. (47)-(52) see the vertical load held
inside the load range [Fz_min, Fz_max] (like MF 6.1's FZMIN/FZMAX); the rear
tyre bottoms on a stiff bump stop at the deflection rt_bottoming; F_x turns the wheel with the
lever arm R_e + fx_lever_loaded (rt - R_e), R_e by default (energy-consistent with eq. 40).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P

#: Below this vertical load [N] the tyre is off the road: no longitudinal force.
FZ_CONTACT_MIN = 1.0e-6


@jit
def radial_force(r: float, rdot: float, r0: float, k: float, c: float, bottoming: float,
                 k_bottoming: float) -> float:
    """One-sided tyre spring-damper, eqs. (36)-(37): zero off the road; beyond the deflection
    ``bottoming`` the rim bottoms on a bump stop of stiffness ``k_bottoming`` (in parallel)."""
    deflection = r0 - r
    if deflection <= 0.0:
        return 0.0
    f = k * deflection - c * rdot
    if deflection > bottoming:
        f += k_bottoming * (deflection - bottoming)
    return f


@jit
def radial_energy(r: float, r0: float, k: float, bottoming: float, k_bottoming: float) -> float:
    """Energy stored in the tyre's radial spring and bump stop [J] (the potential of radial_force)."""
    deflection = r0 - r
    if deflection <= 0.0:
        return 0.0
    e = 0.5 * k * deflection * deflection
    if deflection > bottoming:
        e += 0.5 * k_bottoming * (deflection - bottoming) ** 2
    return e


@jit
def radial_damping_power(r: float, rdot: float, r0: float, c: float) -> float:
    """Power dissipated by the tyre's radial damper [W], c r'^2 while on the road."""
    if r >= r0:
        return 0.0
    return c * rdot * rdot


@jit
def effective_radius(rt: float, p: np.ndarray) -> float:
    """R_e = 2/3 rt0 + 1/3 rt, eq. (38)."""
    return 2.0 / 3.0 * p[P.RT0] + rt / 3.0


@jit
def lever_arm(rt: float, re: float, p: np.ndarray) -> float:
    """Lever arm of F_x on the rear wheel: R_e (default, energy-consistent) or towards rt."""
    return re + p[P.FX_LEVER_LOADED] * (rt - re)


@jit
def range_load(fz: float, p: np.ndarray) -> float:
    """The load eqs. (47)-(52) see: F_z held inside the load range [Fz_min, Fz_max] (MF 6.1's
    FZMIN/FZMAX: beyond the range the tyre's load dependence stays that of the bound)."""
    return min(max(fz, p[P.FZ_MIN]), p[P.FZ_MAX])


@jit
def load_increment(fz: float, p: np.ndarray) -> float:
    """df_z of eq. (52) at the load held in the range."""
    return (range_load(fz, p) - p[P.FZ0]) / p[P.FZ0]


@jit
def slip_stiffness(fz: float, p: np.ndarray) -> float:
    """K_xk, eq. (50), at the load held in the range (df_z from eq. 52)."""
    fzr = range_load(fz, p)
    dfz = (fzr - p[P.FZ0]) / p[P.FZ0]
    return fzr * (p[P.PKX1] + p[P.PKX2] * dfz) * libm.exp(p[P.PKX3] * dfz)


@jit
def magic_formula_slope(fz: float, kappa: float, p: np.ndarray) -> tuple[float, float]:
    """Steady-state F_x(F_z, kappa) of eqs. (45)-(52) and dF_x/dkappa (for linearly implicit
    steps and the tests); zero off the road; the load held in the range."""
    if fz <= FZ_CONTACT_MIN:
        return 0.0, 0.0
    fzr = range_load(fz, p)
    dfz = (fzr - p[P.FZ0]) / p[P.FZ0]                                         # (52)
    cx = p[P.PCX1]                                                            # (46)
    dx = (p[P.PDX1] + p[P.PDX2] * dfz) * fzr                                  # (47)-(48)
    sgn = 1.0 if kappa > 0.0 else (-1.0 if kappa < 0.0 else 0.0)
    ex = (p[P.PEX1] + p[P.PEX2] * dfz + p[P.PEX3] * dfz * dfz) * (1.0 - p[P.PEX4] * sgn)  # (49)
    bx = slip_stiffness(fz, p) / (cx * dx)                                    # (50)-(51)
    bk = bx * kappa
    arg = bk - ex * (bk - libm.atan(bk))
    angle = cx * libm.atan(arg)
    darg = bx - ex * (bx - bx / (1.0 + bk * bk))
    s, c = libm.sincos(angle)
    return dx * s, dx * c * cx / (1.0 + arg * arg) * darg   # (45)


@jit
def magic_formula(fz: float, kappa: float, p: np.ndarray) -> float:
    """Steady-state longitudinal force F_x(F_z, kappa), eqs. (45)-(52)."""
    return magic_formula_slope(fz, kappa, p)[0]


@jit
def low_speed_damping(vx: float, p: np.ndarray) -> float:
    """K_vlow, eq. (44)."""
    avx = abs(vx)
    if avx > p[P.V_LOW]:
        return 0.0
    return 0.5 * p[P.K_VLOW0] * (1.0 + libm.cos(math.pi * avx / p[P.V_LOW]))


@jit
def transient_slip(u: float, sigma: float, vsx: float, vx: float, fz: float, p: np.ndarray) -> float:
    """kappa' = u / sigma* - K_vlow V_sx / K_xk, eq. (43) as corrected."""
    kappa = u / sigma
    if fz > FZ_CONTACT_MIN:
        k_vlow = low_speed_damping(vx, p)
        if k_vlow != 0.0:  # zero above V_low
            kappa -= k_vlow * vsx / slip_stiffness(fz, p)
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


@jit
def low_speed_factor(vx: float, fz: float, p: np.ndarray) -> float:
    """a = |V_x| K_vlow / K_xk >= 0: how much eq. (43)'s low-speed damping adds to the slip
    (docs/engine.md#the-tyres-energy-ledger); 0 off the road and above V_low."""
    k_vlow = low_speed_damping(vx, p) if fz > FZ_CONTACT_MIN else 0.0
    if k_vlow == 0.0:
        return 0.0
    return abs(vx) * k_vlow / slip_stiffness(fz, p)
