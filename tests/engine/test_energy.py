"""Energy balance: drive, dampers and longitudinal tyre force off, the bike dropped 2 cm onto
a flat road keeps its total mechanical energy (kinetic + gravity + springs), in both
formulations: the 39 natural coordinates (reference) and the 6 minimal ones (fast)."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings, outcome
from finaldrive.engine.fast import minimal
from finaldrive.engine.fast.rosenbrock import run_fast
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import FS, FT, N_COORDS, RS, RT, Y1
from finaldrive.engine.model.kinematics import pose_from_minimal
from finaldrive.engine.model.mass import gravity_forces, mass_matrix
from finaldrive.engine.simulation import MINIMAL_COORDS, prepare
from finaldrive.engine.solver import reference

DROP = 0.02


def _energy(q, qd, setup):
    p = setup.p
    kinetic = 0.5 * qd @ mass_matrix(p) @ qd
    gravity = -gravity_forces(p) @ q             # Q_g is constant: V_g = -Q_g . q
    springs = 0.5 * p[P.K_RS] * (q[RS] - p[P.S_RS]) ** 2 + 0.5 * p[P.K_FS] * (q[FS] - p[P.S_FS]) ** 2
    springs += 0.5 * p[P.K_RT] * min(q[RT] - p[P.RT0], 0.0) ** 2
    springs += 0.5 * p[P.K_FT] * min(q[FT] - p[P.FT0], 0.0) ** 2
    return kinetic + gravity + springs


def _conservative(vehicle):
    return vehicle.replace(torque=0.0, c_rs=0.0, c_fs=0.0, c_rt=0.0, c_ft=0.0)


@pytest.mark.slow
def test_energy_is_conserved_within_half_a_percent_of_the_drop(vehicle):
    conservative = _conservative(vehicle)
    settings = SimSettings(method="reference", duration=1.0, tyre_longitudinal=False)
    road = Road.parse("flat")
    setup = prepare(Design.from_deg(195.3, 0.037, 0.088), road, settings, conservative)
    q0 = setup.q0.copy()
    q0[1:26:2] += DROP            # points 1-13 up by 2 cm (contact points stay on the road)
    q0[RT] += DROP
    q0[FT] += DROP
    y0 = np.zeros(reference.N_STATE)
    y0[:N_COORDS] = q0
    kind, rp = road.packed()
    code, _, _, _, _, series, states = reference.run_reference(
        y0, setup.p, kind, rp, mass_matrix(setup.p), gravity_forces(setup.p), False, settings.dt, 1000, 4, 0.7,
        settings.corrector_tol, settings.corrector_max_iter, settings.lambda_tol,
        settings.lambda_max_iter, 1e-3, 10**6, 1, True)
    assert code == outcome.OK
    e = np.array([_energy(s[:N_COORDS], s[N_COORDS:], setup) for s in states])
    e_rest = _energy(setup.q0, np.zeros(N_COORDS), setup)
    drop_energy = e[0] - e_rest
    assert drop_energy > 0.9 * 269.2 * 9.81 * DROP * 0.5   # the drop is a real energy input
    assert (series[:, outcome.SERIES_COLUMNS.index("fz_rear")] > 0).any()  # it lands
    drift = np.max(np.abs(e - e[0])) / drop_energy
    print(f"energy drift {drift:.2e} of the drop energy {drop_energy:.2f} J")
    assert drift < 0.005, drift


def test_fast_path_conserves_energy_too(vehicle):
    """Minimal coordinates: T = 1/2 z'^T M(z) z' (M from the model's own factor), V from the
    pose rebuilt in natural coordinates: an independent check of the reduced equations."""
    conservative = _conservative(vehicle)
    road = Road.parse("flat")
    setup = prepare(Design.from_deg(195.3, 0.037, 0.088), road, SimSettings(), conservative)
    p = setup.p
    y0 = np.zeros(minimal.N_STATE)
    y0[:minimal.N_DOF] = setup.q0[list(MINIMAL_COORDS)]
    y0[minimal.ZY1] += DROP
    kind, rp = road.packed()
    code, _, _, _, _, _, states = run_fast(y0, p, kind, rp, False, 1e-3, 1000, 5e-6, 1e-3, 10.0, 1, True)
    assert code == 0
    geo = minimal.design_constants(p)
    work = {"out": np.zeros(minimal.N_STATE), "aux": np.zeros(minimal.N_AUX), "L": np.zeros((6, 6)),
                "b": np.zeros(6), "c": np.zeros(6), "ws": np.zeros((6, 6))}
    qg = gravity_forces(p)

    def energy(state):
        y = np.zeros(minimal.N_STATE)
        y[:12] = state
        minimal.fast_rhs(y, p, geo, kind, rp, 0.2, False, False, work["out"], work["aux"],
                         work["L"], work["b"], work["c"], work["ws"])
        zd = state[6:]
        kinetic = 0.5 * np.sum((work["L"].T @ zd) ** 2)          # M = L L^T
        q = pose_from_minimal(state, p, road)
        springs = 0.5 * p[P.K_RS] * (q[RS] - p[P.S_RS]) ** 2 + 0.5 * p[P.K_FS] * (q[FS] - p[P.S_FS]) ** 2
        springs += 0.5 * p[P.K_RT] * min(q[RT] - p[P.RT0], 0.0) ** 2
        springs += 0.5 * p[P.K_FT] * min(q[FT] - p[P.FT0], 0.0) ** 2
        return kinetic - qg @ q + springs

    e = np.array([energy(s) for s in states])
    rest = setup.q0.copy()
    drop_energy = e[0] - (-qg @ rest + 0.5 * p[P.K_RS] * (rest[RS] - p[P.S_RS]) ** 2
                          + 0.5 * p[P.K_FS] * (rest[FS] - p[P.S_FS]) ** 2
                          + 0.5 * p[P.K_RT] * (rest[RT] - p[P.RT0]) ** 2
                          + 0.5 * p[P.K_FT] * (rest[FT] - p[P.FT0]) ** 2)
    assert states[0][minimal.ZY1] == setup.q0[Y1] + DROP
    assert drop_energy > 0.9 * 269.2 * 9.81 * DROP * 0.5
    drift = np.max(np.abs(e - e[0])) / drop_energy
    print(f"fast path energy drift {drift:.2e} of the drop energy {drop_energy:.2f} J")
    assert drift < 0.005, drift
