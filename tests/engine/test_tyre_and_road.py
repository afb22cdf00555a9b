"""Magic formula, transient slip model and road profiles against their definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine import Design, Road, RoadError, SimSettings, simulate
from finaldrive.engine.model import params as P
from finaldrive.engine.model.road_height import road_height
from finaldrive.engine.model.tyre import (
    deformation_rate,
    load_increment,
    magic_formula,
    relaxation_length,
    slip_stiffness,
    transient_slip,
)
from finaldrive.engine.simulation import pack_parameters


@pytest.fixture()
def p(vehicle):
    return pack_parameters(vehicle, Design.from_deg(0, 0, 0.09), SimSettings())


@pytest.mark.parametrize("fz", [500.0, 1600.0, 2500.0])
def test_magic_formula_slope_peak_and_sign(p, fz):
    h = 1e-7
    slope = (magic_formula(fz, h, p) - magic_formula(fz, -h, p)) / (2 * h)
    assert slope == pytest.approx(slip_stiffness(fz, p), rel=1e-5)            # dF/dk at 0 = K_xk
    kappas = np.linspace(0, 1, 20001)
    peak = max(magic_formula(fz, k, p) for k in kappas)
    dfz = (fz - 1600.0) / 1600.0
    assert peak == pytest.approx((1.2017 - 0.092206 * dfz) * fz, rel=1e-4)  # D_x = mu_x F_z
    assert magic_formula(fz, 0.2, p) > 0 > magic_formula(fz, -0.2, p)
    assert magic_formula(0.0, 0.2, p) == 0.0


def test_transient_state_settles_on_the_kinematic_slip(p):
    """Eq. (42) at constant speeds: u -> -V_sx sigma / |V_x|, so kappa' -> -V_sx / |V_x|."""
    vx, vsx, sigma, u, dt = 10.0, -0.8, 0.2, 0.0, 1e-4
    for _ in range(20000):
        u += dt * deformation_rate(u, sigma, vsx, vx)
    assert transient_slip(u, sigma, vsx, vx, 1500.0, p) == pytest.approx(-vsx / vx, rel=1e-6)


def test_relaxation_length_limits(p):
    fz = 1500.0
    assert relaxation_length(0.0, 0.0, fz, p) == pytest.approx(0.2)             # sigma_k0 at kappa' = 0
    k = 1e-4
    assert relaxation_length(magic_formula(fz, k, p), k, fz, p) == pytest.approx(0.2, rel=1e-3)
    assert relaxation_length(0.0, 10.0, fz, p) == pytest.approx(0.02)           # sigma_min floor


@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2", "sine:0.01:5", "sine:0.03:3:90", "sine:0.03:3:-45",
                                  "bump:0.04:0.2", "bump:0.02:1.0:3"])
def test_road_derivatives(spec):
    road = Road.parse(spec)
    kind, rp = road.packed()
    for x in np.linspace(-2, 12, 57):
        h, d1, d2 = road_height(kind, rp, x)
        assert h == pytest.approx(float(road.height_at(x)), abs=1e-15)
        e = 1e-5
        hp, d1p, _ = road_height(kind, rp, x + e)
        hm, d1m, _ = road_height(kind, rp, x - e)
        assert d1 == pytest.approx((hp - hm) / (2 * e), abs=1e-8)
        assert d2 == pytest.approx((d1p - d1m) / (2 * e), abs=1e-6)


def test_bump_default_centre_and_profile_road():
    assert Road.parse("bump:0.04:0.2").mu == 5.0
    road = Road.from_points([0, 1, 2], [0, 0.1, 0.0])
    kind, rp = road.packed()
    assert road_height(kind, rp, 0.5)[:2] == pytest.approx((0.05, 0.1))
    assert road_height(kind, rp, 5.0)[0] == 0.0


@pytest.mark.parametrize("spec", ["cobbles", "sine:0.04", "sine:a:3", "sine:0.04:0", "bump:0.04:-1", ""])
def test_bad_road_specs(spec):
    with pytest.raises(RoadError):
        Road.parse(spec)


def test_a_sine_road_s_phase() -> None:
    """sine:H:LAMBDA:PHI is H sin(2 pi x / LAMBDA + PHI) (eq. 32a shifted): its spec round-trips (the paper's
    phase 0 keeps its spec), and half a period of phase is the road turned upside down, to the run."""
    assert Road.parse("sine:0.04:3:0").spec == "sine:0.04:3" and Road.parse("sine:0.04:3:90").spec == "sine:0.04:3:90"
    quarter = Road.parse("sine:0.04:3:90")
    assert quarter.height_at(0.0) == pytest.approx(0.04) and quarter.height_at(0.75) == pytest.approx(0.0, abs=1e-15)
    design, settings = Design.from_deg(195.3, 0.037, 0.088), SimSettings(duration=1.0)
    shifted = simulate(design, Road.parse("sine:0.01:3:180"), settings)
    flipped = simulate(design, Road.parse("sine:-0.01:3"), settings)
    assert shifted.ok and flipped.ok
    assert shifted.distance_m == pytest.approx(flipped.distance_m, rel=1e-9)
    assert shifted.fz_rear_max_n == pytest.approx(flipped.fz_rear_max_n, rel=1e-6)
    assert abs(shifted.distance_m - simulate(design, Road.parse("sine:0.01:3"), settings).distance_m) > 1e-4


def test_profile_needs_increasing_x():
    with pytest.raises(RoadError, match="increasing"):
        Road.from_points([0, 2, 1], [0, 0, 0])
    assert math.isfinite(Road.from_points([0, 1], [0, 0]).height_at(0.5))


@pytest.mark.parametrize("spec, fragment", [
    ("sine:1e308:1e-308", "height H must be within"),
    ("sine:0.01:0.01", "wavelength LAMBDA must be in"),
    ("sine:0.01:1e6", "wavelength LAMBDA must be in"),
    ("bump:0.01:1e-6", "width SIGMA must be in"),
    ("bump:0.01:0.2:1e9", "bump centre MU"),
    ("sine:0.01:3:400", "PHASE_DEG must be within"),
])
def test_roads_beyond_the_limits_are_refused(spec, fragment):
    with pytest.raises(RoadError, match=fragment):
        Road.parse(spec)


@pytest.mark.parametrize("xs, ys, row, fragment", [
    ([0, 1, 1], [0, 0, 0], 2, "strictly increasing"),
    ([0, 1, 2], [0, math.nan, 0], 1, "y must be a finite number"),
    ([0, math.inf], [0, 0], 1, "x must be a finite number"),
    ([0, 2e4], [0, 0], 1, "within \\+-10000 m"),
    ([0], [0], None, "2 to 100000 points"),
    (range(100_001), [0] * 100_001, None, "2 to 100000 points"),
])
def test_a_bad_profile_names_its_row(xs, ys, row, fragment):
    with pytest.raises(RoadError, match=fragment) as info:
        Road.from_points(xs, ys)
    assert info.value.row == row


def test_load_dependence_is_held_beyond_the_load_range(p):
    """Beyond Fz_max, eqs. (47)-(52) see the load held at the bound (MF 6.1's FZMAX): slip stiffness
    and force stay those of the bound, and the slope test above holds there too."""
    fz_max = p[P.FZ_MAX]
    for fz in (1.5 * fz_max, 4.0 * fz_max):
        assert slip_stiffness(fz, p) == slip_stiffness(fz_max, p)
        for kappa in (-0.5, 0.05, 0.3):
            assert magic_formula(fz, kappa, p) == magic_formula(fz_max, kappa, p)
    assert slip_stiffness(0.999 * fz_max, p) < slip_stiffness(fz_max, p)   # the fit is still used below it
    # inside the range the fit is used as printed: eq. (50) at 3000 N
    dfz = (3000.0 - 1600.0) / 1600.0
    assert slip_stiffness(3000.0, p) == pytest.approx(3000.0 * (25.939 - 4.2327 * dfz) * math.exp(0.33686 * dfz))


@pytest.mark.slow
def test_slip_stiffness_and_peak_force_stay_positive_for_any_load_a_simulation_reaches(vehicle, p):
    """The largest rear loads of the roughest runs (Table 14's geometry 2 on sine:0.04:2, where the
    rear tyre bottoms, and 20 random designs there and on bump:0.04:0.2): K_xk > 0, a positive
    peak force D_x and E_x < 1 (so F_x has the sign of kappa') at every load up to 1.5 times it."""
    rng = np.random.default_rng(12)
    designs = [Design.from_deg(270, 0.15, 0.05)] + [
        Design(rng.uniform(0, 2 * np.pi), rng.uniform(0, 0.2), rng.uniform(0.05, 0.15)) for _ in range(20)]
    settings = SimSettings(max_airborne_time=3.5)  # hopping designs run to the end too
    runs = [simulate(d, Road.parse(spec), settings, vehicle)
            for d in designs for spec in ("sine:0.04:2", "bump:0.04:0.2")]
    assert all(r.ok for r in runs), [r.reason for r in runs if not r.ok]
    reached = max(r.fz_rear_max_n for r in runs)
    print(f"largest rear load reached: {reached:.0f} N ({reached / 1600:.1f} F_z0)")
    assert reached > p[P.FZ_MAX]   # the range is reached: the bound matters
    for fz in np.linspace(1.0, 1.5 * reached, 400):
        dfz = load_increment(fz, p)
        mux = p[P.PDX1] + p[P.PDX2] * dfz
        for sgn in (-1.0, 1.0):
            ex = (p[P.PEX1] + p[P.PEX2] * dfz + p[P.PEX3] * dfz * dfz) * (1.0 - p[P.PEX4] * sgn)
            assert ex < 1.0
        assert slip_stiffness(fz, p) > 0.0 and mux > 0.0
        assert magic_formula(fz, 0.1, p) > 0.0 > magic_formula(fz, -0.1, p)
        assert magic_formula(fz, 3.0, p) > 0.0 > magic_formula(fz, -3.0, p)   # far past the peak too


def test_a_run_that_leaves_a_profile_fails_naming_it() -> None:
    """Beyond its ends a profile is held level, a road nobody measured: a run that starts before its
    first point or ends past its last fails with the reason; one on it drives as on the same flat road."""
    design = Design.from_deg(0.0, 0.0, 0.093)
    flat = simulate(design, Road(), SimSettings())
    on = simulate(design, Road.from_points([-1.0, 40.0], [0.0, 0.0], name="level"), SimSettings())
    assert on.status == "ok" and on.distance_m == pytest.approx(flat.distance_m, abs=1e-3)
    front_end = flat.distance_m + 1.0  # the front tyre is a wheelbase (> 1 m) ahead of the rear one
    short = simulate(design, Road.from_points([-1.0, front_end], [0.0, 0.0], name="kerb"), SimSettings())
    assert short.status == "failed" and "past the end of road profile 'kerb'" in short.reason
    assert f"at x = {front_end:g} m" in short.reason and math.isnan(short.fitness_m)
    late = simulate(design, Road.from_points([0.5, 40.0], [0.0, 0.0], name="late"), SimSettings())
    assert late.status == "failed" and "road profile 'late' starts at x = 0.5 m" in late.reason
    assert simulate(design, Road.from_points([0.0, 40.0], [0.0, 0.0]), SimSettings()).status == "ok"


def test_a_tyre_pulls_only_through_its_damper(vehicle) -> None:
    """Eqs. (36)-(37) as printed: in contact the tyre's force k d - c r' goes negative while it springs
    back faster than k d / c (the negative minimum loads on rough roads); without the tyre dampers the
    smallest load is 0 (airborne), never below."""
    design, road = Design.from_deg(270, 0.15, 0.05), Road.parse("sine:0.04:2")
    settings = SimSettings(max_airborne_time=3.5)
    damped = simulate(design, road, settings, vehicle)
    undamped = simulate(design, road, settings, vehicle.replace(c_rt=0.0, c_ft=0.0))
    assert damped.ok and undamped.ok
    assert min(damped.fz_rear_min_n, damped.fz_front_min_n) < -1.0
    assert undamped.fz_rear_min_n == 0.0 and undamped.fz_front_min_n == 0.0


def test_an_airborne_tyre_relaxes_without_slip_when_the_vehicle_says_so(vehicle) -> None:
    """tyre_airborne_relax = 1: off the road eq. (42) loses its slip forcing, u' = -|V_x| u / sigma*
    (on the road it is unchanged). Geometry 2 hopping on sine:0.04:2: the landing slip falls from
    eq. (42)'s wound-up 8 to below 1, the carcass returns less energy it was never given, and the
    ledger closes as well (3x its measured 1.6e-4)."""
    from finaldrive.engine.model.elements import AUX_DUDT, AUX_RE, N_AUX, rear_tyre
    from finaldrive.engine.simulation import pack_parameters

    relax = vehicle.replace(tyre_airborne_relax=1.0)
    design = Design.from_deg(270, 0.15, 0.05)
    vx, omega, u, sigma = 12.0, 60.0, 0.01, 0.3
    for v in (vehicle, relax):
        p = pack_parameters(v, design, SimSettings())
        for airborne, rt in ((True, p[P.RT0] + 0.01), (False, p[P.RT0] - 0.02)):
            aux = np.zeros(N_AUX)
            rear_tyre(rt, 0.0, vx, omega, u, sigma, p, True, aux)
            slip = 0.0 if (airborne and v is relax) else vx - aux[AUX_RE] * omega   # V_sx, eq. (40)
            assert aux[AUX_DUDT] == pytest.approx(-slip - abs(vx) * u / sigma, rel=1e-12)
    road, settings = Road.parse("sine:0.04:2"), SimSettings(max_airborne_time=3.5)
    paper, relaxed = simulate(design, road, settings, vehicle), simulate(design, road, settings, relax)
    assert relaxed.ok and relaxed.airborne_rear_s > 0.5
    assert paper.slip_max > 5.0 and relaxed.slip_max < 1.0
    assert paper.tyre_carcass_energy_j < relaxed.tyre_carcass_energy_j < 0.5 * abs(paper.tyre_carcass_energy_j)
    assert abs(relaxed.ledger_residual_j) < 3 * 1.6e-4 * relaxed.drive_work_j
