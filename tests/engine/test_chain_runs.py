"""The two-run chain (vehicle chain_runs = 2, docs/engine.md#chain-overrun), against geometry and physics.

- the lower run is the other common tangent (the mirror of eqs. 24-29, 31), and the loop of both
  taut runs is the perimeter of the two pitch circles' convex hull, built independently;
- the fast path's lower-run terms d(alpha)/dz, alpha'' at z'' = 0 against central differences of
  alpha(z) from that construction;
- the re-engagement impact: momentum changes only along the run's constraint, the gap's rate ends
  at zero, and the energy it takes is the kinetic energy lost;
- the drive reversed: the upper run goes slack, the engine sprocket crosses the free play in the
  time its inertia and the torque give, the lower run pulls (tension >= 0), the ledger closes with
  the impacts booked;
- no overrun: the same run as the paper's upper-run chain, bit for bit; rough-road overrun moves the
  distance by micrometres; paused runs continue exactly; the reference method refuses the option.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull

import finaldrive.engine.simulation as sim
from finaldrive.engine import Design, Road, SimSettings, simulate
from finaldrive.engine.fast import bodies, chain_runs, minimal, rosenbrock
from finaldrive.engine.jit import records
from finaldrive.engine.model import diagnostics as D, params as P
from finaldrive.engine.model.coordinates import ALPHA, BETA, X2, X6, X10, Y2, Y6, Y10
from finaldrive.engine.model.elements import AUX_ALPHA_DOT, N_AUX
from finaldrive.engine.model.kinematics import (
    design_pose,
    free_play_slack,
    loop_length,
    pose_from_minimal,
    tangent_angle,
    taut_length,
)
from finaldrive.engine.outcome import N_SERIES, OK
from finaldrive.engine.simulation import MINIMAL_COORDS, pack_parameters, prepare
from finaldrive.engine.vehicle import VehicleError

TABLE11 = Design.from_deg(195.3, 0.037, 0.088)
DESIGNS = [TABLE11, Design.from_deg(270, 0.15, 0.05), Design.from_deg(45, 0.2, 0.15), Design.from_deg(0, 0.0, 0.093)]
IDS = ["table11", "geometry2", "45-0.2-0.15", "geometry1"]
REVERSED = -60.0  # N m on the engine sprocket: the drive reversed (engine braking from rest)


@pytest.fixture(scope="module")
def two_runs(vehicle):
    return vehicle.replace(chain_runs=2)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _centres(q):
    return np.array([q[X2], q[Y2]]), np.array([q[X6], q[Y6]])


@pytest.mark.parametrize("design", DESIGNS, ids=IDS)
def test_lower_run_is_the_mirrored_tangent_and_the_loop_is_the_convex_hull(vehicle, design):
    p = pack_parameters(vehicle, design, SimSettings())
    q = design_pose(p)
    c2, c6 = _centres(q)
    res, rws = p[P.R_ES], p[P.R_WS]
    gamma_l = tangent_angle(*c2, *c6, res, rws, -1)
    e = np.array([math.cos(gamma_l), math.sin(gamma_l)])
    p10, p11 = c2 + res * e, c6 + rws * e                   # the lower run's tangent points
    assert np.dot(c6 - p11, p11 - p10) == pytest.approx(0.0, abs=1e-12)  # mirror of eq. (31)
    assert np.dot(c2 - p10, p11 - p10) == pytest.approx(0.0, abs=1e-12)
    d = c6 - c2
    upper_side = _cross(d, np.array([q[X10], q[Y10]]) - c2)            # point 10 of the upper run
    assert np.sign(_cross(d, p10 - c2)) == -np.sign(upper_side)        # the other side of the centres
    angles = np.linspace(0.0, 2.0 * math.pi, 40000, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    hull = ConvexHull(np.concatenate([c2 + res * ring, c6 + rws * ring]))
    perimeter = hull.area  # in 2D, scipy's "area" is the perimeter
    assert loop_length(float(np.hypot(*d)), res, rws) == pytest.approx(perimeter, abs=1e-7)  # polygon error ~1e-9 m


def _lower_alpha(z, p, road):
    """alpha through the lower run, from the natural-coordinate pose: mirror of eq. (30),
    (alpha - gamma_l) R_ES + L_taut,l + (gamma_l - beta) R_WS = const (const = 0 here)."""
    q = pose_from_minimal(z, p, road)
    c2, c6 = _centres(q)
    res, rws = p[P.R_ES], p[P.R_WS]
    ref = z[bodies.ZPHI] + math.pi / 2  # gamma_l is about a right angle from the line of centres (~phi)
    gamma_l = ref + math.remainder(tangent_angle(*c2, *c6, res, rws, -1) - ref, 2.0 * math.pi)  # continuous
    e = np.array([math.cos(gamma_l), math.sin(gamma_l)])
    taut = float(np.hypot(*(c6 + rws * e - c2 - res * e)))
    return gamma_l - (taut + (gamma_l - q[BETA]) * rws) / res


@pytest.mark.parametrize("design", DESIGNS, ids=IDS)
@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2"])
def test_lower_run_terms_against_central_differences(vehicle, design, spec):
    road = Road.parse(spec)
    setup = prepare(design, road, SimSettings(), vehicle)
    p = setup.p
    rng = np.random.default_rng(4)
    z = setup.q0[list(MINIMAL_COORDS)] + rng.normal(scale=[0.02, 0.002, 0.01, 0.005, 0.01, 1.0])
    zd = rng.normal(scale=[3.0, 0.3, 0.5, 1.0, 0.3, 20.0])
    geo = bodies.design_constants(p)
    w2x, w2y, w6x, w6y = chain_runs.sprocket_centres(z, p, geo)
    ja_t, ja_p, alpha_c, _, _, alpha_dot = minimal.chain_terms(
        w2x, w2y, w6x, w6y, zd[bodies.ZTHETA], zd[bodies.ZPHI], zd[bodies.ZBETA], p, -1.0)
    jalpha = np.zeros(6)
    jalpha[bodies.ZTHETA], jalpha[bodies.ZPHI], jalpha[bodies.ZBETA] = ja_t, ja_p, p[P.R_WS] / p[P.R_ES]
    h = 1e-6
    fd = np.array([(_lower_alpha(z + h * e, p, road) - _lower_alpha(z - h * e, p, road)) / (2 * h) for e in np.eye(6)])
    np.testing.assert_allclose(jalpha, fd, atol=1e-7)            # FD error ~1e-10
    assert alpha_dot == pytest.approx(jalpha @ zd, rel=1e-12)
    h2 = 1e-4  # along z(t) = z + z' t: error ~h^2 alpha'''' ~ 1e-6
    second = (_lower_alpha(z + h2 * zd, p, road) - 2 * _lower_alpha(z, p, road)
              + _lower_alpha(z - h2 * zd, p, road)) / h2**2
    assert alpha_c == pytest.approx(second, abs=1e-4 * (1 + abs(second)))
    # the runs' gaps add up to the slack: g_u + g_l = L_loop - loop_length(|D|) for any e
    y = np.zeros(minimal.N_STATE_TWO_RUNS)
    y[:6] = z
    y[minimal.ZPLAY] = rng.normal()
    total = chain_runs.gap(y, minimal.UPPER, p, geo) + chain_runs.gap(y, minimal.LOWER, p, geo)
    assert total == pytest.approx(chain_runs.slack(y, p, geo), abs=1e-15)


@pytest.mark.parametrize("run", [minimal.UPPER, minimal.LOWER], ids=["upper", "lower"])
def test_impact_stops_the_gap_conserves_momentum_and_books_the_lost_energy(two_runs, run):
    road = Road.parse("flat")
    setup = prepare(TABLE11, road, SimSettings(), two_runs)
    p = setup.p
    kind, rp = road.packed()
    rng = np.random.default_rng(7)
    y = np.zeros(minimal.N_STATE_TWO_RUNS)
    y[:6] = setup.q0[list(MINIMAL_COORDS)]
    y[6:12] = rng.normal(scale=[3.0, 0.3, 0.5, 1.0, 0.3, 20.0])
    y[minimal.ZALPHA_DOT] = rng.normal(scale=20.0)
    geo = bodies.design_constants(p)
    ws, out, aux = np.zeros(bodies.N_WS), np.zeros(minimal.N_STATE_TWO_RUNS), np.zeros(N_AUX)
    minimal.fast_rhs(y, p, geo, kind, rp, 0.1, True, out, aux, ws, minimal.FREE)
    before = y.copy()
    energy_before = minimal.kinetic_energy(before, p, kind, rp, minimal.FREE)
    loss = chain_runs.engage(y, run, p, geo, ws)
    energy_after = minimal.kinetic_energy(y, p, kind, rp, run)
    assert loss > 0.0
    assert energy_before - energy_after == pytest.approx(loss, rel=1e-9)
    # the engaged run's rate of closing is zero: alpha' = d(alpha)/dz z' through that run
    minimal.fast_rhs(y, p, geo, kind, rp, 0.1, True, out, aux, ws, run)
    assert y[minimal.ZALPHA_DOT] == pytest.approx(aux[AUX_ALPHA_DOT], abs=1e-12)
    # the impulse acts along G = (-J_a, 1): M dz' = -J_a Lambda and I dalpha' = Lambda
    w2x, w2y, w6x, w6y = chain_runs.sprocket_centres(y, p, geo)
    ja_t, ja_p, *_ = minimal.chain_terms(w2x, w2y, w6x, w6y, 0.0, 0.0, 0.0, p, float(run))
    ja = np.zeros(6)
    ja[bodies.ZTHETA], ja[bodies.ZPHI], ja[bodies.ZBETA] = ja_t, ja_p, p[P.R_WS] / p[P.R_ES]
    minimal.fast_rhs(before, p, geo, kind, rp, 0.1, True, out, aux, ws, minimal.FREE)
    dp = np.zeros(6)
    bodies.mass_product(geo, ws, y[6:12] - before[6:12], dp)
    impulse = p[P.I_SPROCKET] * (y[minimal.ZALPHA_DOT] - before[minimal.ZALPHA_DOT])
    np.testing.assert_allclose(dp, -ja * impulse, atol=1e-9 * abs(impulse) * np.max(np.abs(ja)))
    assert chain_runs.gap(y, run, p, geo) == pytest.approx(0.0, abs=1e-15)


def _run(vehicle, spec, duration, tol=5e-5):
    """The fast loop itself, with the ledger's parts (simulate adds the impacts to the dampers)."""
    road = Road.parse(spec)
    setup = prepare(TABLE11, road, SimSettings(), vehicle)
    p = setup.p
    kind, rp = road.packed()
    y = np.zeros(minimal.N_STATE_TWO_RUNS)
    y[:6] = setup.q0[list(MINIMAL_COORDS)]
    rows = round(duration / 1e-3) + 1
    series, states = np.zeros((rows, N_SERIES)), np.zeros((rows, 12))
    tracked = D.TRACKED.new()
    settings = rosenbrock.FAST_SETTINGS.new(
        tyre_longitudinal=True, duration=duration, dt_out=1e-3, fast_tolerance=tol, fast_max_step=8e-3, fast_ros2=False,
        max_airborne_time=0.5, keep_series=True, chunk_steps=10**9)
    code = rosenbrock.run_fast(y, p, kind, rp, settings, rosenbrock.FAST_STATE.new(), tracked, series, states)
    assert code == OK
    return setup, y, records.read(tracked), series


def test_reversed_drive_loads_the_lower_run_after_the_free_play(two_runs):
    """Torque reversed from rest: the upper run goes slack at once, the engine sprocket turns back
    freely (I alpha'' = -T) through the free play s0 (its gap R_ES e grows to s0) and the lower run
    takes the load; from then on the chain pulls only through the lower run."""
    vehicle = two_runs.replace(torque=REVERSED)
    setup, _, tracked, series = _run(vehicle, "flat", 0.3)
    p = setup.p
    tension, t = series[:, 3], series[:, 0]
    s0 = free_play_slack(taut_length(setup.q0), two_runs["chain_free_play"])
    engaged = t[1 + np.argmax(tension[1:] < 0.0)]  # row 0: the state at rest, the upper run still engaged
    free_sprocket = math.sqrt(2.0 * s0 / p[P.R_ES] / (-REVERSED / p[P.I_SPROCKET]))
    print(f"free play {s0 * 1e3:.3f} mm taken up in {engaged * 1e3:.1f} ms (free sprocket alone: "
          f"{free_sprocket * 1e3:.1f} ms); lower run's peak {-tracked['chain_tension_min_n']:.0f} N, "
          f"impact {tracked['chain_impacts_j']:.3f} J")
    assert engaged == pytest.approx(free_sprocket, abs=2e-3)  # the wheel barely moves meanwhile; rows every 1 ms
    assert np.all(tension[1:] <= 0.0)                          # the upper run never pulls (net pull = -T_lower)
    assert np.all(tension[t > engaged + 0.002] < -100.0)       # the lower run carries the reversed drive
    assert tracked["chain_tension_max_n"] <= 0.0 < tracked["chain_impacts_j"]
    assert tracked["chain_compression_s"] == pytest.approx(0.3, abs=1e-9)  # overrun all along


def test_recorded_pose_turns_the_engine_sprocket_as_its_speed_says(two_runs):
    """The series' q carries the free sprocket's own angle: its rate is the recorded sprocket speed
    while the upper run is slack, the free play being taken up, and the lower run pulls."""
    r = simulate(TABLE11, Road.parse("flat"), SimSettings(duration=0.1, series=True, series_stride=1),
                 two_runs.replace(torque=REVERSED))
    t, alpha, speed = r.series["t_s"], r.series["q"][:, ALPHA], r.series["sprocket_speed_rad_s"]
    rate = -(alpha[2:] - alpha[:-2]) / (t[2:] - t[:-2])   # central differences, rows 1 ms apart
    free = np.flatnonzero(r.series["chain_tension_n"][1:-1] == 0.0)
    assert free.size > 15 and speed[10] == pytest.approx(REVERSED / two_runs["I_sprocket"] * 0.01, rel=1e-3)
    np.testing.assert_allclose(rate[free[:-1]], speed[1:-1][free[:-1]], rtol=1e-6)  # I alpha'' = -T: exact
    steady = np.abs(np.diff(speed, 2)) < 0.05    # away from the impact, where alpha' jumps
    np.testing.assert_allclose(rate[steady], speed[1:-1][steady], atol=0.02)  # the lower run pulling


@pytest.mark.parametrize("spec", ["flat", "bump:0.04:0.2"])
def test_ledger_closes_with_the_impacts_booked(two_runs, spec):
    """drive + lever = kinetic + potential + dampers + impacts + slip, with the drive reversed (flat)
    and on the bump where the upper run would push (the default drive)."""
    flat = spec == "flat"
    vehicle = two_runs.replace(torque=REVERSED) if flat else two_runs
    duration, tol = (0.3, 5e-7) if flat else (3.5, SimSettings().fast_tolerance)
    r = simulate(TABLE11, Road.parse(spec), SimSettings(duration=duration, fast_tolerance=tol), vehicle)
    impact = _run(vehicle, spec, duration, tol)[2]["chain_impacts_j"]
    print(f"{spec}: drive {r.drive_work_j:.3f} J, impacts {impact:.4f} J, residual {r.ledger_residual_j:.6f} J")
    assert r.ok and r.chain_compression_s > 0.0 and impact > 0.0
    # 3x the closure measured 2026-12-05 (as tests/engine/test_energy.py's): 1.75e-6 (flat, tight), 5.5e-6 (bump)
    assert abs(r.ledger_residual_j) < 3 * (1.75e-6 if flat else 5.5e-6) * abs(r.drive_work_j)
    if flat:  # smooth and tight: the residual is the integration error, far below the impacts it would miss
        assert abs(r.ledger_residual_j) < 1e-3 * impact


def test_without_overrun_both_chains_give_the_same_run(vehicle, two_runs):
    """The flat road never unloads the upper run: the two-run chain is the paper's, bit for bit (both
    with ROS2, the two-run chain's method; engine.fast.rosenbrock.high_order)."""
    one = simulate(TABLE11, Road.parse("flat"), SimSettings(fast_ros2=True), vehicle)
    two = simulate(TABLE11, Road.parse("flat"), SimSettings(), two_runs)
    assert one.chain_tension_min_n > 0.0 and two.chain_compression_s == 0.0
    same = {k: v for k, v in one.summary().items() if k != "wall_s"}
    assert same == {k: v for k, v in two.summary().items() if k != "wall_s"} and len(same) > 20


def test_rough_road_overrun_moves_the_distance_by_micrometres(vehicle, two_runs):
    """On the bump the upper run would push for about 6 ms; with both runs it goes slack instead and
    the sprocket re-engages it: the run is otherwise the same."""
    road = Road.parse("bump:0.04:0.2")
    one = simulate(TABLE11, road, SimSettings(), vehicle)
    two = simulate(TABLE11, road, SimSettings(), two_runs)
    assert one.chain_tension_min_n < -100.0 and one.chain_compression_s > 0.001
    assert two.chain_compression_s > 0.001
    assert two.chain_tension_max_n == pytest.approx(one.chain_tension_max_n, rel=0.01)
    assert two.distance_m == pytest.approx(one.distance_m, abs=1e-3)


@pytest.mark.parametrize("chunk", [1, 5])
def test_two_run_chain_continues_exactly_after_a_pause(two_runs, monkeypatch, chunk):
    road = Road.parse("bump:0.04:0.2")  # the upper run released and re-engaged after the bump
    settings = SimSettings(series=True)
    whole = simulate(TABLE11, road, settings, two_runs)
    assert whole.ok and whole.chain_compression_s > 0.0
    monkeypatch.setattr(sim, "FAST_CHUNK_STEPS", chunk)
    pieces = simulate(TABLE11, road, settings, two_runs)
    for name, value in whole.summary().items():
        if name != "wall_s":
            assert value == getattr(pieces, name), name
    for key in whole.series:
        np.testing.assert_array_equal(whole.series[key], pieces.series[key], err_msg=key)


def test_reference_method_refuses_two_runs(two_runs):
    with pytest.raises(ValueError, match="chain_runs"):
        simulate(TABLE11, Road.parse("flat"), SimSettings(method="reference"), two_runs)


@pytest.mark.parametrize("key, value", [("chain_runs", 1.5), ("chain_runs", 3), ("chain_free_play", 0.0)])
def test_vehicle_file_refuses_a_bad_chain(vehicle, key, value):
    with pytest.raises(VehicleError, match=key):
        vehicle.replace(**{key: value})
