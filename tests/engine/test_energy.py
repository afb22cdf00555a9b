"""Energy: the ledger of a full run with every force on (drive, dampers, tyre springs and the
longitudinal tyre force) closes, and the tyre creates no energy; without dissipation and drive,
a dropped bike keeps its mechanical energy in both formulations.

The ledger (docs/engine.md#the-tyres-energy-ledger): drive work + lever-arm work = kinetic energy
+ potential energy change + damper dissipation + tyre slip work, each power integrated on the
integrator's own steps, the energies taken from the states at both ends.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings, simulate
from finaldrive.engine.fast import minimal
from finaldrive.engine.fast.rosenbrock import N_ST as FAST_N_ST, run_fast
from finaldrive.engine.model import diagnostics as D, params as P
from finaldrive.engine.model.coordinates import N_CONSTRAINTS, N_COORDS, Y1
from finaldrive.engine.model.elements import N_AUX, rear_tyre
from finaldrive.engine.model.kinematics import pose_from_minimal
from finaldrive.engine.model.mass import gravity_forces, mass_matrix, potential_energy
from finaldrive.engine.outcome import N_SERIES, OK
from finaldrive.engine.simulation import MINIMAL_COORDS, pack_parameters, prepare
from finaldrive.engine.solver import reference

TABLE11 = Design.from_deg(195.3, 0.037, 0.088)
GEOMETRY2 = Design.from_deg(270, 0.15, 0.050)
DROP = 0.02
LEDGER_TOL = 5e-3  # of the drive's work over 3.5 s


def _closure(r) -> float:
    return abs(r.ledger_residual_j) / r.drive_work_j


def _check_ledger(r) -> None:
    assert r.ok, r.reason
    print(f"drive {r.drive_work_j:.1f} J = kinetic {r.kinetic_energy_j:.1f} + potential {r.potential_energy_j:.2f}"
          f" + dampers {r.damper_dissipation_j:.2f} + slip {r.tyre_slip_work_j:.2f} (carcass "
          f"{r.tyre_carcass_energy_j:.3f}, dissipated {r.tyre_dissipation_j:.2f}) - lever {r.tyre_lever_work_j:.2f}"
          f"; residual {r.ledger_residual_j:.4f} J = {_closure(r):.2e}")
    assert r.drive_work_j > 1e4                   # the drive is on
    assert r.tyre_slip_work_j > 0.0               # the longitudinal force is on
    assert r.damper_dissipation_j > 0.0           # the dampers are on
    assert r.tyre_lever_work_j == 0.0             # lever arm R_e (the default)
    assert _closure(r) < LEDGER_TOL
    assert r.tyre_dissipation_min_w >= 0.0        # no energy created by the tyre, at any step
    assert r.tyre_slip_work_j == pytest.approx(r.tyre_carcass_energy_j + r.tyre_dissipation_j, rel=1e-9)


@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2", "sine:0.04:3", "bump:0.04:0.2"])
@pytest.mark.parametrize("design", [TABLE11, GEOMETRY2], ids=["table11", "geometry2"])
def test_ledger_closes_with_every_force_on_fast(vehicle, spec, design):
    """Geometry 2 on sine:0.04:2 hops (its rear wheel is off the road for more than the 0.5 s a run
    allows) and bottoms on the bump stop: the limit is lifted to let the ledger see it all."""
    r = simulate(design, Road.parse(spec), SimSettings(max_airborne_time=3.5), vehicle)
    _check_ledger(r)
    if design == GEOMETRY2 and spec == "sine:0.04:2":
        assert r.tyre_compression_rear_max_m > vehicle["rt_bottoming"] and r.airborne_rear_s > 0.5


@pytest.mark.slow
@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2"])
def test_ledger_closes_with_every_force_on_reference(vehicle, spec):
    _check_ledger(simulate(TABLE11, Road.parse(spec), SimSettings(method="reference"), vehicle))


def test_loaded_radius_as_lever_arm_creates_energy(vehicle):
    """With rt as the lever arm the tyre does the net work F_x omega (R_e - rt) > 0 (2.6 % of the
    drive's work on the flat road); the ledger closes only with that term."""
    loaded = vehicle.replace(fx_lever_loaded=1.0)
    r = simulate(TABLE11, Road.parse("flat"), SimSettings(), loaded)
    share = r.tyre_lever_work_j / r.drive_work_j
    print(f"lever-arm work with rt: {share:.2%} of the drive's work")
    assert 0.02 < share < 0.03
    assert _closure(r) < LEDGER_TOL
    assert abs(r.ledger_residual_j - r.tyre_lever_work_j) > 0.5 * r.tyre_lever_work_j  # it is not hidden


def test_slip_power_splits_into_carcass_storage_and_non_negative_dissipation(vehicle):
    """-F_x V_sx = F_x u' / (1 + a) + |V_x| F_x kappa' / (1 + a) at any state, the second >= 0,
    over speeds below and above V_low (where eq. 43's damping acts) and loads past Fz_max."""
    p = pack_parameters(vehicle, TABLE11, SimSettings())
    rng = np.random.default_rng(5)
    aux, pw = np.zeros(N_AUX), np.zeros(D.N_POWERS)
    for _ in range(5000):
        rt = p[P.RT0] - rng.uniform(-0.01, 0.09)
        vx = rng.choice([rng.uniform(-3, 3), rng.uniform(0, 30)])
        omega = vx / 0.29 * (1 + rng.normal(scale=0.3))
        u, sigma = rng.normal(scale=0.05), rng.uniform(p[P.SIGMA_MIN], p[P.SIGMA_K0])
        aux[:] = 0.0
        rear_tyre(rt, rng.normal(), vx, omega, u, sigma, p, True, aux)
        D.powers(aux, p, pw)
        split = pw[D.L_CARCASS] + pw[D.L_TYRE_DISSIPATION]
        assert pw[D.L_SLIP] == pytest.approx(split, abs=1e-9 * (1 + abs(pw[D.L_SLIP])))
        assert pw[D.L_TYRE_DISSIPATION] >= 0.0


def _drop_state_reference(setup):
    q0 = setup.q0.copy()
    q0[1:26:2] += DROP            # points 1-13 up by 2 cm (contact points stay on the road)
    q0[32] += DROP                # rt
    q0[33] += DROP                # ft
    return q0


def _conservative(vehicle):
    return vehicle.replace(torque=0.0, c_rs=0.0, c_fs=0.0, c_rt=0.0, c_ft=0.0)


@pytest.mark.slow
def test_dropped_bike_keeps_its_energy_reference(vehicle):
    """Drive, dampers and longitudinal force off, dropped 2 cm onto a flat road: kinetic + gravity +
    springs stays constant to 0.5 % of the drop energy over 1 s (the paper's method)."""
    settings = SimSettings(method="reference", duration=1.0, tyre_longitudinal=False)
    road = Road.parse("flat")
    setup = prepare(TABLE11, road, settings, _conservative(vehicle))
    p = setup.p
    y = np.zeros(reference.N_STATE)
    y[:N_COORDS] = _drop_state_reference(setup)
    kind, rp = road.packed()
    M, qg = mass_matrix(p), gravity_forces(p)
    n = 1000
    series, states = np.zeros((n + 2, N_SERIES)), np.zeros((n + 2, 2 * N_COORDS))
    ext, led = np.zeros(D.N_EXT), np.zeros(D.N_LED)
    code = reference.run_reference(
        y, p, kind, rp, M, qg, False, settings.dt, n, 4, 0.7, settings.corrector_tol, settings.corrector_max_iter,
        settings.lambda_tol, settings.lambda_max_iter, 1e-3, 10**6, 1, True, np.zeros(reference.N_ST),
        np.zeros((4, reference.N_STATE)), np.zeros(N_CONSTRAINTS), np.zeros(1), np.zeros(N_AUX), ext, led,
        series, states, 10**9)
    assert code == OK
    e = np.array([0.5 * s[N_COORDS:] @ M @ s[N_COORDS:] + potential_energy(s[:N_COORDS], p) for s in states[:n + 1]])
    drop_energy = e[0] - potential_energy(setup.q0, p)
    assert drop_energy > 0.9 * 269.2 * 9.81 * DROP * 0.5
    assert ext[D.E_FZ_REAR_MAX] > 0  # it lands
    drift = np.max(np.abs(e - e[0])) / drop_energy
    print(f"energy drift {drift:.2e} of the drop energy {drop_energy:.2f} J")
    assert drift < 0.005, drift
    assert led[D.L_DAMPERS] == 0.0 and led[D.L_DRIVE] == 0.0


def test_dropped_bike_keeps_its_energy_fast(vehicle):
    """The same in minimal coordinates: T from the model's own M(z), V from the pose rebuilt in
    natural coordinates: an independent check of the reduced equations. ROS34PW2 (the flat road's
    method) damps some of the drop energy of its own, less at a tighter tolerance: 0.54 % at 5e-6,
    0.46 % at 2e-6, 0.30 % at 1e-6 (ROS2: 0.005 % at 5e-6)."""
    road = Road.parse("flat")
    setup = prepare(TABLE11, road, SimSettings(), _conservative(vehicle))
    p = setup.p
    kind, rp = road.packed()
    n = 1000
    y = np.zeros(minimal.N_STATE)
    y[:minimal.N_DOF] = setup.q0[list(MINIMAL_COORDS)]
    y[minimal.ZY1] += DROP
    series, states = np.zeros((n + 1, N_SERIES)), np.zeros((n + 1, 2 * minimal.N_DOF))
    code = run_fast(y, p, kind, rp, False, 1.0, 1e-3, 1e-6, 1e-3, False, 10.0, True, np.zeros(FAST_N_ST),
                    np.zeros(D.N_EXT), np.zeros(D.N_LED), series, states, 10**9)
    assert code == OK
    assert states[0][minimal.ZY1] == setup.q0[Y1] + DROP

    def energy(state):
        full = np.zeros(minimal.N_STATE)
        full[:12] = state
        return minimal.kinetic_energy(full, p, kind, rp) + potential_energy(pose_from_minimal(state, p, road), p)

    e = np.array([energy(s) for s in states])
    drop_energy = e[0] - potential_energy(setup.q0, p)
    assert drop_energy > 0.9 * 269.2 * 9.81 * DROP * 0.5
    drift = np.max(np.abs(e - e[0])) / drop_energy
    print(f"fast path energy drift {drift:.2e} of the drop energy {drop_energy:.2f} J")
    assert drift < 0.005, drift
    assert math.isfinite(drift)
