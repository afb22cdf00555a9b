"""The six bodies of Table 2 in minimal coordinates z = (x1, y1, theta, phi, fs, beta), in closed form.

Lagrange's equations with the bodies' kinetic energy (mass at the centre of mass, inertia about it)
give M(z) z'' = F - h(z, z'). A body's centre of mass r = r_1 + w moves with point 1 and turns with
theta (chassis + rider, engine sprocket at point 2, lower fork, front wheel at point 13: chassis
bodies, the last two also sliding along the fork axis u, eqs. 14-17) or with phi (swingarm, rear
wheel at point 6); the sprocket also turns with alpha(z) (the chain, eqs. 30-31) and the rear
wheel with beta. Summed over the bodies, M's entries are the bodies' masses, first moments
S = sum m w and second moments sum m |w|^2 about point 1, the same in the chassis frame as in the
world for the chassis bodies but for the fork's slide:

    M_xx = M_yy = m_total,  (M_x., M_y.) = (-S_y, S_x) for theta and phi,  m_F u for fs,
    M_theta,theta = sum m |w|^2 + I's + I_sprocket alpha_theta^2,  M_theta,fs = m_F (r_4 x u), ...

with m_F the fork's and front wheel's masses, alpha_k = d(alpha)/dz_k. The velocity products
h = sum m J^T (J' z') are -theta'^2 S_theta - phi'^2 S_phi + 2 fs' theta' m_F perp(u) on (x1, y1),
the fork's Coriolis and centrifugal terms, and I_sprocket alpha_k alpha'' (z'' = 0).

A rolling front wheel (the vehicle's front_wheel_spin; engine.model.mass.front_wheel_spin_mass
k = I_front_wheel / ft0^2) adds k x_13'^2 / 2 with x_13' = a . z' the front axle's forward speed,
a = (1, 0, -(w_y), 0, u_x, 0) for w = r_1->13 in the world: M gains k a a^T (M_xx = m_total + k, no
longer M_yy) and h gains k a (a' . z'), a' . z' = -theta'^2 w_x - 2 theta' fs' u_y (x_13 is a
function of z, so Lagrange's equations leave only these terms).

M is solved by its structure: x1 (M_xx), y1 (m_total) and beta (coupled to theta and phi only through
the sprocket) are eliminated, leaving a 3 x 3 system in (theta, phi, fs) (LDL^T). Nothing is
allocated: the entries and factors live in the caller's workspace ``ws``.
"""

from __future__ import annotations

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.mass import front_wheel_spin_mass

N_DOF = 6
ZX1, ZY1, ZTHETA, ZPHI, ZFS, ZBETA = range(N_DOF)

# Per-design constants (design_constants): chassis-frame vectors from point 1 to the chassis centre
# of mass and points 2, 3, 4, the fork axis unit vector, and the bodies' mass moments.
(G_COG_X, G_COG_Y, G_P2_X, G_P2_Y, G_P3_X, G_P3_Y, G_P4_X, G_P4_Y, G_AXIS_X, G_AXIS_Y,
 G_MASS, G_MASS_FORK, G_S_RIGID_X, G_S_RIGID_Y, G_J_RIGID, G_P4_DOT_U, G_P4_CROSS_U, G_S_SWING,
 G_J_SWING, G_FORK_MOMENT, G_FORK_SECOND, G_SPIN, G_MASS_X) = range(23)
N_GEO = 23

# Workspace slots (ws): the generalized forces Q = F - h; b, the generalized force of a unit F_x
# at the rear contact (its lever arm included); c, d(u')/dz'; the entries of M that are not constant
# or zero, and the factors of its solve.
W_Q = 0
W_B = 6
W_C = 12
(W_MXT, W_MYT, W_MXP, W_MYP, W_MXS, W_MYS, W_MTT, W_MPP, W_MTP, W_MTS, W_MTB, W_MPB, W_MBB, W_MSS,
 W_D1, W_D2, W_D3, W_L21, W_L31, W_L32, W_KT, W_KP) = range(18, 40)
N_WS = 40


@jit(allocates=True)
def design_constants(p: np.ndarray) -> np.ndarray:
    """Chassis-frame vectors from point 1 (the chassis centre of mass, points 2, 3, 4; the unit
    vector of the fork axis r_4->5, eqs. 1-8, 14-15) and the mass moments of the bodies."""
    g = np.empty(N_GEO)
    g[G_COG_X], g[G_COG_Y] = p[P.CHASSIS_COG_X], p[P.CHASSIS_COG_Y]
    g[G_P2_X], g[G_P2_Y] = p[P.L2] * libm.cos(p[P.A2]), p[P.L2] * libm.sin(p[P.A2])
    g[G_P3_X], g[G_P3_Y] = p[P.L3] * libm.cos(p[P.A3]), p[P.L3] * libm.sin(p[P.A3])
    g[G_P4_X], g[G_P4_Y] = p[P.L4] * libm.cos(p[P.A4]), p[P.L4] * libm.sin(p[P.A4])
    ux = p[P.L5] * libm.cos(p[P.A5]) - g[G_P4_X]
    uy = p[P.L5] * libm.sin(p[P.A5]) - g[G_P4_Y]
    n = libm.hypot(ux, uy)
    ux, uy = ux / n, uy / n
    g[G_AXIS_X], g[G_AXIS_Y] = ux, uy
    m_c, m_sp, m_f, m_fw = p[P.M_CHASSIS], p[P.M_SPROCKET], p[P.M_FORK], p[P.M_FRONT_WHEEL]
    m_fork = m_f + m_fw
    g[G_MASS] = m_c + m_sp + m_fork + p[P.M_SWINGARM] + p[P.M_REAR_WHEEL]
    g[G_MASS_FORK] = m_fork
    g[G_SPIN] = front_wheel_spin_mass(p)
    g[G_MASS_X] = g[G_MASS] + g[G_SPIN]
    # chassis bodies, the fork's at point 4 (their slide along u is added per state)
    p4x, p4y = g[G_P4_X], g[G_P4_Y]
    g[G_S_RIGID_X] = m_c * g[G_COG_X] + m_sp * g[G_P2_X] + m_fork * p4x
    g[G_S_RIGID_Y] = m_c * g[G_COG_Y] + m_sp * g[G_P2_Y] + m_fork * p4y
    g[G_J_RIGID] = (m_c * (g[G_COG_X] ** 2 + g[G_COG_Y] ** 2) + m_sp * (g[G_P2_X] ** 2 + g[G_P2_Y] ** 2)
                    + m_fork * (p4x * p4x + p4y * p4y))
    g[G_P4_DOT_U] = p4x * ux + p4y * uy
    g[G_P4_CROSS_U] = p4x * uy - p4y * ux
    # the fork bodies slide to fs + offset along u: fork at fork_cog_fraction L8, wheel at L8
    off_f, off_w = p[P.FORK_COG_FRACTION] * p[P.L8], p[P.L8]
    g[G_FORK_MOMENT] = m_f * off_f + m_fw * off_w
    g[G_FORK_SECOND] = m_f * off_f * off_f + m_fw * off_w * off_w
    # swingarm bodies along the swingarm line: centre of mass at swingarm_cog_fraction L_SA, wheel at L_SA
    r_sa = p[P.SWINGARM_COG_FRACTION] * p[P.L_SA]
    g[G_S_SWING] = p[P.M_SWINGARM] * r_sa + p[P.M_REAR_WHEEL] * p[P.L_SA]
    g[G_J_SWING] = p[P.M_SWINGARM] * r_sa * r_sa + p[P.M_REAR_WHEEL] * p[P.L_SA] ** 2
    return g


@jit
def inertia(geo: np.ndarray, p: np.ndarray, ct: float, st: float, cp: float, sp: float, fs: float, wt: float,
            wp: float, fs_dot: float, ja_t: float, ja_p: float, alpha_c: float, rho: float,
            ws: np.ndarray) -> tuple[float, float]:
    """Fill M's entries into ws and start Q with gravity minus the velocity products h.

    ct, st, cp, sp: cos and sin of theta and phi; wt, wp, fs_dot: theta', phi', fs'; ja_t, ja_p, rho:
    d(alpha)/d(theta, phi, beta) through the engaged chain run (all 0 for a free engine sprocket, whose
    inertia then leaves M); alpha_c: alpha'' at z'' = 0. Returns the world fork axis (ux, uy).
    """
    g = p[P.GRAVITY]
    m_fork = geo[G_MASS_FORK]
    ux, uy = ct * geo[G_AXIS_X] - st * geo[G_AXIS_Y], st * geo[G_AXIS_X] + ct * geo[G_AXIS_Y]
    # chassis bodies: first moment S_theta (chassis frame, then world) and second moment
    moment = m_fork * fs + geo[G_FORK_MOMENT]             # sum over the fork bodies of m * slide
    sx = geo[G_S_RIGID_X] + moment * geo[G_AXIS_X]
    sy = geo[G_S_RIGID_Y] + moment * geo[G_AXIS_Y]
    stx, sty = ct * sx - st * sy, st * sx + ct * sy
    fork_j = m_fork * fs * fs + 2.0 * fs * geo[G_FORK_MOMENT] + geo[G_FORK_SECOND]  # sum m slide^2
    fork_dot = m_fork * geo[G_P4_DOT_U] + moment          # sum over the fork bodies of m (r_4->o . u)
    # swingarm bodies
    spx, spy = geo[G_S_SWING] * cp, geo[G_S_SWING] * sp
    i_sp = p[P.I_SPROCKET]
    ws[W_MXT], ws[W_MYT] = -sty, stx
    ws[W_MXP], ws[W_MYP] = -spy, spx
    ws[W_MXS], ws[W_MYS] = m_fork * ux, m_fork * uy
    ws[W_MTT] = (geo[G_J_RIGID] + 2.0 * geo[G_P4_DOT_U] * moment + fork_j + p[P.I_CHASSIS] + p[P.I_FORK]
                 + i_sp * ja_t * ja_t)
    ws[W_MPP] = geo[G_J_SWING] + p[P.I_SWINGARM] + i_sp * ja_p * ja_p
    ws[W_MTP] = i_sp * ja_t * ja_p
    ws[W_MTS] = m_fork * geo[G_P4_CROSS_U]
    ws[W_MTB] = i_sp * ja_t * rho
    ws[W_MPB] = i_sp * ja_p * rho
    ws[W_MBB] = p[P.I_REAR_WHEEL] + i_sp * rho * rho
    ws[W_MSS] = m_fork
    # Q = gravity - h
    wt2, wp2 = wt * wt, wp * wp
    cor = 2.0 * fs_dot * wt * m_fork
    ws[W_Q + ZX1] = wt2 * stx + wp2 * spx + cor * uy
    ws[W_Q + ZY1] = wt2 * sty + wp2 * spy - cor * ux - geo[G_MASS] * g
    ws[W_Q + ZTHETA] = -g * stx - 2.0 * fs_dot * wt * fork_dot - i_sp * ja_t * alpha_c
    ws[W_Q + ZPHI] = -g * spx - i_sp * ja_p * alpha_c
    ws[W_Q + ZFS] = -m_fork * g * uy + wt2 * fork_dot
    ws[W_Q + ZBETA] = -i_sp * rho * alpha_c
    k = geo[G_SPIN]
    if k != 0.0:   # the rolling front wheel: k a a^T into M, k a (a' . z') into h (module doc)
        s = fs + p[P.L8]                                  # point 13 along the fork axis from point 4
        wx = ct * geo[G_P4_X] - st * geo[G_P4_Y] + s * ux
        wy = st * geo[G_P4_X] + ct * geo[G_P4_Y] + s * uy
        a_t = -wy
        conv = k * (-wt2 * wx - 2.0 * wt * fs_dot * uy)
        ws[W_MXT] += k * a_t
        ws[W_MXS] += k * ux
        ws[W_MTT] += k * a_t * a_t
        ws[W_MTS] += k * a_t * ux
        ws[W_MSS] += k * ux * ux
        ws[W_Q + ZX1] -= conv
        ws[W_Q + ZTHETA] -= a_t * conv
        ws[W_Q + ZFS] -= ux * conv
    return ux, uy


@jit
def mass_factor(geo: np.ndarray, ws: np.ndarray) -> None:
    """Factor M: x1, y1 and beta eliminated, LDL^T of the remaining 3 x 3 in (theta, phi, fs)."""
    m, mx = geo[G_MASS], geo[G_MASS_X]
    mxt, myt, mxp, myp, mxs, mys = ws[W_MXT], ws[W_MYT], ws[W_MXP], ws[W_MYP], ws[W_MXS], ws[W_MYS]
    kt, kp = ws[W_MTB] / ws[W_MBB], ws[W_MPB] / ws[W_MBB]
    a11 = ws[W_MTT] - (mxt * mxt + myt * myt) / m - kt * ws[W_MTB]
    a21 = ws[W_MTP] - (mxt * mxp + myt * myp) / m - kt * ws[W_MPB]
    a31 = ws[W_MTS] - (mxt * mxs + myt * mys) / m
    a22 = ws[W_MPP] - (mxp * mxp + myp * myp) / m - kp * ws[W_MPB]
    a32 = -(mxp * mxs + myp * mys) / m
    a33 = ws[W_MSS] - (mxs * mxs + mys * mys) / m
    if mx != m:   # x1 eliminated with M_xx = mx (a rolling front wheel), not m: the x terms' share corrected
        d = 1.0 / m - 1.0 / mx
        a11 += mxt * mxt * d
        a21 += mxt * mxp * d
        a31 += mxt * mxs * d
        a22 += mxp * mxp * d
        a32 += mxp * mxs * d
        a33 += mxs * mxs * d
    d1 = a11
    l21, l31 = a21 / d1, a31 / d1
    d2 = a22 - l21 * a21
    l32 = (a32 - l31 * a21) / d2
    d3 = a33 - l31 * a31 - l32 * l32 * d2
    ws[W_D1], ws[W_D2], ws[W_D3] = 1.0 / d1, 1.0 / d2, 1.0 / d3
    ws[W_L21], ws[W_L31], ws[W_L32] = l21, l31, l32
    ws[W_KT], ws[W_KP] = kt, kp


@jit
def mass_solve(geo: np.ndarray, ws: np.ndarray, r: np.ndarray, x: np.ndarray, r0: int = 0, x0: int = 0) -> None:
    """x[x0:x0 + 6] = M^-1 r[r0:r0 + 6] with the factors of mass_factor (distinct 6-vectors; offsets instead
    of slices, which would cost a reference count each in the right-hand side)."""
    m, mx = geo[G_MASS], geo[G_MASS_X]
    mxt, myt, mxp, myp, mxs, mys = ws[W_MXT], ws[W_MYT], ws[W_MXP], ws[W_MYP], ws[W_MXS], ws[W_MYS]
    rx, ry, rb = r[r0 + ZX1] / mx, r[r0 + ZY1] / m, r[r0 + ZBETA] / ws[W_MBB]
    g1 = r[r0 + ZTHETA] - mxt * rx - myt * ry - ws[W_MTB] * rb
    g2 = r[r0 + ZPHI] - mxp * rx - myp * ry - ws[W_MPB] * rb
    g3 = r[r0 + ZFS] - mxs * rx - mys * ry
    l21, l31, l32 = ws[W_L21], ws[W_L31], ws[W_L32]
    g2 -= l21 * g1
    g3 -= l31 * g1 + l32 * g2
    a3 = g3 * ws[W_D3]
    a2 = g2 * ws[W_D2] - l32 * a3
    a1 = g1 * ws[W_D1] - l21 * a2 - l31 * a3
    x[x0 + ZTHETA], x[x0 + ZPHI], x[x0 + ZFS] = a1, a2, a3
    x[x0 + ZX1] = rx - (mxt * a1 + mxp * a2 + mxs * a3) / mx
    x[x0 + ZY1] = ry - (myt * a1 + myp * a2 + mys * a3) / m
    x[x0 + ZBETA] = rb - ws[W_KT] * a1 - ws[W_KP] * a2


@jit
def mass_product(geo: np.ndarray, ws: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out = M x (6-vectors, distinct)."""
    m = geo[G_MASS]
    xt, xp, xs, xb = x[ZTHETA], x[ZPHI], x[ZFS], x[ZBETA]
    out[ZX1] = geo[G_MASS_X] * x[ZX1] + ws[W_MXT] * xt + ws[W_MXP] * xp + ws[W_MXS] * xs
    out[ZY1] = m * x[ZY1] + ws[W_MYT] * xt + ws[W_MYP] * xp + ws[W_MYS] * xs
    out[ZTHETA] = (ws[W_MXT] * x[ZX1] + ws[W_MYT] * x[ZY1] + ws[W_MTT] * xt + ws[W_MTP] * xp + ws[W_MTS] * xs
                   + ws[W_MTB] * xb)
    out[ZPHI] = ws[W_MXP] * x[ZX1] + ws[W_MYP] * x[ZY1] + ws[W_MTP] * xt + ws[W_MPP] * xp + ws[W_MPB] * xb
    out[ZFS] = ws[W_MXS] * x[ZX1] + ws[W_MYS] * x[ZY1] + ws[W_MTS] * xt + ws[W_MSS] * xs
    out[ZBETA] = ws[W_MTB] * xt + ws[W_MPB] * xp + ws[W_MBB] * xb
