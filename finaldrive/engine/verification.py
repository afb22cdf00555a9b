"""The drop test: how well each method keeps a conservative bike's energy (tests and docs/validation.md).

Drive, dampers (suspension and tyres) and the longitudinal tyre force off, the bike is dropped
``drop_m`` onto the flat road from its static equilibrium and left for ``duration_s``; without
dissipation, kinetic + gravity + spring energy is constant, so its largest change over the drop
energy is the method's energy error. The energies are computed here from the states the solvers
return (the reference: its mass matrix and coordinates; the fast path: its own M(z), and the
potential of the pose rebuilt in natural coordinates), independently of the solvers' ledgers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from finaldrive.engine.api import Design, SimSettings
from finaldrive.engine.fast import bodies, minimal, rosenbrock
from finaldrive.engine.jit import records
from finaldrive.engine.model import diagnostics as D
from finaldrive.engine.model.coordinates import FT, N_CONSTRAINTS, N_COORDS, RT, Y1
from finaldrive.engine.model.elements import N_AUX
from finaldrive.engine.model.kinematics import pose_from_minimal
from finaldrive.engine.model.mass import gravity_forces, mass_matrix, potential_energy
from finaldrive.engine.model.road import Road
from finaldrive.engine.outcome import N_SERIES, OK
from finaldrive.engine.setup import MINIMAL_COORDS, prepare
from finaldrive.engine.vehicle import Vehicle

#: The drop [m] and how long the bike is left [s] (1 s: a few tyre and suspension bounces).
DROP_M = 0.02
DROP_S = 1.0


@dataclass(frozen=True)
class Drop:
    """A drop's energy record: the drop energy [J], the largest |E - E0| and E(end) - E0 as shares of it."""

    drop_energy_j: float
    drift: float
    end: float
    landed: bool


def conservative(vehicle: Vehicle) -> Vehicle:
    """The vehicle without drive and dampers (the longitudinal tyre force is switched off in the run)."""
    return vehicle.replace(torque=0.0, c_rs=0.0, c_fs=0.0, c_rt=0.0, c_ft=0.0)


def _record(energies: np.ndarray, rest_j: float, landed: bool) -> Drop:
    drop_energy = float(energies[0] - rest_j)
    return Drop(drop_energy, float(np.max(np.abs(energies - energies[0])) / drop_energy),
                float((energies[-1] - energies[0]) / drop_energy), landed)


def fast_drop(vehicle: Vehicle, design: Design, tolerance: float, max_step: float, ros2: bool,
              drop_m: float = DROP_M, duration_s: float = DROP_S) -> Drop:
    """The drop with the fast path at ``tolerance`` and ``max_step`` (ROS2 if ``ros2``, else ROS34PW2), for
    the paper's chain (ValueError for the elastic one, whose sprocket state the drop does not carry)."""
    if vehicle["chain_compliance"] == 1.0:
        raise ValueError("fast_drop: vehicle chain_compliance = 1 is not supported (the drop checks the paper's chain)")
    road = Road()
    setup = prepare(design, road, SimSettings(), conservative(vehicle))
    p = setup.p
    kind, rp = road.packed()
    n = round(duration_s / 1e-3)
    y = np.zeros(minimal.N_STATE)
    y[:bodies.N_DOF] = setup.q0[list(MINIMAL_COORDS)]
    y[bodies.ZY1] += drop_m
    series, states = np.zeros((n + 1, N_SERIES)), np.zeros((n + 1, 2 * bodies.N_DOF))
    tracked = D.TRACKED.new()
    settings = rosenbrock.FAST_SETTINGS.new(
        tyre_longitudinal=False, duration=duration_s, dt_out=1e-3, fast_tolerance=tolerance, fast_max_step=max_step,
        fast_ros2=ros2, max_airborne_time=10.0, keep_series=True, chunk_steps=10**9)
    code = rosenbrock.run_fast(y, p, kind, rp, settings, rosenbrock.FAST_STATE.new(), tracked, series, states)
    if code != OK or states[0][bodies.ZY1] != setup.q0[Y1] + drop_m:
        raise RuntimeError(f"the fast drop did not run (code {code})")

    def energy(state: np.ndarray) -> float:
        full = np.zeros(minimal.N_STATE)
        full[:2 * bodies.N_DOF] = state
        return float(minimal.kinetic_energy(full, p, kind, rp) + potential_energy(pose_from_minimal(state, p, road), p))

    return _record(np.array([energy(s) for s in states]), float(potential_energy(setup.q0, p)),
                   records.read(tracked)["fz_rear_max_n"] > 0)


def reference_drop(vehicle: Vehicle, design: Design, dt: float = 1e-3, drop_m: float = DROP_M,
                   duration_s: float = DROP_S) -> Drop:
    """The drop with the paper's method (eqs. 57-66) at step ``dt``, its other settings the defaults."""
    from finaldrive.engine.solver import reference  # builds its integrator steps on import

    settings = SimSettings(method="reference", duration=duration_s, dt=dt, tyre_longitudinal=False)
    road = Road()
    setup = prepare(design, road, settings, conservative(vehicle))
    p = setup.p
    y = np.zeros(reference.N_STATE)
    y[:N_COORDS] = setup.q0
    y[1:26:2] += drop_m    # points 1-13 up (the contact points 14 and 15 stay on the road)
    y[RT] += drop_m
    y[FT] += drop_m
    kind, rp = road.packed()
    M, qg = mass_matrix(p), gravity_forces(p)
    n, step = settings.steps()
    series, states = np.zeros((n + 2, N_SERIES)), np.zeros((n + 2, 2 * N_COORDS))
    tracked = D.TRACKED.new()
    loop_settings = reference.REFERENCE_SETTINGS.new(
        tyre_longitudinal=False, dt=step, n_steps=n, trapezoidal_steps=settings.trapezoidal_steps,
        under_relaxation=settings.under_relaxation, corrector_tol=settings.corrector_tol,
        corrector_max_iter=settings.corrector_max_iter, lambda_tol=settings.lambda_tol,
        lambda_max_iter=settings.lambda_max_iter, max_constraint_residual=settings.max_constraint_residual,
        max_airborne_steps=10**6, series_stride=1, keep_series=True, chunk_steps=10**9)
    code = reference.run_reference(y, p, kind, rp, M, qg, loop_settings, reference.REFERENCE_STATE.new(), tracked,
                                   np.zeros((4, reference.N_STATE)), np.zeros(N_CONSTRAINTS), np.zeros(N_AUX),
                                   series, states)
    at_end = records.read(tracked)
    if code != OK or at_end["dampers_j"] != 0.0 or at_end["drive_work_j"] != 0.0:
        raise RuntimeError(f"the reference drop did not run conservatively (code {code})")
    energies = np.array([0.5 * s[N_COORDS:] @ M @ s[N_COORDS:] + potential_energy(s[:N_COORDS], p)
                         for s in states[:n + 1]])
    return _record(energies, float(potential_energy(setup.q0, p)), at_end["fz_rear_max_n"] > 0)
