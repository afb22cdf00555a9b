"""The constant mass matrix reproduces each body's kinetic energy; gravity adds to the weight."""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine import Design, SimSettings
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import N_COORDS
from finaldrive.engine.model.mass import bodies, gravity_forces, mass_matrix
from finaldrive.engine.simulation import pack_parameters

ROT = np.array([[0.0, -1.0], [1.0, 0.0]])


def test_rigid_motion_energy_equals_translation_plus_rotation(vehicle):
    """For each body moved rigidly: 1/2 q'^T M q' = 1/2 m v_G^2 + 1/2 I_G w^2."""
    p = pack_parameters(vehicle, Design.from_deg(120, 0.1, 0.09), SimSettings())
    rng = np.random.default_rng(3)
    for b in bodies(p):
        ri = rng.normal(size=2)
        angle = rng.uniform(0, 2 * math.pi)
        rj = ri + b.length * np.array([math.cos(angle), math.sin(angle)])
        v_i, w = rng.normal(size=2), rng.normal()
        v_j = v_i + w * (ROT @ (rj - ri))
        qd = np.zeros(N_COORDS)
        qd[b.i:b.i + 2], qd[b.j:b.j + 2] = v_i, v_j
        g = b.a_g * (rj - ri) + b.b_g * (ROT @ (rj - ri))   # centre of mass from point i
        v_g = v_i + w * (ROT @ g)
        expected = 0.5 * b.mass * v_g @ v_g + 0.5 * b.inertia * w * w
        Mb = _mass_matrix_of(p, b.name)
        assert 0.5 * qd @ Mb @ qd == pytest.approx(expected, rel=1e-12), b.name


def _mass_matrix_of(p, name):
    """M of the named body alone (the other bodies' masses and inertias set to zero)."""
    q = p.copy()
    keep = {"chassis": (P.M_CHASSIS, P.I_CHASSIS), "swingarm": (P.M_SWINGARM, P.I_SWINGARM),
            "engine_sprocket": (P.M_SPROCKET, P.I_SPROCKET), "rear_wheel": (P.M_REAR_WHEEL, P.I_REAR_WHEEL),
            "lower_fork": (P.M_FORK, P.I_FORK)}
    for body, idx in keep.items():
        if body != name:
            q[list(idx)] = 0.0
    q[P.M_FRONT_WHEEL] = 0.0
    return mass_matrix(q)


def test_mass_matrix_symmetric_and_total_weight(vehicle):
    p = pack_parameters(vehicle, Design.from_deg(195.3, 0.037, 0.088), SimSettings())
    M = mass_matrix(p)
    np.testing.assert_allclose(M, M.T)
    Qg = gravity_forces(p)
    assert Qg[0::2][:15].sum() == pytest.approx(0.0, abs=1e-9)      # no horizontal gravity
    assert Qg[1::2][:15].sum() == pytest.approx(-269.2 * vehicle["gravity"])
    # a rigid vertical translation of the whole bike has the whole mass
    qd = np.zeros(N_COORDS)
    qd[1:30:2] = 1.0
    assert qd @ M @ qd == pytest.approx(269.2)
