"""Phi_q and Phi_q-dot q-dot against finite differences; assembled poses satisfy Phi = 0."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings
from finaldrive.engine.model import params as P
from finaldrive.engine.model.constraints import jacobian, phi, phiq_dot_qdot
from finaldrive.engine.model.coordinates import N_CONSTRAINTS, N_COORDS
from finaldrive.engine.model.kinematics import assemble, chain_length, design_pose
from finaldrive.engine.simulation import pack_parameters

ROADS = ["flat", "sine:0.04:2", "bump:0.04:0.2:0.3"]


def _setup(vehicle, spec, seed):
    rng = np.random.default_rng(seed)
    design = Design(rng.uniform(0, 2 * np.pi), rng.uniform(0, 0.2), rng.uniform(0.05, 0.15))
    p = pack_parameters(vehicle, design, SimSettings())
    q = design_pose(p) + rng.normal(scale=0.05, size=N_COORDS)  # any pose, not only consistent ones
    p[P.L_CHAIN] = 0.9
    road = Road.parse(spec)
    kind, rp = road.packed()
    return p, q, kind, rp, rng


@pytest.mark.parametrize("spec", ROADS)
@pytest.mark.parametrize("seed", range(4))
def test_jacobian_matches_finite_differences_for_every_coordinate(vehicle, spec, seed):
    p, q, kind, rp, _ = _setup(vehicle, spec, seed)
    J = np.empty((N_CONSTRAINTS, N_COORDS))
    jacobian(q, p, kind, rp, J)
    h = 1e-6
    plus, minus = np.empty(N_CONSTRAINTS), np.empty(N_CONSTRAINTS)
    for k in range(N_COORDS):
        dq = np.zeros(N_COORDS)
        dq[k] = h
        phi(q + dq, p, kind, rp, plus)
        phi(q - dq, p, kind, rp, minus)
        np.testing.assert_allclose(J[:, k], (plus - minus) / (2 * h), atol=1e-7, err_msg=f"column {k}")


@pytest.mark.parametrize("spec", ROADS)
@pytest.mark.parametrize("seed", range(4))
def test_phiq_dot_qdot_is_the_time_derivative_of_phiq_along_qdot(vehicle, spec, seed):
    p, q, kind, rp, rng = _setup(vehicle, spec, seed)
    qd = rng.normal(size=N_COORDS)
    out = np.empty(N_CONSTRAINTS)
    phiq_dot_qdot(q, qd, p, kind, rp, out)
    h = 1e-6
    Jp, Jm = np.empty((N_CONSTRAINTS, N_COORDS)), np.empty((N_CONSTRAINTS, N_COORDS))
    jacobian(q + h * qd, p, kind, rp, Jp)
    jacobian(q - h * qd, p, kind, rp, Jm)
    np.testing.assert_allclose(out, (Jp - Jm) @ qd / (2 * h), atol=1e-6)


@pytest.mark.parametrize("spec", ROADS)
def test_assembled_pose_satisfies_all_33_equations(vehicle, spec):
    rng = np.random.default_rng(7)
    road = Road.parse(spec)
    kind, rp = road.packed()
    for _ in range(10):
        design = Design(rng.uniform(0, 2 * np.pi), rng.uniform(0, 0.2), rng.uniform(0.05, 0.15))
        p = pack_parameters(vehicle, design, SimSettings())
        q = assemble(p, road, rng.uniform(-1, 1), 0.4, rng.uniform(-0.1, 0.1), 3.3 + rng.uniform(-0.1, 0.1),
                     0.35, rng.uniform(-5, 5), rng.uniform(-5, 5))
        p[P.L_CHAIN] = chain_length(q, p)
        out = np.empty(N_CONSTRAINTS)
        phi(q, p, kind, rp, out)
        assert np.max(np.abs(out)) < 1e-12
