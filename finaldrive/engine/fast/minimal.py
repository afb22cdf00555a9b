"""The same motorcycle in minimal coordinates z = (x1, y1, theta, phi, fs, beta).

Every other coordinate of Table 1 follows from z in closed form (engine.model.kinematics);
the engine sprocket angle alpha is eliminated through the chain constraint (30)-(31):
alpha = (1 - rho) gamma(D) + L_taut(D) / R_ES + rho beta - L / R_ES,  rho = R_WS / R_ES,
with D = r_6 - r_2, gamma the upper run's tangent angle and L_taut = sqrt(|D|^2 - (R_WS - R_ES)^2).

Lagrange's equations with the bodies' kinetic energy (engine.fast.bodies) give
M(z) z'' = F(z, z', u) - h(z, z'). Applied forces are the elements of engine.model.elements
(eqs. 34-52), projected by virtual work. The tyre state u obeys eq. (42) with the relaxation
length held through a step.

With the two-run chain (vehicle chain_runs = 2, docs/engine.md#chain-overrun) the engaged run
chooses the tangent: the upper run as above, or the lower run, the mirror of eqs. (24)-(29):
alpha = (1 - rho) gamma_l(D) - L_taut(D) / R_ES + rho beta + L_l / R_ES, gamma_l = delta + psi. Between
them the engine sprocket turns freely (its inertia leaves M); the state then carries the play the
sprocket has turned beyond the upper run's engagement, e = alpha - alpha_u(z) (the upper run's gap is
R_ES e), and alpha'.

With the elastic chain (vehicle chain_compliance = 1, docs/engine.md#the-elastic-chain-and-cush-drive)
the upper run and the cush drive are one spring-damper along the run, in series: the state carries e and
alpha' as above, the run is stretched by s = -R_ES e, and its tension T = k s + c s' (k = 1 / (1 / k_chain
+ R_WS^2 / k_cush), c = c_cush / R_WS^2) pulls the sprocket (I alpha'' = -T_drive + T R_ES) and, by
virtual work on alpha_u(z), the bodies (Q -= T R_ES d(alpha_u)/dz). A chain cannot push: slack (s <= 0)
the run carries nothing, and its damper holds T >= 0 (engine.fast.minimal.elastic_tension).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.fast.bodies import (
    G_P2_X,
    G_P2_Y,
    G_P3_X,
    G_P3_Y,
    G_P4_X,
    G_P4_Y,
    N_DOF,
    N_WS,
    W_B,
    W_C,
    W_Q,
    ZBETA,
    ZFS,
    ZPHI,
    ZTHETA,
    ZX1,
    ZY1,
    design_constants,
    inertia,
    mass_factor,
    mass_product,
    mass_solve,
)
from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.elements import (
    AUX_ALPHA_DOT,
    AUX_DUDT,
    AUX_P_DAMP,
    AUX_RE,
    AUX_TAUT,
    AUX_TAUT_RATE,
    AUX_TENSION,
    N_AUX,
    drive_torque,
    front_tyre,
    rear_tyre,
    spring_damper,
    sprocket_chain_tension,
)
from finaldrive.engine.model.linalg import dot
from finaldrive.engine.model.road_height import road_height

N_STATE = 2 * N_DOF + 1
ZU = 2 * N_DOF
#: The two-run chain's state adds e, the engine sprocket's turn beyond the upper run's engagement
#: [rad], and alpha' (in an engaged mode both follow from z, z'); so does the elastic chain's.
ZPLAY, ZALPHA_DOT = N_STATE, N_STATE + 1
N_STATE_TWO_RUNS = N_STATE + 2
#: The chain's modes (the engaged run): upper, lower, none (the engine sprocket turning freely); and the
#: elastic upper run (chain_compliance = 1), in which the engine sprocket also turns on its own.
UPPER, LOWER, FREE, ELASTIC = 1, -1, 0, 2


@jit
def chain_terms(w2x, w2y, w6x, w6y, wt, wp, wb, p, run=1.0):
    """The chain constraint solved for alpha, given the world offsets of points 2 and 6 from
    point 1 and theta', phi', beta': (d(alpha)/d(theta), d(alpha)/d(phi), alpha'' at z'' = 0,
    L_taut, L_taut', alpha'); d(alpha)/d(beta) = rho.

    alpha = g(D) + rho beta + const with g = (1 - rho) (delta - s psi) + s L_taut / R_ES, delta the
    angle of D, psi = acos(k / |D|), k = R_ES - R_WS; s = run = 1 for the upper run (eqs. 24-29, 31,
    30), -1 for the lower (their mirror); alpha'' at z'' = 0 is g's second derivative along D(t) with
    D'' the centripetal part.
    """
    dx, dy = w6x - w2x, w6y - w2y                                 # D = r6 - r2
    dth_x, dth_y = w2y, -w2x                                      # dD/dtheta
    dph_x, dph_y = -w6y, w6x                                      # dD/dphi
    vx, vy = dth_x * wt + dph_x * wp, dth_y * wt + dph_y * wp     # D'
    ddx = -w6x * wp * wp + w2x * wt * wt                          # D'' at z'' = 0
    ddy = -w6y * wp * wp + w2y * wt * wt
    res = p[P.R_ES]
    rho = p[P.R_WS] / res
    k = res - p[P.R_WS]
    d2 = dx * dx + dy * dy
    inv_d2 = 1.0 / d2
    d = math.sqrt(d2)
    lt = math.sqrt(d2 - k * k)
    inv_lt = 1.0 / lt
    radial = dx * vx + dy * vy                                    # |D| |D|'
    cross = dx * vy - dy * vx                                     # |D|^2 delta'
    d_dot = radial / d
    d_ddot = (vx * vx + vy * vy + dx * ddx + dy * ddy) / d - d_dot * d_dot / d
    delta_ddot = (dx * ddy - dy * ddx - 2.0 * radial * cross * inv_d2) * inv_d2
    psi1 = run * k / d * inv_lt                                   # s d(psi)/d|D|
    psi2 = -run * k * (2.0 * d2 - k * k) * inv_d2 * inv_lt * inv_lt * inv_lt
    lt1, lt2 = run * d * inv_lt, -run * k * k * inv_lt * inv_lt * inv_lt   # s d(L_taut)/d|D|, s d2(L_taut)/d|D|2
    f = 1.0 - rho
    # gradient of g in D: (1 - rho) (perp(D) / |D|^2 - psi1 D / |D|) + lt1 D / (|D| R_ES)
    radial_part = (-f * psi1 + lt1 / res) / d
    gx = -f * dy * inv_d2 + radial_part * dx
    gy = f * dx * inv_d2 + radial_part * dy
    ja_t = gx * dth_x + gy * dth_y
    ja_p = gx * dph_x + gy * dph_y
    alpha_c = f * (delta_ddot - psi1 * d_ddot - psi2 * d_dot * d_dot) + (lt1 * d_ddot + lt2 * d_dot * d_dot) / res
    alpha_dot = ja_t * wt + ja_p * wp + rho * wb
    return ja_t, ja_p, alpha_c, lt, radial * inv_lt, alpha_dot


@jit
def elastic_stiffness(p: np.ndarray) -> tuple[float, float]:
    """(k [N/m], c [N s/m]) of the elastic chain: the upper run (k_chain) in series with the cush drive
    (k_cush, c_cush about the wheel, seen along the run through R_WS)."""
    rws2 = p[P.R_WS] * p[P.R_WS]
    return 1.0 / (1.0 / p[P.K_CHAIN] + rws2 / p[P.K_CUSH]), p[P.C_CUSH] / rws2


@jit
def elastic_tension(play: float, play_rate: float, p: np.ndarray, aux: np.ndarray) -> float:
    """The elastic run's tension [N] for the sprocket's turn e = play beyond alpha_u(z): with the stretch
    s = -R_ES e, T = k s + c s' while both s and that are positive, else 0 (a chain does not push). The
    power it dissipates, T s' - k s s' (what does not go into the spring), into aux[AUX_P_DAMP]:
    c s'^2 while it pulls, -k s s' > 0 while it is stretched but releasing faster than its damper allows."""
    k, c = elastic_stiffness(p)
    s, s_dot = -p[P.R_ES] * play, -p[P.R_ES] * play_rate
    if s <= 0.0:
        return 0.0
    t = k * s + c * s_dot
    if t <= 0.0:
        aux[AUX_P_DAMP] -= k * s * s_dot
        return 0.0
    aux[AUX_P_DAMP] += c * s_dot * s_dot
    return t


@jit
def elastic_energy(y: np.ndarray, p: np.ndarray) -> float:
    """The elastic run's spring energy k s^2 / 2 at the state y [J], 0 when slack (s <= 0) or without
    chain_compliance (or without the sprocket's state in y)."""
    if p[P.CHAIN_COMPLIANCE] == 0.0 or y.shape[0] != N_STATE_TWO_RUNS:
        return 0.0
    k, _ = elastic_stiffness(p)
    s = max(0.0, -p[P.R_ES] * y[ZPLAY])
    return 0.5 * k * s * s


@jit
def fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, out, aux, ws, run=UPPER):
    """y' for y = (z, z', u), or (z, z', u, e, alpha') for the two-run or the elastic chain; returns a failure
    code (0 = ok).

    run: the chain's mode, UPPER (the paper's), LOWER, FREE or ELASTIC. aux[AUX_TENSION] is the chain's net
    pull on the engine sprocket, T_upper - T_lower = (T + I alpha'') / R_ES: the upper run's tension
    in the paper's model (negative: pushing), the lower run's pull with its sign changed in LOWER.

    The force elements are engine.model.elements' (aux receives their outputs); this function
    projects them onto z by virtual work beside the bodies' gravity and inertia
    (engine.fast.bodies). Also fills the workspace ws (N_WS) for the linearly implicit step:
    M's factors (engine.fast.bodies.mass_solve), b = ws[W_B:W_B + 6], the generalized force of a
    unit F_x (its lever arm included), and c = ws[W_C:W_C + 6] = d(u')/dz' (dF_x/du is
    aux[AUX_SLOPE] / sigma). geo: design_constants(p).
    """
    x1, y1, theta, phi, fs = y[ZX1], y[ZY1], y[ZTHETA], y[ZPHI], y[ZFS]
    xd, yd, wt, wp, fsd, wb = y[6], y[7], y[8], y[9], y[10], y[11]
    u = y[ZU]
    aux[AUX_P_DAMP] = 0.0
    st, ct = libm.sincos(theta)
    sp, cp = libm.sincos(phi)
    w2x, w2y = ct * geo[G_P2_X] - st * geo[G_P2_Y], st * geo[G_P2_X] + ct * geo[G_P2_Y]
    w6x, w6y = p[P.L_SA] * cp, p[P.L_SA] * sp
    ja_t, ja_p, alpha_c, taut, taut_rate, alpha_dot = chain_terms(
        w2x, w2y, w6x, w6y, wt, wp, wb, p, -1.0 if run == LOWER else 1.0)
    rho = p[P.R_WS] / p[P.R_ES]
    upper_rate = alpha_dot                                             # alpha_u', read when FREE or ELASTIC (e')
    stretch_t, stretch_p, stretch_b = ja_t, ja_p, rho                  # d(alpha_u)/dz: the elastic run's gradient
    if run in (FREE, ELASTIC):                                         # alpha is the sprocket's own
        ja_t, ja_p, alpha_c, rho, alpha_dot = 0.0, 0.0, 0.0, 0.0, y[ZALPHA_DOT]
    ux, uy = inertia(geo, p, ct, st, cp, sp, fs, wt, wp, fsd, ja_t, ja_p, alpha_c, rho, ws)
    # rear tyre: radial (36) and longitudinal (38)-(52) forces at point 14, below point 6
    hr, dhr, _ = road_height(kind, rp, x1 + w6x)
    rt = y1 + w6y - hr                                                 # (20), (32)
    drt_phi = w6x + dhr * w6y
    rt_dot = yd - dhr * xd + drt_phi * wp
    vx = xd - w6y * wp                                                 # (39)
    fz_rear, fx, lever = rear_tyre(rt, rt_dot, vx, -wb, u, sigma, p, longitudinal, aux)  # (36), (38)-(52)
    # drive torque on the sprocket (alpha decreasing) and its reaction on the chassis (after the rear
    # tyre: the launch drive reads its load)
    torque = drive_torque(wt, alpha_dot, p, aux)
    q_x = ws[W_Q + ZX1]
    q_y = ws[W_Q + ZY1]
    q_t = ws[W_Q + ZTHETA] + torque * (1.0 - ja_t)
    q_p = ws[W_Q + ZPHI] - torque * ja_p
    q_s = ws[W_Q + ZFS]
    q_b = ws[W_Q + ZBETA] - torque * rho
    pull = 0.0
    if run == ELASTIC:   # the run's tension T, times R_ES: on the sprocket, and on z through alpha_u(z)
        pull = elastic_tension(y[ZPLAY], alpha_dot - upper_rate, p, aux) * p[P.R_ES]
        q_t -= pull * stretch_t
        q_p -= pull * stretch_p
        q_b -= pull * stretch_b
    q_x += fx - fz_rear * dhr
    q_y += fz_rear
    q_p += fz_rear * drt_phi - fx * w6y
    q_b += fx * lever
    ws[W_B + ZX1], ws[W_B + ZY1], ws[W_B + ZTHETA] = 1.0, 0.0, 0.0
    ws[W_B + ZPHI], ws[W_B + ZFS], ws[W_B + ZBETA] = -w6y, 0.0, lever
    sgn = 1.0 if vx > 0.0 else (-1.0 if vx < 0.0 else 0.0)
    c_x = -(1.0 + sgn * u / sigma)                                     # d(u')/dx1' (42), (40)
    ws[W_C + ZX1], ws[W_C + ZY1], ws[W_C + ZTHETA] = c_x, 0.0, 0.0
    ws[W_C + ZPHI], ws[W_C + ZFS], ws[W_C + ZBETA] = -c_x * w6y, 0.0, -aux[AUX_RE]  # dV_sx/dbeta' = R_e (38)
    # rear suspension (35) between points 3 (chassis) and 7 (swingarm)
    w3x, w3y = ct * geo[G_P3_X] - st * geo[G_P3_Y], st * geo[G_P3_X] + ct * geo[G_P3_Y]
    ex, ey = w3x - p[P.L7] * cp, w3y - p[P.L7] * sp
    rs = math.sqrt(ex * ex + ey * ey)                                  # (13)
    drs_th = (-ex * w3y + ey * w3x) / rs
    drs_ph = (ex * p[P.L7] * sp - ey * p[P.L7] * cp) / rs
    f_rs = spring_damper(rs, drs_th * wt + drs_ph * wp, p[P.K_RS], p[P.C_RS], p[P.S_RS], p[P.RS_BUMP], p,
                         aux)  # (35)
    q_t += f_rs * drs_th
    q_p += f_rs * drs_ph
    # front suspension (34): fs is a minimal coordinate
    q_s += spring_damper(fs, fsd, p[P.K_FS], p[P.C_FS], p[P.S_FS], p[P.FS_BUMP], p, aux)  # (34)
    # front tyre (37) at point 13 = r_4 + (fs + L8) u, on the fork axis (eqs. 14-17)
    slide = fs + p[P.L8]
    ox = ct * geo[G_P4_X] - st * geo[G_P4_Y] + slide * ux
    oy = st * geo[G_P4_X] + ct * geo[G_P4_Y] + slide * uy
    hf, dhf, _ = road_height(kind, rp, x1 + ox)
    ft = y1 + oy - hf                                                  # (21), (33)
    g_t, g_s = ox + dhf * oy, uy - dhf * ux                            # d(ft)/d(theta), d(ft)/d(fs)
    fz_front = front_tyre(ft, yd - dhf * xd + g_t * wt + g_s * fsd, p, aux)  # (37)
    q_x -= fz_front * dhf
    q_y += fz_front
    q_t += fz_front * g_t
    q_s += fz_front * g_s
    ws[W_Q + ZX1], ws[W_Q + ZY1], ws[W_Q + ZTHETA] = q_x, q_y, q_t
    ws[W_Q + ZPHI], ws[W_Q + ZFS], ws[W_Q + ZBETA] = q_p, q_s, q_b
    # M z'' = F - h
    mass_factor(geo, ws)
    mass_solve(geo, ws, ws, out, W_Q, N_DOF)
    for i in range(N_DOF):
        out[i] = y[N_DOF + i]
    out[ZU] = aux[AUX_DUDT]                                            # (42)
    alpha_dd = alpha_c + ja_t * out[N_DOF + ZTHETA] + ja_p * out[N_DOF + ZPHI] + rho * out[N_DOF + ZBETA]
    if run in (FREE, ELASTIC):
        alpha_dd = (pull - torque) / p[P.I_SPROCKET]                   # its own: I alpha'' = -T_drive + T R_ES
    # the elastic run's own tension (through alpha'' it would be T only up to rounding: a slack run pushing 1e-12 N)
    aux[AUX_TENSION] = pull / p[P.R_ES] if run == ELASTIC else sprocket_chain_tension(torque, alpha_dd, p)
    aux[AUX_TAUT] = taut
    aux[AUX_TAUT_RATE] = taut_rate
    aux[AUX_ALPHA_DOT] = alpha_dot
    if y.shape[0] == N_STATE_TWO_RUNS:  # e' (engaged: e follows from z, projected after each step)
        out[ZPLAY] = alpha_dot - upper_rate if run in (FREE, ELASTIC) else 0.0
        out[ZALPHA_DOT] = alpha_dd
    for i in range(y.shape[0]):
        if not math.isfinite(out[i]):
            return 1
    return 0


@jit(allocates=True)
def kinetic_energy(y, p, kind, rp, run=UPPER):
    """1/2 z'^T M(z) z' [J] at the state y, with the mass matrix of fast_rhs in the chain's mode run
    (FREE, ELASTIC: the engine sprocket's 1/2 I alpha'^2 added, its inertia being out of M)."""
    out = np.zeros(y.shape[0])
    aux = np.zeros(N_AUX)
    ws = np.zeros(N_WS)
    geo = design_constants(p)
    fast_rhs(y, p, geo, kind, rp, p[P.SIGMA_K0], False, out, aux, ws, run)
    mz = np.zeros(N_DOF)
    mass_product(geo, ws, y[N_DOF:ZU], mz)
    free = 0.5 * p[P.I_SPROCKET] * y[ZALPHA_DOT] ** 2 if run in (FREE, ELASTIC) else 0.0
    return 0.5 * dot(y[N_DOF:ZU], mz) + free
