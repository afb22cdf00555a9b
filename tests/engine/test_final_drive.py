"""Fig. 5: with the engine sprocket held, rotating the swingarm turns the wheel.

The pose after the swingarm moves is found by Newton's method on all 33 constraint equations
(eqs. 1-33 and their Jacobian); the wheel's rotation is compared with the closed form of the
tangent geometry: delta beta = delta gamma (1 - R_ES/R_WS) - delta L_taut / R_WS, where
gamma = delta - acos((R_ES - R_WS)/D) and L_taut = sqrt(D^2 - (R_WS - R_ES)^2), D = |r_2->6|.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings
from finaldrive.engine.model import params as P
from finaldrive.engine.model.constraints import jacobian, phi
from finaldrive.engine.model.coordinates import (
    ALPHA,
    BETA,
    FS,
    N_CONSTRAINTS,
    N_COORDS,
    PHI,
    THETA,
    X1,
    X2,
    X6,
    Y1,
    Y2,
    Y6,
)
from finaldrive.engine.model.kinematics import chain_length, design_pose
from finaldrive.engine.simulation import pack_parameters

HELD = [X1, Y1, THETA, PHI, FS, ALPHA]
FREE = [k for k in range(N_COORDS) if k not in HELD]


def _newton_pose(q, p, kind, rp):
    res, J = np.empty(N_CONSTRAINTS), np.empty((N_CONSTRAINTS, N_COORDS))
    for _ in range(30):
        phi(q, p, kind, rp, res)
        if np.max(np.abs(res)) < 1e-13:
            return q
        jacobian(q, p, kind, rp, J)
        q[FREE] -= np.linalg.solve(J[:, FREE], res)
    raise AssertionError("position analysis did not converge")


def _closed_form(q, p):
    dx, dy = q[X6] - q[X2], q[Y6] - q[Y2]
    d = math.hypot(dx, dy)
    gamma = math.atan2(dy, dx) - math.acos((p[P.R_ES] - p[P.R_WS]) / d)
    return gamma, math.sqrt(d * d - (p[P.R_WS] - p[P.R_ES]) ** 2)


@pytest.mark.parametrize(
    "a2_deg, l2, rws", [(0, 0.0, 0.093), (270, 0.15, 0.05), (195.3, 0.037, 0.088), (45, 0.2, 0.15)]
)
def test_wheel_turns_by_the_tangent_geometry(vehicle, a2_deg, l2, rws):
    p = pack_parameters(vehicle, Design.from_deg(a2_deg, l2, rws), SimSettings())
    q = design_pose(p)
    p[P.L_CHAIN] = chain_length(q, p)
    kind, rp = Road().packed()
    g_a, taut_a = _closed_form(q, p)
    beta_a = q[BETA]
    moved = q.copy()
    moved[PHI] += math.radians(8.0)              # swingarm up 8 degrees, engine sprocket held
    moved = _newton_pose(moved, p, kind, rp)
    g_b, taut_b = _closed_form(moved, p)
    d_gamma = math.remainder(g_b - g_a, 2 * math.pi)
    expected = d_gamma * (1 - p[P.R_ES] / p[P.R_WS]) - (taut_b - taut_a) / p[P.R_WS]
    assert moved[BETA] - beta_a == pytest.approx(expected, abs=1e-10)
    assert moved[ALPHA] == q[ALPHA]
    if l2 == 0.0:  # concentric sprocket: the wheel turns by (1 - R_ES/R_WS) of the swingarm's turn
        assert moved[BETA] - beta_a == pytest.approx(math.radians(8.0) * 0.5, abs=1e-10)
