"""The driver: one design on one road -> SimResult; a batch -> BatchResult.

Pure: no file I/O, no global state; failures come back as results with status "failed".
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from finaldrive.engine import outcome
from finaldrive.engine.api import STATUS_FAILED, STATUS_OK, BatchResult, Design, DesignError, SimResult, SimSettings
from finaldrive.engine.fast import minimal
from finaldrive.engine.fast.equilibrium import EquilibriumError, static_equilibrium
from finaldrive.engine.fast.rosenbrock import run_fast
from finaldrive.engine.fitness import fitness, slack
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import BETA, FS, N_COORDS, PHI, THETA, X1, X14, Y1, Y14
from finaldrive.engine.model.kinematics import (
    GeometryError,
    chain_length,
    design_squat_ratio,
    pose_from_minimal,
    squat_ratio_at,
)
from finaldrive.engine.model.mass import gravity_forces, mass_matrix
from finaldrive.engine.model.road import Road
from finaldrive.engine.solver import reference
from finaldrive.engine.vehicle import Vehicle, default_vehicle

#: The natural coordinates that are the fast path's minimal coordinates z, in order.
MINIMAL_COORDS = (X1, Y1, THETA, PHI, FS, BETA)

_REASONS = {
    outcome.NONFINITE: "the state became non-finite (diverged)",
    outcome.RESIDUAL: "constraint residual max|Phi| exceeded the limit (diverged)",
    outcome.CORRECTOR: "ABM corrector did not converge",
    outcome.REAR_AIRBORNE: "rear wheel off the road for longer than the limit",
    outcome.FRONT_AIRBORNE: "front wheel off the road for longer than the limit",
}


def pack_parameters(vehicle: Vehicle, design: Design, settings: SimSettings) -> np.ndarray:
    """The model's parameter vector P (engine.model.params); the chain length is filled later."""
    p = np.zeros(P.N_PARAMS)
    p[:P.N_VEHICLE] = vehicle.packed()
    p[P.A2], p[P.L2], p[P.R_WS] = design.a2, design.l2, design.rws
    p[P.R_ES] = design.rws / vehicle["sprocket_ratio"]   # section 4: R_WS / R_ES fixed
    p[P.AL_ALPHA], p[P.AL_XI], p[P.AL_OMEGA] = (
        settings.penalty_alpha, settings.baumgarte_xi, settings.baumgarte_omega)
    return p


@dataclass(frozen=True)
class Setup:
    """Everything a run needs that does not change with time."""

    p: np.ndarray       # parameters incl. the chain length L (69)
    q0: np.ndarray      # static equilibrium on the road
    squat_ratio: float  # at the design pose


def prepare(design: Design, road: Road, settings: SimSettings, vehicle: Vehicle) -> Setup:
    """Parameters, static equilibrium and the chain length L of eq. (69) at t = 0."""
    p = pack_parameters(vehicle, design, settings)
    q0 = static_equilibrium(p, road)
    p[P.L_CHAIN] = chain_length(q0, p)
    return Setup(p=p, q0=q0, squat_ratio=float(design_squat_ratio(p)))


def _failed(reason: str, sr: float, chain: float, start: float) -> SimResult:
    return SimResult(STATUS_FAILED, reason, math.nan, sr, math.nan, math.nan, chain,
                     time.perf_counter() - start)


def simulate(design: Design, road: Road, settings: SimSettings = SimSettings(),
             vehicle: Vehicle | None = None) -> SimResult:
    """Simulate one design on one road from rest; never raises for a design that fails."""
    start = time.perf_counter()
    vehicle = vehicle or default_vehicle()
    try:
        setup = prepare(design, road, settings, vehicle)
    except (GeometryError, EquilibriumError) as exc:
        return _failed(str(exc), math.nan, math.nan, start)
    p = setup.p
    chain = float(p[P.L_CHAIN])
    kind, rp = road.packed()
    n_steps, dt = settings.steps()
    if settings.method == "fast":
        # outputs (series rows) every stride steps of dt, at the reference's times
        n_out = max(1, math.ceil(settings.duration / (dt * settings.series_stride) - 1e-9))
        y0 = np.zeros(minimal.N_STATE)
        y0[:minimal.N_DOF] = setup.q0[list(MINIMAL_COORDS)]
        code, failed_at, y_end, tmin, tmax, series, states = run_fast(
            y0, p, kind, rp, settings.tyre_longitudinal, settings.duration / n_out, n_out,
            settings.fast_tolerance, settings.fast_max_step, settings.max_airborne_time, 1,
            settings.series)
        x1_end = y_end[minimal.ZX1]
    else:
        max_air_steps = math.ceil(settings.max_airborne_time / dt)
        y0 = np.zeros(reference.N_STATE)
        y0[:N_COORDS] = setup.q0
        code, failed_step, y_end, tmin, tmax, series, states = reference.run_reference(
            y0, p, kind, rp, mass_matrix(p), gravity_forces(p), settings.tyre_longitudinal, dt, n_steps,
            settings.trapezoidal_steps, settings.under_relaxation, settings.corrector_tol,
            settings.corrector_max_iter, settings.lambda_tol, settings.lambda_max_iter,
            settings.max_constraint_residual, max_air_steps, settings.series_stride, settings.series)
        x1_end = y_end[X1]
        failed_at = failed_step * dt
    if code != outcome.OK:
        return _failed(f"{_REASONS[code]} at t = {failed_at:.4f} s", setup.squat_ratio, chain, start)
    distance = float(x1_end - setup.q0[X1])
    slack_m = slack(tmin, tmax)
    fit = fitness(distance, setup.squat_ratio, slack_m, eps1=p[P.EPS1], eps2=p[P.EPS2],
                  sr_optimum=p[P.SR_OPTIMUM], floor=p[P.FLOOR])
    out = None
    if settings.series:
        if settings.method == "fast":
            qs = np.array([pose_from_minimal(s, p, road) for s in states])
        else:
            qs = states[:, :N_COORDS]
        out = _series(series, qs, setup, p, settings.method)
    return SimResult(STATUS_OK, "", distance, setup.squat_ratio, slack_m, fit, chain,
                     time.perf_counter() - start, out)


def _series(series: np.ndarray, qs: np.ndarray, setup: Setup, p: np.ndarray,
            method: str) -> dict[str, np.ndarray]:
    """Name the recorded columns (Fig. 13 quantities) and add derived ones."""
    out = {name: series[:, k].copy() for k, name in enumerate(outcome.SERIES_COLUMNS)}
    out["distance"] = out.pop("x1") - setup.q0[X1]
    out["pitch"] = out.pop("theta")
    out["squat_ratio"] = np.array([squat_ratio_at(q, p, q[X14], q[Y14]) for q in qs])
    out["q"] = np.array(qs, dtype=float)
    if method == "fast":
        del out["residual"]  # minimal coordinates satisfy the constraints exactly
    return out


def evaluate(designs: np.ndarray, road: Road, settings: SimSettings = SimSettings(),
             vehicle: Vehicle | None = None) -> BatchResult:
    """Simulate a batch of design rows (a2 [rad], L2 [m], R_WS [m]), results in input order.

    Series are never kept in a batch. A row that is not a valid design is a failed result.
    """
    rows = np.asarray(designs, dtype=float).reshape(-1, 3)
    settings = settings.with_(series=False)
    vehicle = vehicle or default_vehicle()
    results = []
    for a2, l2, rws in rows:
        try:
            design = Design(float(a2), float(l2), float(rws))
        except DesignError as exc:
            results.append(_failed(f"invalid design: {exc}", math.nan, math.nan, time.perf_counter()))
            continue
        results.append(simulate(design, road, settings, vehicle))
    return BatchResult.from_results(rows, results)



