"""Static equilibrium of the reference model, in its own 39 natural coordinates (section 3.3).

Independent of the fast path: at rest, with no drive torque and no longitudinal tyre force, the
applied forces Q of engine.model.forces (gravity, suspension and tyre springs) do no virtual work
on any motion the constraints (1)-(33) allow. The free motions are those of the fast path's
equilibrium (y1, theta, phi, fs, the rear contact point held at x = 0, which ties x1 to phi); the
admissible velocity of all 39 coordinates for each comes from the constraint Jacobian Phi_q
(engine.model.constraints): Phi_q,dep q'_dep = -Phi_q,ind q'_ind. Solved by Newton's method with
a central-difference matrix, from the same first guess (the design pose pitched onto the road).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.model import libm, params as P
from finaldrive.engine.model.constraints import jacobian
from finaldrive.engine.model.coordinates import BETA, FS, FT, GAMMA, N_CONSTRAINTS, N_COORDS, PHI, RT, THETA, X1, Y1
from finaldrive.engine.model.elements import N_AUX
from finaldrive.engine.model.forces import applied_forces
from finaldrive.engine.model.kinematics import assemble, first_guess
from finaldrive.engine.model.linalg import matmul, rmatvec, solve
from finaldrive.engine.model.mass import gravity_forces
from finaldrive.engine.model.road import Road

#: Newton stops when the update is below this [m, rad].
_XTOL = 1.0e-12
_MAX_NEWTON = 30
#: Step of the central differences of the Newton matrix [m, rad].
_FD_STEP = 1.0e-7
#: The six coordinates whose velocities are chosen; the other 33 follow from Phi_q q' = 0.
_INDEPENDENT = (X1, Y1, THETA, PHI, FS, BETA)
_DEPENDENT = tuple(k for k in range(N_COORDS) if k not in _INDEPENDENT)


class ReferenceEquilibriumError(RuntimeError):
    """No static equilibrium found by the reference model."""


def _pose(free: np.ndarray, p: np.ndarray, road: Road) -> np.ndarray:
    y1, theta, phi, fs = (float(v) for v in free)
    x1 = -p[P.L_SA] * libm.cos(phi)
    q = assemble(p, road, x1, y1, theta, phi, fs, 0.0, 0.0)
    return assemble(p, road, x1, y1, theta, phi, fs, q[GAMMA] + math.pi, q[GAMMA] - math.pi)


def rest_forces(free: np.ndarray, p: np.ndarray, road: Road) -> np.ndarray:
    """Virtual work of Q on the four free motions at rest, over the chassis weight."""
    kind, rp = road.packed()
    q = _pose(free, p, road)
    Q = np.empty(N_COORDS)
    aux = np.zeros(N_AUX)
    rest = p.copy()
    rest[P.TORQUE] = 0.0
    rest[P.DRIVE_MODEL] = 0.0  # no drive at rest, whichever the vehicle's
    applied_forces(q, np.zeros(N_COORDS), 0.0, p[P.SIGMA_K0], rest, gravity_forces(rest), False, Q, aux)
    J = np.empty((N_CONSTRAINTS, N_COORDS))
    jacobian(q, rest, kind, rp, J)
    ind = np.zeros((len(_INDEPENDENT), 4))  # q'_ind per unit rate of each free coordinate
    ind[1, 0] = 1.0                                     # y1
    ind[2, 1] = 1.0                                     # theta
    ind[3, 2] = 1.0                                     # phi ...
    ind[0, 2] = p[P.L_SA] * libm.sin(float(free[2]))    # ... with x1 = -L_SA cos(phi)
    ind[4, 3] = 1.0                                     # fs
    # Phi_q,dep q'_dep = -Phi_q,ind q'_ind, by engine.model.linalg (the same bits on every CPU)
    V = np.zeros((N_COORDS, 4))
    V[list(_INDEPENDENT)] = ind
    moved = np.empty((len(_DEPENDENT), 4))
    matmul(J[:, list(_INDEPENDENT)], ind, moved)
    dep = np.empty(len(_DEPENDENT))
    for k in range(4):
        solve(J[:, list(_DEPENDENT)], -moved[:, k], dep)
        V[list(_DEPENDENT), k] = dep
    work = np.empty(4)
    rmatvec(V, Q, work)
    return np.asarray(work / (p[P.M_CHASSIS] * p[P.GRAVITY]))


def reference_equilibrium(p: np.ndarray, road: Road, pose: np.ndarray | None = None) -> np.ndarray:
    """The equilibrium pose q (sprocket reference points opposite the tangent points); pose: the
    design pose (kinematics.design_pose) if known."""
    free = first_guess(p, road, pose)
    for _ in range(_MAX_NEWTON):
        g = rest_forces(free, p, road)
        K = np.empty((4, 4))
        for k in range(4):
            e = np.zeros(4)
            e[k] = _FD_STEP
            K[:, k] = (rest_forces(free + e, p, road) - rest_forces(free - e, p, road)) / (2.0 * _FD_STEP)
        step = np.empty(4)
        try:
            solve(K, g, step)
        except np.linalg.LinAlgError:
            raise ReferenceEquilibriumError("static equilibrium not found: singular stiffness") from None
        free = free - step
        if not np.all(np.isfinite(free)):
            break
        if np.max(np.abs(step)) < _XTOL:
            q = _pose(free, p, road)
            if q[RT] >= p[P.RT0] or q[FT] >= p[P.FT0]:
                raise ReferenceEquilibriumError("static equilibrium has a wheel off the road")
            return q
    raise ReferenceEquilibriumError("static equilibrium not found: Newton did not converge")


__all__ = ["ReferenceEquilibriumError", "reference_equilibrium", "rest_forces"]
