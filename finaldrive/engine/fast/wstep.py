"""One trial step of ROS34PW2, a Rosenbrock-W method of J. Rang and L. Angermann (New Rosenbrock
W-methods of order 3 for partial differential algebraic equations of index 1, BIT Numer. Math. 45
(2005) 761-787; gamma, a_ij, g_ij, b_i and b^_i below are their coefficient table of ROS34PW2):
4 stages, order 3 for any matrix W = I - gamma h J, L-stable, stiffly accurate, with an embedded
solution of order 2:

    W k_i = f(y_n + h sum_j a_ij k_j) + h J sum_j g_ij k_j,   y_n+1 = y_n + h sum_i b_i k_i,

error estimate h sum_i (b_i - b^_i) k_i. J holds only the tyre state's stiff terms (section 3.2):
d(u')/du = -|V_x| / sigma*, d(u')/dz' (through V_sx, eqs. 40, 42) and dz''/du = M^-1 b dF_x/du;
W is then solved in closed form (w_solve, which ROS2 in engine.fast.rosenbrock shares).

sigma* of eq. (41) is held through the step (engine.model.tyre). Holding it is an error of its own,
which the embedded solution cannot see: with sigma* moving by d_sigma over the step, kappa' = u / sigma*
is off as if u were off by -u d_sigma / sigma*, so the local error gains (h / 2) J[:, u] (-u d_sigma / sigma*)
(d_sigma from the last stage, at y_n + h k_3). The step-size control then resolves sigma*'s changes
(the slip transients after a landing) the way it resolves the state's.

The embedded estimate assumes a smooth right-hand side: a kink of the road's slope inside a step
(piecewise-linear profiles) is invisible to it, so engine.fast.rosenbrock uses this step on smooth
roads, with the paper's chain or the elastic one (not the two-run chain's events).
"""

from __future__ import annotations

import numpy as np

from finaldrive.engine.fast.bodies import N_DOF
from finaldrive.engine.fast.minimal import ZU, fast_rhs
from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model.elements import AUX_FX, AUX_FZ_REAR, AUX_KAPPA
from finaldrive.engine.model.tyre import relaxation_length

N_STAGES = 4
#: Rang & Angermann 2005, the coefficient table of ROS34PW2.
GAMMA = 0.4358665215084590
#: a_ij: stage arguments; g_ij: the stages' coupling through J (row i, columns j < i).
A = np.array([[0.0, 0.0, 0.0, 0.0],
              [0.8717330430169180, 0.0, 0.0, 0.0],
              [0.8445706001536942, -0.1129906423648418, 0.0, 0.0],
              [0.0, 0.0, 1.0, 0.0]])
G = np.array([[0.0, 0.0, 0.0, 0.0],
              [-0.8717330430169180, 0.0, 0.0, 0.0],
              [-0.9033805701304408, 0.0541806723880953, 0.0, 0.0],
              [0.2421238070609535, -1.2232505839045147, 0.5452602553351021, 0.0]])
B = np.array([0.2421238070609535, -1.2232505839045147, 1.5452602553351020, 0.4358665215084590])
#: b_i - b^_i, b^ the embedded second-order solution's weights.
E = B - np.array([0.3781090314581937, -0.0960422922124232, 0.5, 0.2179332607542295])
#: Order of the error estimate's leading term (the step-size control's exponent 1/3).
ERROR_ORDER = 3


@jit
def w_solve(r, gh, v, c_row, a_uu, k):
    """k = W^-1 r for W = I - gh J with J's nonzero blocks dz''/du = v, du'/dz' = c_row,
    du'/du = a_uu (rows of z and of the two-run chain's e, alpha': identity)."""
    cr = 0.0
    cv = 0.0
    for i in range(N_DOF):
        k[i] = r[i]
        cr += c_row[i] * r[N_DOF + i]
        cv += c_row[i] * v[i]
    for i in range(ZU + 1, r.shape[0]):
        k[i] = r[i]
    ku = (r[ZU] + gh * cr) / (1.0 - gh * a_uu - gh * gh * cv)
    for i in range(N_DOF):
        k[N_DOF + i] = r[N_DOF + i] + gh * v[i] * ku
    k[ZU] = ku


@jit
def attempt(y, f0, h, sigma, v, c_row, a_uu, p, geo, kind, rp, longitudinal, K, ys, fs, aux, ws, ynew, err, run):
    """One trial step of size h from y = (z, z', u), or with the elastic chain (z, z', u, e, alpha')
    (f0 = f(y) at sigma*, in the chain's mode run: the paper's upper run or ELASTIC); fills ynew and
    the local error estimate err (sigma*'s lag included); returns a failure code of fast_rhs (0 = ok).
    K (N_STAGES x the state's size), ys, fs, aux, ws: scratch."""
    n = y.shape[0]
    gh = GAMMA * h
    w_solve(f0, gh, v, c_row, a_uu, K[0])
    for s in range(1, N_STAGES):
        for i in range(n):
            acc = y[i]
            for j in range(s):
                acc += h * A[s, j] * K[j, i]
            ys[i] = acc
        code = fast_rhs(ys, p, geo, kind, rp, sigma, longitudinal, fs, aux, ws, run)
        if code != 0:
            return code
        # + h J sum_j g_sj k_j: J reads only z' and u, and acts on z'' and u
        ju = 0.0
        jdu = 0.0
        for j in range(s):
            ju += G[s, j] * K[j, ZU]
        for i in range(N_DOF):
            gz = 0.0
            for j in range(s):
                gz += G[s, j] * K[j, N_DOF + i]
            jdu += c_row[i] * gz
        for i in range(N_DOF):
            fs[N_DOF + i] += h * v[i] * ju
        fs[ZU] += h * (jdu + a_uu * ju)
        w_solve(fs, gh, v, c_row, a_uu, K[s])
    for i in range(n):
        sol = 0.0
        est = 0.0
        for s in range(N_STAGES):
            sol += B[s] * K[s, i]
            est += E[s] * K[s, i]
        ynew[i] = y[i] + h * sol
        err[i] = h * est
    # sigma*'s lag over the step, from the last stage's tyre outputs
    d_sigma = relaxation_length(aux[AUX_FX], aux[AUX_KAPPA], aux[AUX_FZ_REAR], p) - sigma
    du = -0.5 * h * y[ZU] * d_sigma / sigma
    for i in range(N_DOF):
        err[N_DOF + i] += v[i] * du
    err[ZU] += a_uu * du
    return 0
