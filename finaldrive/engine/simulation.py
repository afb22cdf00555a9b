"""The driver: one design on one road -> SimResult; a batch -> BatchResult.

Pure: no file I/O, no global state; failures come back as results with status "failed".
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from finaldrive.engine import outcome
from finaldrive.engine.api import (
    STATUS_FAILED,
    STATUS_OK,
    BatchResult,
    Design,
    DesignError,
    SimResult,
    SimSettings,
)
from finaldrive.engine.fast import bodies, minimal, rosenbrock
from finaldrive.engine.fast.equilibrium import EquilibriumError
from finaldrive.engine.fitness import fitness, slack
from finaldrive.engine.jit import records
from finaldrive.engine.jit.records import Record
from finaldrive.engine.model import diagnostics as D, params as P
from finaldrive.engine.model.coordinates import N_CONSTRAINTS, N_COORDS, X1, X14, X15, Y14
from finaldrive.engine.model.elements import N_AUX
from finaldrive.engine.model.kinematics import GeometryError, assemble, pose_from_minimal, squat_ratio_at
from finaldrive.engine.model.linalg import dot, matvec
from finaldrive.engine.model.mass import gravity_forces, mass_matrix, potential_energy
from finaldrive.engine.model.road import Road
from finaldrive.engine.record import DIAGNOSTICS
from finaldrive.engine.setup import MINIMAL_COORDS, Setup, pack_parameters, prepare
from finaldrive.engine.solver.equilibrium import ReferenceEquilibriumError
from finaldrive.engine.vehicle import Vehicle, default_vehicle

__all__ = ["MINIMAL_COORDS", "Setup", "evaluate", "pack_parameters", "prepare", "simulate", "simulate_prepared"]

#: Steps of a compiled loop between two looks at the wall clock and at should_stop: about
#: 5-20 ms of work on one core (fast path ~2 us a step, reference ~60 us a step).
FAST_CHUNK_STEPS = 4096
REFERENCE_CHUNK_STEPS = 256

_REASONS = {
    outcome.NONFINITE: "the state became non-finite (diverged)",
    outcome.RESIDUAL: "constraint residual max|Phi| exceeded the limit (diverged)",
    outcome.CORRECTOR: "ABM corrector did not converge",
    outcome.REAR_AIRBORNE: "rear wheel off the road for longer than the limit",
    outcome.FRONT_AIRBORNE: "front wheel off the road for longer than the limit",
}
REASON_CANCELLED = "cancelled"


def _failed(reason: str, sr: float, chain: float, start: float) -> SimResult:
    return SimResult.of(STATUS_FAILED, reason, squat_ratio=sr, chain_length_m=chain,
                        wall_s=time.perf_counter() - start)


def _settings_record(record: Record, settings: SimSettings, **given: float) -> np.ndarray:
    """A solver's settings record: ``given``, and SimSettings' fields of the other names."""
    return record.new(**{name: getattr(settings, name) for name in record.names if name not in given}, **given)


def _run_chunks(chunk: Callable[[], int], settings: SimSettings,
                should_stop: Callable[[], bool] | None) -> tuple[int, str]:
    """Run a resumable compiled loop to its end, one chunk at a time; between chunks, stop it when
    should_stop() says so or the wall-time limit has passed. (code, reason why it was stopped).

    The limit's clock starts when the first chunk returns: in a fresh process numba compiles the
    model during its first call (tens of seconds on a loaded machine), which is not the run's time.
    """
    clock: float | None = None
    while True:
        if should_stop is not None and should_stop():
            return outcome.PAUSED, REASON_CANCELLED
        if settings.max_wall_s is not None and clock is not None and time.perf_counter() - clock > settings.max_wall_s:
            return outcome.PAUSED, f"time limit: {settings.max_wall_s:g} s of wall time exceeded"
        code = chunk()
        if clock is None:
            clock = time.perf_counter()
        if code != outcome.PAUSED:
            return code, ""


def simulate(design: Design, road: Road, settings: SimSettings = SimSettings(),
             vehicle: Vehicle | None = None, should_stop: Callable[[], bool] | None = None) -> SimResult:
    """Simulate one design on one road from rest; never raises for a design that fails.

    should_stop, if given, is asked between chunks of integration (every few ms of work): when
    it returns True the run ends as failed with reason "cancelled". A run whose integration takes
    longer than settings.max_wall_s (counted from the end of its first chunk, so that numba's
    compilation in a fresh process does not count) ends as failed with a reason starting
    "time limit". Neither changes a result that finishes.
    """
    start = time.perf_counter()
    vehicle = vehicle or default_vehicle()
    try:
        setup = prepare(design, road, settings, vehicle)
    except DesignError as exc:
        return _failed(f"invalid design: {exc}", math.nan, math.nan, start)
    except (GeometryError, EquilibriumError, ReferenceEquilibriumError) as exc:
        return _failed(str(exc), math.nan, math.nan, start)
    return simulate_prepared(setup, road, settings, should_stop, start)


def simulate_prepared(setup: Setup, road: Road, settings: SimSettings,
                      should_stop: Callable[[], bool] | None = None, start: float | None = None) -> SimResult:
    """:func:`simulate` from its setup on (``prepare``'s, for the same road and settings); ``start``:
    the perf_counter reading the run's wall time counts from (default: now)."""
    start = time.perf_counter() if start is None else start
    p = setup.p
    chain = float(p[P.L_CHAIN])
    off_road = road.uncovered(float(setup.q0[X14]), -math.inf)
    if off_road:
        return _failed(off_road, setup.squat_ratio, chain, start)
    kind, rp = road.packed()
    tracked = D.TRACKED.new()
    qg = gravity_forces(p)
    if settings.method == "fast":
        # series rows every series_stride x dt, by dense output (the steps do not land on them)
        n_out = max(1, math.ceil(settings.duration / (settings.dt * settings.series_stride) - 1e-9))
        n_rows = n_out + 1 if settings.series else 0
        own_sprocket = bool(p[P.CHAIN_RUNS] == 2.0 or p[P.CHAIN_COMPLIANCE] == 1.0)  # e and alpha' in the state
        series = np.zeros((n_rows, outcome.N_SERIES))
        states = np.zeros((n_rows, 2 * bodies.N_DOF + int(own_sprocket)))  # e too
        loop_settings = _settings_record(rosenbrock.FAST_SETTINGS, settings, dt_out=settings.duration / n_out,
                                         keep_series=settings.series, chunk_steps=FAST_CHUNK_STEPS)
        state = rosenbrock.FAST_STATE.new()
        y = np.zeros(minimal.N_STATE_TWO_RUNS if own_sprocket else minimal.N_STATE)
        y[:bodies.N_DOF] = setup.q0[list(MINIMAL_COORDS)]

        def chunk() -> int:
            return int(rosenbrock.run_fast(y, p, kind, rp, loop_settings, state, tracked, series, states))

        code, stopped = _run_chunks(chunk, settings, should_stop)
        state_at_end = records.read(state)
        reached = state_at_end["t"]
    else:
        # imported here: the reference's module builds its integrator steps (numba dispatchers) on import
        from finaldrive.engine.solver import reference

        n_steps, dt = settings.steps()
        n_rows = (n_steps // settings.series_stride + 2) if settings.series else 0
        series = np.zeros((n_rows, outcome.N_SERIES))
        states = np.zeros((n_rows, 2 * N_COORDS))
        loop_settings = _settings_record(reference.REFERENCE_SETTINGS, settings, dt=dt, n_steps=n_steps,
                                         max_airborne_steps=math.ceil(settings.max_airborne_time / dt),
                                         keep_series=settings.series, chunk_steps=REFERENCE_CHUNK_STEPS)
        state = reference.REFERENCE_STATE.new()
        y = np.zeros(reference.N_STATE)
        y[:N_COORDS] = setup.q0
        hist = np.zeros((4, reference.N_STATE))
        lam = np.zeros(N_CONSTRAINTS)
        aux = np.zeros(N_AUX)
        M = mass_matrix(p)

        def chunk() -> int:
            return int(reference.run_reference(y, p, kind, rp, M, qg, loop_settings, state, tracked, hist, lam, aux,
                                               series, states))

        code, stopped = _run_chunks(chunk, settings, should_stop)
        state_at_end = records.read(state)
        reached = state_at_end["step"] * dt
    if stopped:
        at = f" at t = {reached:.4f} s" if stopped != REASON_CANCELLED else ""
        return _failed(stopped + at, setup.squat_ratio, chain, start)
    if code != outcome.OK:
        return _failed(f"{_REASONS[code]} at t = {reached:.4f} s", setup.squat_ratio, chain, start)
    if settings.method == "fast":
        x1_end = float(y[bodies.ZX1])
        kinetic = float(minimal.kinetic_energy(y, p, kind, rp, state_at_end["mode"]))
        chain_energy = float(minimal.elastic_energy(y, p))   # the elastic chain's spring (0 at the start)
        x1, y1, theta, phi, fs = (float(c) for c in y[:bodies.ZBETA])
        q_end = assemble(p, road, x1, y1, theta, phi, fs, 0.0, 0.0)  # the pose, but for alpha and beta
    else:
        x1_end = float(y[X1])
        qd = y[N_COORDS:2 * N_COORDS]
        Mqd = np.empty(N_COORDS)
        matvec(M, qd, Mqd)
        kinetic = 0.5 * dot(qd, Mqd)   # engine.model.linalg: not BLAS's CPU-chosen kernels
        q_end = y[:N_COORDS]
        chain_energy = 0.0
    rows = state_at_end["row"]
    off_road = road.uncovered(float(setup.q0[X14]), float(q_end[X15]))
    if off_road:
        return _failed(off_road, setup.squat_ratio, chain, start)
    distance = x1_end - float(setup.q0[X1])
    tracked_at_end = records.read(tracked)
    slack_m = slack(tracked_at_end["taut_min_m"], tracked_at_end["taut_max_m"])
    fit = fitness(distance, setup.squat_ratio, slack_m, eps1=p[P.EPS1], eps2=p[P.EPS2],
                  sr_optimum=p[P.SR_OPTIMUM], floor=p[P.FLOOR])
    diagnostics = _diagnostics(tracked_at_end, kinetic,
                               potential_energy(q_end, p, qg) - potential_energy(setup.q0, p, qg) + chain_energy)
    out = None
    if settings.series:
        if settings.method == "fast":
            play = states[:rows, 2 * bodies.N_DOF] if states.shape[1] > 2 * bodies.N_DOF else np.zeros(rows)
            qs = np.array([pose_from_minimal(s, p, road, e) for s, e in zip(states[:rows], play, strict=True)])
        else:
            qs = states[:rows, :N_COORDS]
        out = _series(series[:rows], qs, setup, p, settings.method)
    return SimResult.of(STATUS_OK, "", out, distance_m=distance, squat_ratio=setup.squat_ratio, slack_m=slack_m,
                        fitness_m=fit, chain_length_m=chain, wall_s=time.perf_counter() - start, **diagnostics)


def _diagnostics(tracked: dict[str, float], kinetic: float, potential: float) -> dict[str, float]:
    """The record's diagnostics (engine.record) from what the loop tracked (D.TRACKED, read) and the end
    state's energies."""
    values = {name: tracked[name] for name in DIAGNOSTICS if name in tracked}
    values.update(kinetic_energy_j=kinetic, potential_energy_j=potential,
                  damper_dissipation_j=tracked["dampers_j"] + tracked["chain_impacts_j"])
    # the sum in this order, term by term (results bit for bit as before the records)
    values["ledger_residual_j"] = tracked["drive_work_j"] + tracked["tyre_lever_work_j"] - (
        kinetic + potential + tracked["dampers_j"] + tracked["chain_impacts_j"] + tracked["tyre_slip_work_j"])
    assert values.keys() == set(DIAGNOSTICS)  # every diagnostic the record declares
    return values


def _series(series: np.ndarray, qs: np.ndarray, setup: Setup, p: np.ndarray,
            method: str) -> dict[str, np.ndarray]:
    """Name the recorded columns (Fig. 13 quantities) and add derived ones."""
    out = {name: series[:, k].copy() for k, name in enumerate(outcome.SERIES_COLUMNS)}
    out["distance_m"] = out.pop("x1_m") - setup.q0[X1]
    out["pitch_deg"] = np.degrees(out.pop("theta_rad"))
    out["squat_ratio"] = np.array([squat_ratio_at(q, p, q[X14], q[Y14]) for q in qs])
    out["q"] = np.array(qs, dtype=float)
    if method == "fast":
        del out["residual_m"]  # minimal coordinates satisfy the constraints exactly
    return out


def evaluate(designs: np.ndarray, road: Road, settings: SimSettings = SimSettings(),
             vehicle: Vehicle | None = None, should_stop: Callable[[], bool] | None = None) -> BatchResult:
    """Simulate a batch of design rows (a2 [rad], L2 [m], R_WS [m]), results in input order.

    Series are never kept in a batch. A row that is not a valid design is a failed result.
    should_stop is passed to each simulate (once it says stop, the remaining rows are cancelled).
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
        results.append(simulate(design, road, settings, vehicle, should_stop))
    return BatchResult.from_results(rows, results)
