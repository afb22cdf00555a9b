"""Kinematics over the rear travel: against the paper (Table 14), `finaldrive geometry` at each pose,
closed forms of the chain run and the squat point, and the squat a simulation shows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings, drive_squat, static_geometry, travel_kinematics

GEOMETRY1 = Design.from_deg(0.0, 0.0, 0.093)        # Table 14, geometry 1: SR 1.092
OFFSET = Design.from_deg(195.3, 0.037, 0.088)       # Table 11 flat-road optimum


def test_geometry1_passes_the_paper_sr_at_the_design_pose(vehicle, tables):
    sr_paper = tables["table14_geometries"]["geometry1"]["SR"]
    t = travel_kinematics(GEOMETRY1, vehicle, 41)
    assert t["design_pose"]["squat_ratio"] == pytest.approx(sr_paper, abs=0.01)
    travel = [c["travel_m"] for c in t["curve"]]
    sr = [c["squat_ratio"] for c in t["curve"]]
    assert travel[0] < t["design_pose"]["travel_m"] < travel[-1]
    assert np.interp(t["design_pose"]["travel_m"], travel, sr) == pytest.approx(sr_paper, abs=0.01)


@pytest.mark.parametrize("design", [GEOMETRY1, OFFSET])
def test_each_point_is_finaldrive_geometry_at_that_pose(vehicle, design):
    t = travel_kinematics(design, vehicle, 5)
    for point in [*t["curve"], t["design_pose"]]:
        at_pose = vehicle.replace(phi0=vehicle["theta0"] + math.radians(point["swingarm_angle_deg"]))
        assert point["squat_ratio"] == pytest.approx(static_geometry(design, at_pose)["squat_ratio"], rel=1e-12)


def test_travel_ends_spring_free_length_and_wheel_travel(vehicle):
    t = travel_kinematics(OFFSET, vehicle, 3)
    ext, comp = math.radians(t["extension_angle_deg"]), math.radians(t["compression_angle_deg"])
    x3, y3 = vehicle["L3"] * math.cos(vehicle["a3"]), vehicle["L3"] * math.sin(vehicle["a3"])
    spring = math.hypot(x3 - vehicle["L7"] * math.cos(ext), y3 - vehicle["L7"] * math.sin(ext))   # eq. (13)
    assert spring == pytest.approx(vehicle["s_rs"], abs=1e-12)
    lift = vehicle["L_SA"] * (math.sin(comp) - math.sin(ext))
    assert lift == pytest.approx(vehicle["rear_wheel_travel"], abs=1e-12)
    assert t["curve"][0]["travel_m"] == 0.0
    assert t["curve"][-1]["travel_m"] == pytest.approx(vehicle["rear_wheel_travel"], abs=1e-12)
    assert 0 < t["static_sag"]["travel_m"] < vehicle["rear_wheel_travel"]


def test_chain_growth_is_the_closed_form_external_tangent(vehicle):
    """Upper run = sqrt(d^2 - (R_WS - R_ES)^2), d the sprocket centre distance (law of cosines)."""
    d_ = OFFSET
    res = d_.rws / vehicle["sprocket_ratio"]

    def run(angle: float) -> float:
        d2 = d_.l2**2 + vehicle["L_SA"] ** 2 - 2 * d_.l2 * vehicle["L_SA"] * math.cos(angle - d_.a2)
        return math.sqrt(d2 - (d_.rws - res) ** 2)

    t = travel_kinematics(d_, vehicle, 7)
    base = run(math.radians(t["extension_angle_deg"]))
    growth = [c["chain_growth_m"] for c in t["curve"]]
    for c in t["curve"]:
        angle = math.radians(c["swingarm_angle_deg"])
        assert c["taut_length_m"] == pytest.approx(run(angle), abs=1e-12)
        assert c["chain_growth_m"] == pytest.approx(run(angle) - base, abs=1e-12)
    assert max(abs(g) for g in growth) > 1e-4          # an offset sprocket does grow the chain


def test_concentric_squat_point_is_the_mirrored_axle(vehicle):
    """With L2 = 0 and R_WS = 2 R_ES the upper run meets the swingarm line at the circles' external
    centre of similitude, the rear axle mirrored through the pivot: tan(tau) in closed form."""
    t = travel_kinematics(GEOMETRY1, vehicle, 5)
    tan_sigma = vehicle["target_cog_height"] / t["wheelbase_m"]
    for c in t["curve"]:
        phi = math.radians(c["swingarm_angle_deg"])
        ax, ay = vehicle["L_SA"] * math.cos(phi), vehicle["L_SA"] * math.sin(phi)
        tan_tau = (-ay - (ay - vehicle["rt0"])) / (-ax - ax)
        assert c["squat_ratio"] == pytest.approx(vehicle["squat_K"] / tan_tau, rel=1e-9)
        assert c["anti_squat_pct"] == pytest.approx(100 * tan_tau / tan_sigma, rel=1e-9)
        assert c["chain_growth_m"] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(("a2_deg", "squats"), [(90.0, True), (270.0, False)])
def test_simulated_squat_follows_the_static_anti_squat(vehicle, a2_deg, squats):
    """Below 100 % anti-squat the rear compresses under drive, above it extends (0.5 s, flat road)."""
    design = Design.from_deg(a2_deg, 0.1, 0.088)
    sag = travel_kinematics(design, vehicle, 2)["static_sag"]
    assert (sag["anti_squat_pct"] < 100) is squats
    d = drive_squat(design, Road(), SimSettings(duration=0.5), vehicle)
    assert d["status"] == "ok"
    assert d["travel_static_m"] == pytest.approx(sag["travel_m"], abs=1e-6)   # the same static equilibrium
    assert (d["squat_mean_m"] > 0) is squats


def test_the_leverage_ratio_integrates_to_the_springs_stroke(vehicle):
    """Wheel travel per unit of spring travel, integrated over the wheel's travel, gives back the spring's
    stroke: from s_rs at full extension (Table 5) to its length at full compression."""
    t = travel_kinematics(OFFSET, vehicle, 201)
    travel = np.array([c["travel_m"] for c in t["curve"]])
    leverage = np.array([c["leverage_ratio"] for c in t["curve"]])
    stroke = np.trapezoid(1.0 / leverage, travel)
    assert t["curve"][0]["spring_length_m"] == pytest.approx(vehicle["s_rs"], abs=1e-12)
    assert stroke == pytest.approx(vehicle["s_rs"] - t["curve"][-1]["spring_length_m"], rel=1e-6)
    assert 2.0 < leverage.min() < leverage.max() < 5.0   # Table 4's shock, near the pivot


def test_anti_rise_is_the_pivot_line_over_the_centre_of_mass_line(vehicle):
    """Closed form at each pose (chassis at theta0 = 0): the pivot at the origin, the rear contact point
    rt0 below the axle at L_SA along the swingarm; the kickback is the growth over R_WS."""
    t = travel_kinematics(OFFSET, vehicle, 5)
    tan_sigma = vehicle["target_cog_height"] / t["wheelbase_m"]
    for c in [*t["curve"], t["design_pose"]]:
        phi = math.radians(c["swingarm_angle_deg"])
        ax, ay = vehicle["L_SA"] * math.cos(phi), vehicle["L_SA"] * math.sin(phi)
        assert c["anti_rise_pct"] == pytest.approx(100 * (0 - (ay - vehicle["rt0"])) / (0 - ax) / tan_sigma, rel=1e-9)
        assert c["kickback_deg"] == pytest.approx(math.degrees(c["chain_growth_m"] / OFFSET.rws), abs=1e-12)


def test_teeth_and_links(vehicle):
    """A wheel sprocket of exactly 42 teeth's pitch radius has 42; the chain's links agree with the roller
    chain's textbook length, 2C/p + (N1 + N2)/2 + ((N2 - N1)/2 pi)^2 p/C, plus the free play's slack
    (the slack run pushed chain_free_play to the side at its middle: two straight halves) and what the
    model's pitch circles add to the textbook's polygons, about half of each sprocket's 2 pi R - N p =
    N p (pi^2 / 6 N^2): (pi^2 / 12)(1/N1 + 1/N2) links."""
    p = vehicle["chain_pitch"]
    design = Design.from_deg(195.3, 0.037, p / (2 * math.sin(math.pi / 42)))
    t = travel_kinematics(design, vehicle, 2)
    assert t["wheel_sprocket_teeth"] == pytest.approx(42.0, abs=1e-9)
    n1, n2 = t["engine_sprocket_teeth"], t["wheel_sprocket_teeth"]
    c = t["design_pose"]["centre_distance_m"]
    textbook = 2 * c / p + (n1 + n2) / 2 + ((n2 - n1) / (2 * math.pi)) ** 2 * p / c
    taut = t["design_pose"]["taut_length_m"]
    slack = math.sqrt(taut**2 + vehicle["chain_free_play"] ** 2) - taut
    circles = math.pi**2 / 12 * (1 / n1 + 1 / n2)
    assert t["chain_links"] - textbook == pytest.approx(slack / p + circles, abs=0.005)


def test_anti_dive_is_the_braking_force_along_the_fork_over_the_load_transfer(vehicle):
    """Virtual work through the model's kinematics (eqs. 14-16): the front contact point's motion per unit
    of fork slide gives each force's share along the fork; a braking force F (rearward at the front
    contact point) against the load transfer F tan(sigma) it brings (upward). Negative: a telescopic fork
    dives more than the load transfer alone makes it; the fork is the same for every design."""
    from finaldrive.engine.model.coordinates import ALPHA, BETA, FS, PHI, THETA, X1, X13, Y1, Y13
    from finaldrive.engine.model.kinematics import assemble, design_pose
    from finaldrive.engine.simulation import pack_parameters

    t = travel_kinematics(OFFSET, vehicle, 2)
    p = pack_parameters(vehicle, OFFSET, SimSettings())
    q = design_pose(p)
    h = 1e-6
    up, down = (assemble(p, Road(), q[X1], q[Y1], q[THETA], q[PHI], q[FS] + s, q[BETA], q[ALPHA]) for s in (h, -h))
    dx, dy = (up[X13] - down[X13]) / (2 * h), (up[Y13] - down[Y13]) / (2 * h)   # per unit of fork extension
    tan_sigma = vehicle["target_cog_height"] / t["wheelbase_m"]
    brake, transfer = -1.0 * dx, tan_sigma * dy          # generalised forces on the slide, F = 1 N
    assert t["anti_dive_pct"] == pytest.approx(-100.0 * brake / transfer, rel=1e-6)
    assert t["fork_angle_deg"] == pytest.approx(math.degrees(math.atan2(dx, -dy)), abs=1e-6)
    assert 15.0 < t["fork_angle_deg"] < 35.0 and t["anti_dive_pct"] < 0.0   # a motorcycle's rake: pro-dive
    other = travel_kinematics(Design.from_deg(10.0, 0.15, 0.12), vehicle, 2)
    assert other["anti_dive_pct"] == t["anti_dive_pct"]
