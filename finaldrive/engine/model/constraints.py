"""Kinematic constraints Phi(q) = 0, eqs. (1)-(33), their Jacobian Phi_q and Phi_q-dot q-dot.

Row r holds the paper's equation r + 1. Compiled; callers pass preallocated outputs.
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.coordinates import (
    ALPHA,
    BETA,
    FS,
    FT,
    GAMMA,
    PHI,
    RS,
    RT,
    THETA,
    X1,
    X2,
    X3,
    X4,
    X5,
    X6,
    X7,
    X8,
    X9,
    X10,
    X11,
    X12,
    X13,
    X14,
    X15,
    Y1,
    Y2,
    Y3,
    Y4,
    Y5,
    Y6,
    Y7,
    Y8,
    Y9,
    Y10,
    Y11,
    Y12,
    Y13,
    Y14,
    Y15,
)
from finaldrive.engine.model.road_height import road_height


@jit
def _rotating_point(q, p, r, base_x, base_y, pt_x, pt_y, ang, length, offset, out):
    """Rows r, r+1: base + length * e(q[ang] + offset) - point = 0."""
    a = q[ang] + offset
    out[r] = q[base_x] + length * libm.cos(a) - q[pt_x]
    out[r + 1] = q[base_y] + length * libm.sin(a) - q[pt_y]


@jit
def phi(q: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray, out: np.ndarray) -> None:
    """Constraint residuals Phi(q), eqs. (1)-(33)."""
    _rotating_point(q, p, 0, X1, Y1, X2, Y2, THETA, p[P.L2], p[P.A2], out)            # (1)-(2)
    _rotating_point(q, p, 2, X1, Y1, X3, Y3, THETA, p[P.L3], p[P.A3], out)            # (3)-(4)
    _rotating_point(q, p, 4, X1, Y1, X4, Y4, THETA, p[P.L4], p[P.A4], out)            # (5)-(6)
    _rotating_point(q, p, 6, X1, Y1, X5, Y5, THETA, p[P.L5], p[P.A5], out)            # (7)-(8)
    _rotating_point(q, p, 8, X1, Y1, X6, Y6, PHI, p[P.L_SA], 0.0, out)                # (9)-(10)
    _rotating_point(q, p, 10, X1, Y1, X7, Y7, PHI, p[P.L7], 0.0, out)                 # (11)-(12)
    out[12] = (q[X3] - q[X7]) ** 2 + (q[Y3] - q[Y7]) ** 2 - q[RS] ** 2                # (13)
    ax, ay = q[X5] - q[X4], q[Y5] - q[Y4]
    out[13] = ax * (q[Y13] - q[Y12]) - ay * (q[X13] - q[X12])                         # (14)
    out[14] = ax * (q[Y13] - q[Y4]) - ay * (q[X13] - q[X4])                           # (15)
    out[15] = (q[X13] - q[X12]) ** 2 + (q[Y13] - q[Y12]) ** 2 - p[P.L8] ** 2           # (16)
    out[16] = (q[X4] - q[X12]) ** 2 + (q[Y4] - q[Y12]) ** 2 - q[FS] ** 2              # (17)
    out[17] = q[X6] - q[X14]                                                          # (18)
    out[18] = q[X13] - q[X15]                                                         # (19)
    out[19] = q[Y6] - q[Y14] - q[RT]                                                  # (20)
    out[20] = q[Y13] - q[Y15] - q[FT]                                                 # (21)
    _rotating_point(q, p, 21, X2, Y2, X8, Y8, ALPHA, p[P.R_ES], 0.0, out)             # (22)-(23)
    _rotating_point(q, p, 23, X2, Y2, X10, Y10, GAMMA, p[P.R_ES], 0.0, out)           # (24)-(25)
    _rotating_point(q, p, 25, X6, Y6, X9, Y9, BETA, p[P.R_WS], 0.0, out)              # (26)-(27)
    _rotating_point(q, p, 27, X6, Y6, X11, Y11, GAMMA, p[P.R_WS], 0.0, out)           # (28)-(29)
    ex, ey = q[X10] - q[X11], q[Y10] - q[Y11]
    out[29] = ((q[GAMMA] - q[ALPHA]) * p[P.R_ES] + math.sqrt(ex * ex + ey * ey)
               + (q[BETA] - q[GAMMA]) * p[P.R_WS] - p[P.L_CHAIN])                    # (30)
    out[30] = ((q[X6] - q[X11]) * (q[X11] - q[X10])
               + (q[Y6] - q[Y11]) * (q[Y11] - q[Y10]))                                # (31)
    out[31] = q[Y14] - road_height(kind, rp, q[X14])[0]                               # (32)
    out[32] = q[Y15] - road_height(kind, rp, q[X15])[0]                               # (33)


@jit
def _rotating_point_jac(q, r, base_x, base_y, pt_x, pt_y, ang, length, offset, J):
    a = q[ang] + offset
    J[r, base_x] = 1.0
    J[r, pt_x] = -1.0
    J[r, ang] = -length * libm.sin(a)
    J[r + 1, base_y] = 1.0
    J[r + 1, pt_y] = -1.0
    J[r + 1, ang] = length * libm.cos(a)


@jit
def _distance_sq_jac(q, r, ix, iy, jx, jy, J):
    """d/dq of (x_i - x_j)^2 + (y_i - y_j)^2 (accumulates)."""
    dx, dy = q[ix] - q[jx], q[iy] - q[jy]
    J[r, ix] += 2.0 * dx
    J[r, jx] -= 2.0 * dx
    J[r, iy] += 2.0 * dy
    J[r, jy] -= 2.0 * dy


@jit(allocates=True, one_form=True)
def jacobian(q: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray, J: np.ndarray) -> None:
    """Phi_q, the 33 x 39 Jacobian of eqs. (1)-(33). J is overwritten."""
    J[:, :] = 0.0
    _rotating_point_jac(q, 0, X1, Y1, X2, Y2, THETA, p[P.L2], p[P.A2], J)             # (1)-(2)
    _rotating_point_jac(q, 2, X1, Y1, X3, Y3, THETA, p[P.L3], p[P.A3], J)             # (3)-(4)
    _rotating_point_jac(q, 4, X1, Y1, X4, Y4, THETA, p[P.L4], p[P.A4], J)             # (5)-(6)
    _rotating_point_jac(q, 6, X1, Y1, X5, Y5, THETA, p[P.L5], p[P.A5], J)             # (7)-(8)
    _rotating_point_jac(q, 8, X1, Y1, X6, Y6, PHI, p[P.L_SA], 0.0, J)                 # (9)-(10)
    _rotating_point_jac(q, 10, X1, Y1, X7, Y7, PHI, p[P.L7], 0.0, J)                  # (11)-(12)
    _distance_sq_jac(q, 12, X3, Y3, X7, Y7, J)                                        # (13)
    J[12, RS] = -2.0 * q[RS]
    ax, ay = q[X5] - q[X4], q[Y5] - q[Y4]
    bx, by = q[X13] - q[X12], q[Y13] - q[Y12]                                         # (14)
    J[13, X5] = by
    J[13, X4] = -by
    J[13, Y5] = -bx
    J[13, Y4] = bx
    J[13, Y13] = ax
    J[13, Y12] = -ax
    J[13, X13] = -ay
    J[13, X12] = ay
    cx, cy = q[X13] - q[X4], q[Y13] - q[Y4]                                           # (15)
    J[14, X5] = cy
    J[14, Y5] = -cx
    J[14, X13] = -ay
    J[14, Y13] = ax
    J[14, X4] = -cy + ay
    J[14, Y4] = cx - ax
    _distance_sq_jac(q, 15, X13, Y13, X12, Y12, J)                                    # (16)
    _distance_sq_jac(q, 16, X4, Y4, X12, Y12, J)                                      # (17)
    J[16, FS] = -2.0 * q[FS]
    J[17, X6] = 1.0                                                                   # (18)
    J[17, X14] = -1.0
    J[18, X13] = 1.0                                                                  # (19)
    J[18, X15] = -1.0
    J[19, Y6] = 1.0                                                                   # (20)
    J[19, Y14] = -1.0
    J[19, RT] = -1.0
    J[20, Y13] = 1.0                                                                  # (21)
    J[20, Y15] = -1.0
    J[20, FT] = -1.0
    _rotating_point_jac(q, 21, X2, Y2, X8, Y8, ALPHA, p[P.R_ES], 0.0, J)              # (22)-(23)
    _rotating_point_jac(q, 23, X2, Y2, X10, Y10, GAMMA, p[P.R_ES], 0.0, J)            # (24)-(25)
    _rotating_point_jac(q, 25, X6, Y6, X9, Y9, BETA, p[P.R_WS], 0.0, J)               # (26)-(27)
    _rotating_point_jac(q, 27, X6, Y6, X11, Y11, GAMMA, p[P.R_WS], 0.0, J)            # (28)-(29)
    ex, ey = q[X10] - q[X11], q[Y10] - q[Y11]                                         # (30)
    d = math.sqrt(ex * ex + ey * ey)
    J[29, GAMMA] = p[P.R_ES] - p[P.R_WS]
    J[29, ALPHA] = -p[P.R_ES]
    J[29, BETA] = p[P.R_WS]
    J[29, X10] = ex / d
    J[29, X11] = -ex / d
    J[29, Y10] = ey / d
    J[29, Y11] = -ey / d
    ux, uy = q[X6] - q[X11], q[Y6] - q[Y11]                                           # (31)
    vx, vy = q[X11] - q[X10], q[Y11] - q[Y10]
    J[30, X6] = vx
    J[30, Y6] = vy
    J[30, X11] = ux - vx
    J[30, Y11] = uy - vy
    J[30, X10] = -ux
    J[30, Y10] = -uy
    J[31, Y14] = 1.0                                                                  # (32)
    J[31, X14] = -road_height(kind, rp, q[X14])[1]
    J[32, Y15] = 1.0                                                                  # (33)
    J[32, X15] = -road_height(kind, rp, q[X15])[1]


@jit(allocates=True)
def phiq_dot_qdot(q: np.ndarray, qd: np.ndarray, p: np.ndarray, kind: int, rp: np.ndarray,
                  out: np.ndarray) -> None:
    """(d/dt Phi_q) q-dot: the part of Phi-double-dot that does not depend on q-double-dot."""
    out[:] = 0.0
    th = q[THETA]
    w2 = qd[THETA] * qd[THETA]
    for r, length, offset in ((0, p[P.L2], p[P.A2]), (2, p[P.L3], p[P.A3]),
                              (4, p[P.L4], p[P.A4]), (6, p[P.L5], p[P.A5])):    # (1)-(8)
        out[r] = -length * libm.cos(th + offset) * w2
        out[r + 1] = -length * libm.sin(th + offset) * w2
    w2 = qd[PHI] * qd[PHI]
    for r, length in ((8, p[P.L_SA]), (10, p[P.L7])):                             # (9)-(12)
        out[r] = -length * libm.cos(q[PHI]) * w2
        out[r + 1] = -length * libm.sin(q[PHI]) * w2
    out[12] = 2.0 * ((qd[X3] - qd[X7]) ** 2 + (qd[Y3] - qd[Y7]) ** 2 - qd[RS] ** 2)  # (13)
    adx, ady = qd[X5] - qd[X4], qd[Y5] - qd[Y4]
    out[13] = 2.0 * (adx * (qd[Y13] - qd[Y12]) - ady * (qd[X13] - qd[X12]))          # (14)
    out[14] = 2.0 * (adx * (qd[Y13] - qd[Y4]) - ady * (qd[X13] - qd[X4]))            # (15)
    out[15] = 2.0 * ((qd[X13] - qd[X12]) ** 2 + (qd[Y13] - qd[Y12]) ** 2)            # (16)
    out[16] = 2.0 * ((qd[X4] - qd[X12]) ** 2 + (qd[Y4] - qd[Y12]) ** 2 - qd[FS] ** 2)  # (17)
    for r, ang, length in ((21, ALPHA, p[P.R_ES]), (23, GAMMA, p[P.R_ES]),
                           (25, BETA, p[P.R_WS]), (27, GAMMA, p[P.R_WS])):        # (22)-(29)
        w2 = qd[ang] * qd[ang]
        out[r] = -length * libm.cos(q[ang]) * w2
        out[r + 1] = -length * libm.sin(q[ang]) * w2
    ex, ey = q[X10] - q[X11], q[Y10] - q[Y11]                                         # (30)
    edx, edy = qd[X10] - qd[X11], qd[Y10] - qd[Y11]
    d = math.sqrt(ex * ex + ey * ey)
    dd = ex * edx + ey * edy
    out[29] = (edx * edx + edy * edy) / d - dd * dd / (d * d * d)
    udx, udy = qd[X6] - qd[X11], qd[Y6] - qd[Y11]                                     # (31)
    vdx, vdy = qd[X11] - qd[X10], qd[Y11] - qd[Y10]
    out[30] = 2.0 * (udx * vdx + udy * vdy)
    out[31] = -road_height(kind, rp, q[X14])[2] * qd[X14] ** 2                        # (32)
    out[32] = -road_height(kind, rp, q[X15])[2] * qd[X15] ** 2                        # (33)
