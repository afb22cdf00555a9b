"""Static equilibrium at rest on the road (section 3.3, step 2).

The paper relaxes the dynamics with a trapezoidal solver; the equilibrium itself is a property
of the model, so it is solved here directly: with the bike at rest, no drive torque and no
longitudinal tyre force, the generalized forces projected on the free coordinates
z = (y1, theta, phi, fs) vanish, J(z)^T Q(q(z)) = 0 with J = dq/dz. The rear contact point is
held at x = 0 (READING-NOTES: x = 0 at the rear tyre's initial contact point).
"""

from __future__ import annotations

import math

import numpy as np
from engine.model import params as P
from engine.model.coordinates import FS, FT, GAMMA, PHI, RS, RT, THETA, X1, X14, X15, Y1
from engine.model.forces import radial_tyre_force
from engine.model.kinematics import assemble, design_pose
from engine.model.road import Road

#: Step of the central differences for J = dq/dz and for the Newton matrix.
_FD_STEP = 1.0e-6
#: The first guess presses both tyres this far into the road [m] so both springs act.
_GUESS_PRELOAD = 0.005
#: Newton stops when the update is below this [m, rad].
_XTOL = 1.0e-10
_MAX_NEWTON = 30


class EquilibriumError(RuntimeError):
    """No static equilibrium found (the bike cannot stand on this road)."""


def _pose(z: np.ndarray, p: np.ndarray, road: Road) -> np.ndarray:
    y1, theta, phi, fs = z
    x1 = -p[P.L_SA] * math.cos(phi)   # rear axle, hence the rear contact point, at x = 0
    return assemble(p, road, x1, y1, theta, phi, fs, 0.0, 0.0)


def static_forces(q: np.ndarray, p: np.ndarray, qg: np.ndarray) -> np.ndarray:
    """Generalized forces at rest: gravity, springs (34)-(35), tyre springs (36)-(37)."""
    Q = qg.copy()
    Q[RS] += -p[P.K_RS] * (q[RS] - p[P.S_RS])
    Q[FS] += -p[P.K_FS] * (q[FS] - p[P.S_FS])
    Q[RT] += radial_tyre_force(q[RT], 0.0, p[P.RT0], p[P.K_RT], 0.0)
    Q[FT] += radial_tyre_force(q[FT], 0.0, p[P.FT0], p[P.K_FT], 0.0)
    return Q


def _first_guess(p: np.ndarray, road: Road) -> np.ndarray:
    """The design pose pitched onto the road about the rear contact point, tyres preloaded."""
    q0 = design_pose(p)
    wheelbase = q0[X15] - q0[X14]
    h_rear, h_front = float(road.height_at(0.0)), float(road.height_at(wheelbase))
    pitch = math.atan2(h_front - h_rear, wheelbase)
    y1 = q0[X1] * math.sin(pitch) + q0[Y1] * math.cos(pitch) + h_rear - _GUESS_PRELOAD
    return np.array([y1, q0[THETA] + pitch, q0[PHI] + pitch, q0[FS]])


def static_equilibrium(p: np.ndarray, road: Road, qg: np.ndarray) -> np.ndarray:
    """The equilibrium pose q (sprocket reference points opposite the tangent points)."""

    def residual(z: np.ndarray) -> np.ndarray:
        q = _pose(z, p, road)
        Q = static_forces(q, p, qg)
        g = np.empty(4)
        for k in range(4):
            dz = np.zeros(4)
            dz[k] = _FD_STEP
            dq = (_pose(z + dz, p, road) - _pose(z - dz, p, road)) / (2.0 * _FD_STEP)
            dq[GAMMA] = 0.0  # gamma, alpha, beta carry no static force
            g[k] = dq @ Q
        return g / (p[P.M_CHASSIS] * p[P.GRAVITY])

    z = _first_guess(p, road)
    for _ in range(_MAX_NEWTON):
        g = residual(z)
        K = np.empty((4, 4))
        for k in range(4):
            dz = np.zeros(4)
            dz[k] = 0.1 * _FD_STEP
            K[:, k] = (residual(z + dz) - residual(z - dz)) / (0.2 * _FD_STEP)
        try:
            step = np.linalg.solve(K, g)
        except np.linalg.LinAlgError:
            raise EquilibriumError("static equilibrium not found: singular stiffness") from None
        z = z - step
        if not np.all(np.isfinite(z)):
            break
        if np.max(np.abs(step)) < _XTOL:
            break
    else:
        raise EquilibriumError("static equilibrium not found: Newton did not converge")
    if not np.all(np.isfinite(z)):
        raise EquilibriumError("static equilibrium not found: diverged")
    q = _pose(z, p, road)
    if q[RT] >= p[P.RT0] or q[FT] >= p[P.FT0]:
        raise EquilibriumError("static equilibrium has a wheel off the road")
    y1, theta, phi, fs = z
    return assemble(p, road, q[0], y1, theta, phi, fs, q[GAMMA] + math.pi, q[GAMMA] - math.pi)
