"""The same motorcycle in minimal coordinates z = (x1, y1, theta, phi, fs, beta).

Every other coordinate of Table 1 follows from z in closed form (engine.model.kinematics);
the engine sprocket angle alpha is eliminated through the chain constraint (30)-(31):
alpha = (1 - rho) gamma(D) + L_taut(D) / R_ES + rho beta - L / R_ES,  rho = R_WS / R_ES,
with D = r_6 - r_2, gamma the upper run's tangent angle and L_taut = sqrt(|D|^2 - (R_WS - R_ES)^2).

Lagrange's equations with the bodies' kinetic energy (Table 2: mass at the centre of mass,
inertia about it) give M(z) z'' = F(z, z', u) - h(z, z'), where h collects the velocity
products (J' z' terms). Applied forces are the elements of engine.model.elements (eqs. 34-52),
projected by virtual work. The tyre state u obeys eq. (42) with the relaxation length held through a step.
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.model import params as P
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
from finaldrive.engine.model.jit import jit
from finaldrive.engine.model.linalg import cholesky_in_place, cholesky_solve
from finaldrive.engine.model.road_height import road_height

N_DOF = 6
ZX1, ZY1, ZTHETA, ZPHI, ZFS, ZBETA = range(N_DOF)
N_STATE = 2 * N_DOF + 1
ZU = 2 * N_DOF


# Slots of the per-design constants (chassis-frame vectors), see design_constants.
(G_COG_X, G_COG_Y, G_P2_X, G_P2_Y, G_P3_X, G_P3_Y, G_P4_X, G_P4_Y, G_AXIS_X, G_AXIS_Y) = range(10)
N_GEO = 10


@jit
def design_constants(p: np.ndarray) -> np.ndarray:
    """Chassis-frame vectors from point 1: the chassis centre of mass, points 2, 3, 4, and the
    unit vector of the fork axis r_4->5 (eqs. 1-8, 14-15)."""
    g = np.empty(N_GEO)
    g[G_COG_X], g[G_COG_Y] = p[P.CHASSIS_COG_X], p[P.CHASSIS_COG_Y]
    g[G_P2_X], g[G_P2_Y] = p[P.L2] * math.cos(p[P.A2]), p[P.L2] * math.sin(p[P.A2])
    g[G_P3_X], g[G_P3_Y] = p[P.L3] * math.cos(p[P.A3]), p[P.L3] * math.sin(p[P.A3])
    g[G_P4_X], g[G_P4_Y] = p[P.L4] * math.cos(p[P.A4]), p[P.L4] * math.sin(p[P.A4])
    ux = p[P.L5] * math.cos(p[P.A5]) - g[G_P4_X]
    uy = p[P.L5] * math.sin(p[P.A5]) - g[G_P4_Y]
    n = math.hypot(ux, uy)
    g[G_AXIS_X], g[G_AXIS_Y] = ux / n, uy / n
    return g


@jit
def _rigid_point(wx, wy, col, rate, J, a):
    """A point at world offset w from point 1 on a body turning with coordinate `col`:
    J has identity on (x1, y1) and perp(w) in column col; a = -rate^2 w."""
    J[:, :] = 0.0
    J[0, ZX1] = 1.0
    J[1, ZY1] = 1.0
    J[0, col] = -wy
    J[1, col] = wx
    a[0] = -rate * rate * wx
    a[1] = -rate * rate * wy


@jit
def _fork_point(w4x, w4y, ux, uy, slide, slide_rate, theta_rate, J, a):
    """A point on the fork axis: r4 + slide * u (eqs. 14-17), u the world fork axis."""
    ox, oy = w4x + slide * ux, w4y + slide * uy
    J[:, :] = 0.0
    J[0, ZX1] = 1.0
    J[1, ZY1] = 1.0
    J[0, ZTHETA] = -oy
    J[1, ZTHETA] = ox
    J[0, ZFS] = ux
    J[1, ZFS] = uy
    w2 = theta_rate * theta_rate
    cross = 2.0 * slide_rate * theta_rate
    a[0] = -w2 * ox - cross * uy
    a[1] = -w2 * oy + cross * ux
    return ox, oy


@jit
def chain_terms(w2x, w2y, w6x, w6y, zd, p, jalpha):
    """The chain constraint solved for alpha, given the world offsets of points 2 and 6
    from point 1: fills d(alpha)/dz into jalpha; returns (alpha'' at z'' = 0, L_taut,
    L_taut', alpha')."""
    dx, dy = w6x - w2x, w6y - w2y                                 # D = r6 - r2
    # dD/dtheta, dD/dphi and D'' at z'' = 0
    dth_x, dth_y = w2y, -w2x
    dph_x, dph_y = -w6y, w6x
    wt, wp = zd[ZTHETA], zd[ZPHI]
    ddx = -w6x * wp * wp + w2x * wt * wt
    ddy = -w6y * wp * wp + w2y * wt * wt
    vx, vy = dth_x * wt + dph_x * wp, dth_y * wt + dph_y * wp     # D'
    res, rws = p[P.R_ES], p[P.R_WS]
    rho = rws / res
    k = res - rws
    d2 = dx * dx + dy * dy
    d = math.sqrt(d2)
    lt = math.sqrt(d2 - k * k)
    # gradient and Hessian of g(D) = (1 - rho) (delta - psi) + L_taut / R_ES
    # delta = angle of D; psi = acos(k / d) (eqs. 24-29, 31)
    d4 = d2 * d2
    gdx, gdy = -dy / d2, dx / d2
    hd_xx, hd_xy, hd_yy = 2.0 * dx * dy / d4, (dy * dy - dx * dx) / d4, -2.0 * dx * dy / d4
    root = math.sqrt(d2 - k * k)
    psi1 = k / (d * root)
    psi2 = -k * (2.0 * d2 - k * k) / (d2 * root * root * root)
    gpx, gpy = psi1 * dx / d, psi1 * dy / d
    hp_xx = psi2 * dx * dx / d2 + psi1 * (1.0 / d - dx * dx / (d2 * d))
    hp_xy = psi2 * dx * dy / d2 - psi1 * dx * dy / (d2 * d)
    hp_yy = psi2 * dy * dy / d2 + psi1 * (1.0 / d - dy * dy / (d2 * d))
    glx, gly = dx / lt, dy / lt
    lt3 = lt * lt * lt
    hl_xx, hl_xy, hl_yy = 1.0 / lt - dx * dx / lt3, -dx * dy / lt3, 1.0 / lt - dy * dy / lt3
    f = 1.0 - rho
    gx = f * (gdx - gpx) + glx / res
    gy = f * (gdy - gpy) + gly / res
    hxx = f * (hd_xx - hp_xx) + hl_xx / res
    hxy = f * (hd_xy - hp_xy) + hl_xy / res
    hyy = f * (hd_yy - hp_yy) + hl_yy / res
    jalpha[:] = 0.0
    jalpha[ZTHETA] = gx * dth_x + gy * dth_y
    jalpha[ZPHI] = gx * dph_x + gy * dph_y
    jalpha[ZBETA] = rho
    alpha_c = gx * ddx + gy * ddy + vx * vx * hxx + 2.0 * vx * vy * hxy + vy * vy * hyy
    alpha_dot = gx * vx + gy * vy + rho * zd[ZBETA]
    return alpha_c, lt, glx * vx + gly * vy, alpha_dot


@jit
def _add_body(M, h, F, J, a, m, g):
    """A centre of mass of mass m: M += m J^T J; h += m J^T a; F += gravity (-m g J_y)."""
    for i in range(N_DOF):
        for j in range(i, N_DOF):
            M[i, j] += m * (J[0, i] * J[0, j] + J[1, i] * J[1, j])
        h[i] += m * (J[0, i] * a[0] + J[1, i] * a[1])
        F[i] -= m * g * J[1, i]


@jit
def fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, want_jac, out, aux, L, b, c_row, ws):
    """y' for y = (z, z', u); returns a failure code (0 = ok).

    The force elements are engine.model.elements' (aux receives their outputs); this function
    projects them onto z by virtual work and adds the bodies' gravity and inertia. Also fills,
    for the linearly implicit step: L, the Cholesky factor of M(z); b, the generalized force of
    a unit F_x (its lever arm included); c_row = d(u')/dz' when want_jac (dF_x/du is
    aux[AUX_SLOPE] / sigma). geo: design_constants(p). ws: a (6, 6) workspace.
    """
    z = y[:N_DOF]
    zd = y[N_DOF:ZU]
    u = y[ZU]
    J = ws[0:2]
    a = ws[2, 0:2]
    jalpha = ws[3]
    h = ws[4]
    F = ws[5]
    h[:] = 0.0
    F[:] = 0.0
    aux[AUX_P_DAMP] = 0.0
    M = L
    M[:, :] = 0.0
    g = p[P.GRAVITY]
    ct, st = math.cos(z[ZTHETA]), math.sin(z[ZTHETA])
    cp, sp = math.cos(z[ZPHI]), math.sin(z[ZPHI])
    wt, wp = zd[ZTHETA], zd[ZPHI]
    # chassis + rider (Table 2, body I): gravity and inertia
    wx, wy = ct * geo[G_COG_X] - st * geo[G_COG_Y], st * geo[G_COG_X] + ct * geo[G_COG_Y]
    _rigid_point(wx, wy, ZTHETA, wt, J, a)
    _add_body(M, h, F, J, a, p[P.M_CHASSIS], g)
    M[ZTHETA, ZTHETA] += p[P.I_CHASSIS]
    # swingarm (body II)
    frac = p[P.SWINGARM_COG_FRACTION] * p[P.L_SA]
    _rigid_point(frac * cp, frac * sp, ZPHI, wp, J, a)
    _add_body(M, h, F, J, a, p[P.M_SWINGARM], g)
    M[ZPHI, ZPHI] += p[P.I_SWINGARM]
    # engine sprocket (body III): centre of mass at point 2, turning with alpha (chain)
    w2x, w2y = ct * geo[G_P2_X] - st * geo[G_P2_Y], st * geo[G_P2_X] + ct * geo[G_P2_Y]
    _rigid_point(w2x, w2y, ZTHETA, wt, J, a)
    _add_body(M, h, F, J, a, p[P.M_SPROCKET], g)
    w6x, w6y = p[P.L_SA] * cp, p[P.L_SA] * sp
    alpha_c, taut, taut_rate, alpha_dot = chain_terms(w2x, w2y, w6x, w6y, zd, p, jalpha)
    for i in range(N_DOF):
        for j in range(N_DOF):
            M[i, j] += p[P.I_SPROCKET] * jalpha[i] * jalpha[j]
        h[i] += p[P.I_SPROCKET] * jalpha[i] * alpha_c
    torque = drive_torque(wt, alpha_dot, p, aux)
    for i in range(N_DOF):
        F[i] -= torque * jalpha[i]             # drive torque on the sprocket (alpha decreasing) ...
    F[ZTHETA] += torque                        # ... and its reaction on the chassis
    # rear wheel (body IV): centre of mass at point 6, turning with beta
    _rigid_point(w6x, w6y, ZPHI, wp, J, a)
    _add_body(M, h, F, J, a, p[P.M_REAR_WHEEL], g)
    M[ZBETA, ZBETA] += p[P.I_REAR_WHEEL]
    # rear tyre: radial (36) and longitudinal (38)-(52) forces at point 14, below point 6
    x6, y6 = z[ZX1] + w6x, z[ZY1] + w6y
    hr, dhr, _ = road_height(kind, rp, x6)
    rt = y6 - hr                                                       # (20), (32)
    drt_phi = w6x + dhr * w6y
    rt_dot = zd[ZY1] - dhr * zd[ZX1] + drt_phi * wp
    vx = zd[ZX1] - w6y * wp                                            # (39)
    fz_rear, fx, lever = rear_tyre(rt, rt_dot, vx, -zd[ZBETA], u, sigma, p, longitudinal, aux)  # (36), (38)-(52)
    F[ZY1] += fz_rear
    F[ZX1] -= fz_rear * dhr
    F[ZPHI] += fz_rear * drt_phi
    b[:] = 0.0
    b[ZX1] = 1.0
    b[ZPHI] = -w6y
    b[ZBETA] = lever
    F[ZX1] += fx
    F[ZPHI] -= fx * w6y
    F[ZBETA] += fx * lever
    if want_jac:
        sgn = 1.0 if vx > 0.0 else (-1.0 if vx < 0.0 else 0.0)
        c_row[:] = 0.0
        c_row[ZX1] = -(1.0 + sgn * u / sigma)
        c_row[ZPHI] = c_row[ZX1] * (-w6y)
        c_row[ZBETA] = -aux[AUX_RE]                                   # dV_sx/dbeta' = R_e (38)
    # rear suspension (35) between points 3 (chassis) and 7 (swingarm)
    w3x, w3y = ct * geo[G_P3_X] - st * geo[G_P3_Y], st * geo[G_P3_X] + ct * geo[G_P3_Y]
    w7x, w7y = p[P.L7] * cp, p[P.L7] * sp
    ex, ey = w3x - w7x, w3y - w7y
    rs = math.sqrt(ex * ex + ey * ey)                                  # (13)
    drs_th = (-ex * w3y + ey * w3x) / rs
    drs_ph = (ex * w7y - ey * w7x) / rs
    f_rs = spring_damper(rs, drs_th * wt + drs_ph * wp, p[P.K_RS], p[P.C_RS], p[P.S_RS], aux)  # (35)
    F[ZTHETA] += f_rs * drs_th
    F[ZPHI] += f_rs * drs_ph
    # front suspension (34): fs is a minimal coordinate
    F[ZFS] += spring_damper(z[ZFS], zd[ZFS], p[P.K_FS], p[P.C_FS], p[P.S_FS], aux)
    # lower fork (body V) and front wheel (body VI, a point mass at 13)
    w4x, w4y = ct * geo[G_P4_X] - st * geo[G_P4_Y], st * geo[G_P4_X] + ct * geo[G_P4_Y]
    ux, uy = ct * geo[G_AXIS_X] - st * geo[G_AXIS_Y], st * geo[G_AXIS_X] + ct * geo[G_AXIS_Y]
    _fork_point(w4x, w4y, ux, uy, z[ZFS] + p[P.FORK_COG_FRACTION] * p[P.L8], zd[ZFS], wt, J, a)
    _add_body(M, h, F, J, a, p[P.M_FORK], g)
    M[ZTHETA, ZTHETA] += p[P.I_FORK]
    ox, oy = _fork_point(w4x, w4y, ux, uy, z[ZFS] + p[P.L8], zd[ZFS], wt, J, a)
    _add_body(M, h, F, J, a, p[P.M_FRONT_WHEEL], g)
    x13, y13 = z[ZX1] + ox, z[ZY1] + oy
    hf, dhf, _ = road_height(kind, rp, x13)
    ft = y13 - hf                                                      # (21), (33)
    ft_dot = 0.0
    for i in range(N_DOF):
        ft_dot += (J[1, i] - dhf * J[0, i]) * zd[i]
    fz_front = front_tyre(ft, ft_dot, p, aux)                          # (37)
    for i in range(N_DOF):
        F[i] += fz_front * (J[1, i] - dhf * J[0, i])
    # M z'' = F - h
    cholesky_in_place(M)
    zdd = out[N_DOF:ZU]
    for i in range(N_DOF):
        F[i] -= h[i]
    cholesky_solve(M, F, zdd)
    out[:N_DOF] = zd
    out[ZU] = aux[AUX_DUDT]                                            # (42)
    alpha_dd = alpha_c
    for i in range(N_DOF):
        alpha_dd += jalpha[i] * zdd[i]
    aux[AUX_TENSION] = sprocket_chain_tension(alpha_dd, p)
    aux[AUX_TAUT] = taut
    aux[AUX_TAUT_RATE] = taut_rate
    aux[AUX_ALPHA_DOT] = alpha_dot
    for i in range(N_STATE):
        if not math.isfinite(out[i]):
            return 1
    return 0


@jit
def kinetic_energy(y, p, kind, rp):
    """1/2 z'^T M(z) z' [J] at the state y, with the mass matrix of fast_rhs."""
    out = np.zeros(N_STATE)
    aux = np.zeros(N_AUX)
    L = np.zeros((N_DOF, N_DOF))
    b = np.zeros(N_DOF)
    c = np.zeros(N_DOF)
    ws = np.zeros((6, N_DOF))
    fast_rhs(y, p, design_constants(p), kind, rp, p[P.SIGMA_K0], False, False, out, aux, L, b, c, ws)
    e = 0.0
    for j in range(N_DOF):  # M = L L^T: z'^T M z' = |L^T z'|^2
        s = 0.0
        for i in range(j, N_DOF):
            s += L[i, j] * y[N_DOF + i]
        e += s * s
    return 0.5 * e
