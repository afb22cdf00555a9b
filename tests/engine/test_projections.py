"""The two solvers project one model: the fast path's equations of motion in minimal coordinates
are the reference's natural-coordinate equations (mass matrix, gravity, every force element,
constraints 1-33) projected onto z.

With q(z) the position analysis (engine.model.kinematics.pose_from_minimal, eqs. 1-33) and
J = dq/dz (central differences), the reference's M q'' + Phi_q^T lambda = Q restricted to the
motions the constraints allow gives (J^T M J) z'' = J^T Q(q, J z', u) - J^T M (J' z'), where
J' z' = d^2 q/dt^2 along z(t) = z + z' t. The fast path's z'' (engine.fast.minimal.fast_rhs) must
be that solution, at random states with every force on, on flat and rough roads, with both
lever arms: bodies and force elements are then described once, whatever each solver does with them.
"""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings
from finaldrive.engine.fast import bodies, minimal
from finaldrive.engine.model.coordinates import N_COORDS
from finaldrive.engine.model.elements import AUX_ALPHA_DOT, AUX_FZ_FRONT, AUX_FZ_REAR, AUX_TENSION, N_AUX
from finaldrive.engine.model.forces import applied_forces
from finaldrive.engine.model.kinematics import pose_from_minimal
from finaldrive.engine.model.mass import gravity_forces, mass_matrix
from finaldrive.engine.simulation import MINIMAL_COORDS, prepare

DESIGNS = [Design.from_deg(195.3, 0.037, 0.088), Design.from_deg(270, 0.15, 0.05), Design.from_deg(45, 0.2, 0.15)]
SIGMA = 0.07


def _projected_accelerations(z, zd, u, p, road):
    """z'' from the reference's model projected onto z."""
    h = 1e-6
    J = np.empty((N_COORDS, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        J[:, k] = (pose_from_minimal(z + e, p, road) - pose_from_minimal(z - e, p, road)) / (2 * h)
    h2 = 1e-4
    q0 = pose_from_minimal(z, p, road)
    jdot_zd = (pose_from_minimal(z + h2 * zd, p, road) - 2 * q0 + pose_from_minimal(z - h2 * zd, p, road)) / h2**2
    M = mass_matrix(p)
    Q = np.empty(N_COORDS)
    aux = np.zeros(N_AUX)
    applied_forces(q0, J @ zd, u, SIGMA, p, gravity_forces(p), True, Q, aux)
    lhs = J.T @ M @ J
    return np.linalg.solve(lhs, J.T @ Q - J.T @ M @ jdot_zd), aux


@pytest.mark.parametrize("design", DESIGNS, ids=lambda d: f"{d.a2_deg:.0f}-{d.l2}-{d.rws}")
@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2", "bump:0.04:0.2:0.2"])
@pytest.mark.parametrize("lever", [0.0, 1.0])
def test_fast_equations_are_the_reference_model_projected(vehicle, design, spec, lever):
    road = Road.parse(spec)
    setup = prepare(design, road, SimSettings(), vehicle.replace(fx_lever_loaded=lever))
    p = setup.p
    kind, rp = road.packed()
    geo = bodies.design_constants(p)
    rng = np.random.default_rng([round(design.a2_deg), len(spec), int(lever)])
    for _ in range(3):
        y = np.zeros(minimal.N_STATE)
        y[:6] = setup.q0[list(MINIMAL_COORDS)] + rng.normal(scale=[0.02, 0.002, 0.003, 0.005, 0.005, 1.0])
        y[1] -= 0.01                                     # both tyres on the road, the rear near the bump stop
        y[6:12] = rng.normal(scale=[1.0, 0.2, 0.3, 0.5, 0.2, 5.0])
        y[6] += 6.0
        y[11] -= 6.0 / 0.29                              # driving: the wheel turns forward (beta' < 0)
        y[12] = rng.normal(scale=0.01)
        out, aux = np.zeros(minimal.N_STATE), np.zeros(N_AUX)
        assert minimal.fast_rhs(y, p, geo, kind, rp, SIGMA, True, out, aux, np.zeros(bodies.N_WS)) == 0
        expected, aux_ref = _projected_accelerations(y[:6], y[6:12], y[12], p, road)
        assert aux[AUX_FZ_REAR] > 0 and aux[AUX_FZ_FRONT] > 0
        elements = [*range(AUX_TENSION), AUX_ALPHA_DOT]                     # what the elements write
        np.testing.assert_allclose(aux[elements], aux_ref[elements], rtol=1e-6, atol=1e-4)  # same state, same outputs
        # FD error of J (~1e-12 relative) and J' z' (~1e-8 m/s^2 scale): 1e-5 relative on z''
        np.testing.assert_allclose(out[6:12], expected, rtol=1e-5, atol=1e-5 * np.max(np.abs(expected)))
