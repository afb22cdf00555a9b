"""Static equilibrium at rest on the road (section 3.3, step 2).

The paper relaxes the dynamics with a trapezoidal solver; the equilibrium itself is a property
of the model, so it is solved here directly: at rest, with no drive torque and no longitudinal
tyre force, the generalized forces on the free coordinates vanish. The free coordinates are
y1, theta, phi and fs; the rear contact point stays at x = 0 (x = 0 at the rear tyre's initial
contact point: docs/engine.md#reading-notes-reference-choices), which ties x1 to phi:
x1 = -L_SA cos(phi). The forces come from the compiled minimal-coordinate model
(engine.fast.minimal), by Newton's method. This is the fast path's start; the reference method
solves its own model's equilibrium (engine.solver.equilibrium).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.fast.bodies import N_WS, W_Q, ZFS, ZPHI, ZTHETA, ZX1, ZY1, design_constants
from finaldrive.engine.fast.minimal import N_STATE, fast_rhs
from finaldrive.engine.jit.kernel import jit
from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.coordinates import FT, GAMMA, RT
from finaldrive.engine.model.elements import N_AUX
from finaldrive.engine.model.kinematics import assemble, first_guess
from finaldrive.engine.model.linalg import solve
from finaldrive.engine.model.road import Road

#: Newton stops when the update is below this [m, rad].
_XTOL = 1.0e-12
_MAX_NEWTON = 30
#: Step of the central differences of the Newton matrix [m, rad].
_FD_STEP = 1.0e-7


class EquilibriumError(RuntimeError):
    """No static equilibrium found (the bike cannot stand on this road)."""


@jit(allocates=True)
def _rest_forces(free, p0, geo, kind, rp, out):
    """Generalized forces at rest on (y1, theta, phi + x1 with it, fs), over the chassis weight."""
    y = np.zeros(N_STATE)
    y[ZY1], y[ZTHETA], y[ZPHI], y[ZFS] = free[0], free[1], free[2], free[3]
    y[ZX1] = -p0[P.L_SA] * libm.cos(free[2])
    ydot = np.zeros(N_STATE)
    aux = np.zeros(N_AUX)
    ws = np.zeros(N_WS)
    fast_rhs(y, p0, geo, kind, rp, p0[P.SIGMA_K0], False, ydot, aux, ws)
    F = ws[W_Q:]  # the generalized forces (no velocity products at rest)
    w = p0[P.M_CHASSIS] * p0[P.GRAVITY]
    out[0] = F[ZY1] / w
    out[1] = F[ZTHETA] / w
    out[2] = (F[ZPHI] + p0[P.L_SA] * libm.sin(free[2]) * F[ZX1]) / w
    out[3] = F[ZFS] / w


@jit(allocates=True)
def _newton(free, p0, kind, rp, xtol, max_iter, fd):
    """Newton's method on _rest_forces = 0; returns (free, converged)."""
    geo = design_constants(p0)
    g = np.empty(4)
    gp = np.empty(4)
    gm = np.empty(4)
    K = np.empty((4, 4))
    step = np.empty(4)
    for _ in range(max_iter):
        _rest_forces(free, p0, geo, kind, rp, g)
        for k in range(4):
            free[k] += fd
            _rest_forces(free, p0, geo, kind, rp, gp)
            free[k] -= 2.0 * fd
            _rest_forces(free, p0, geo, kind, rp, gm)
            free[k] += fd
            for i in range(4):   # loops, not array expressions: no compiled shape checks
                K[i, k] = (gp[i] - gm[i]) / (2.0 * fd)
        solve(K, g, step)
        for i in range(4):
            free[i] -= step[i]
        if not np.all(np.isfinite(free)):
            return free, False
        if np.max(np.abs(step)) < xtol:
            return free, True
    return free, False


def static_equilibrium(p: np.ndarray, road: Road, pose: np.ndarray | None = None) -> np.ndarray:
    """The equilibrium pose q (sprocket reference points opposite the tangent points); pose: the
    design pose (kinematics.design_pose) if known."""
    p0 = p.copy()
    p0[P.TORQUE] = 0.0
    p0[P.DRIVE_MODEL] = 0.0  # no drive at rest, whichever the vehicle's
    kind, rp = road.packed()
    try:
        free, ok = _newton(first_guess(p, road, pose), p0, kind, rp, _XTOL, _MAX_NEWTON, _FD_STEP)
    except np.linalg.LinAlgError:
        raise EquilibriumError("static equilibrium not found: singular stiffness") from None
    if not ok:
        raise EquilibriumError("static equilibrium not found: Newton did not converge")
    y1, theta, phi, fs = (float(v) for v in free)
    x1 = -p[P.L_SA] * libm.cos(phi)
    q = assemble(p, road, x1, y1, theta, phi, fs, 0.0, 0.0)
    if q[RT] >= p[P.RT0] or q[FT] >= p[P.FT0]:
        raise EquilibriumError("static equilibrium has a wheel off the road")
    return assemble(p, road, x1, y1, theta, phi, fs, q[GAMMA] + math.pi, q[GAMMA] - math.pi)
