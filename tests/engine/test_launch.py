"""The launch drive (vehicle ``drive_model = 1``): the engine's torque curve through the primary and
first-gear ratios, the clutch slipping below launch_speed, a wheelie and a traction limit on the drive
force. The element against hand values, a run's torque against its limits at every step, the ledger
and the two methods with the drive on, and the vehicle file. docs/engine.md#the-launch-drive."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings, simulate, solve_torque
from finaldrive.engine.model import params as P
from finaldrive.engine.model.elements import engine_torque, launch_torque
from finaldrive.engine.setup import pack_parameters
from finaldrive.engine.vehicle import VehicleError, load_vehicle_dict

TABLE11 = Design.from_deg(195.3, 0.037, 0.088)
#: fast minus reference distance of TABLE11 with the launch drive, measured 2026-12-05 (flat; sine:0.04:3).
MEASURED_METHODS_M = {"flat": 2.92e-3, "sine:0.04:3": 4.59e-3}
#: |ledger residual| / drive work of TABLE11 on sine:0.08:3 with the launch drive (fast; reference),
#: measured 2026-12-05: the rear tyre leaves the road 1.9 s of the 3.5 s and the torque is cut each time.
MEASURED_CLOSURE = {"fast": 2.69e-4, "reference": 1.95e-4}


@pytest.fixture
def launch(vehicle):
    return vehicle.replace(drive_model=1.0)


def test_the_engine_curve_is_its_points_joined_held_below_and_cut_above(launch):
    p = pack_parameters(launch, TABLE11, SimSettings())
    speeds = [launch[f"engine_speed_{i}"] for i in range(1, 5)]
    torques = [launch[f"engine_torque_{i}"] for i in range(1, 5)]
    for n, t in zip(speeds, torques, strict=True):
        assert engine_torque(n, p) == pytest.approx(t, rel=1e-15)
    for i in range(3):  # half way between two points: their mean
        assert engine_torque(0.5 * (speeds[i] + speeds[i + 1]), p) == pytest.approx(0.5 * (torques[i] + torques[i + 1]))
    assert engine_torque(0.5 * speeds[0], p) == torques[0]          # held below the first point
    assert engine_torque(speeds[3] + 1.0, p) == 0.0                  # the rev limit


def test_the_clutch_the_limits_and_the_cut(launch):
    """At rest the clutch slips and passes the engine's torque at launch_speed; the torque is capped by
    the wheelie force and by tc_friction times the rear load (none with the rear tyre off the road);
    above launch_speed the engine turns with the sprocket."""
    p = pack_parameters(launch, TABLE11, SimSettings())
    ratio = launch["primary_ratio"] * launch["first_gear_ratio"]
    re, k = 0.3, launch["sprocket_ratio"]
    free = ratio * engine_torque(launch["launch_speed"], p)
    assert free == pytest.approx(1.596 * 2.615 * (100.0 + 46.0 * 3000.0 / 4200.0))  # 6,000 rpm on the curve
    uncapped = p.copy()
    uncapped[P.WHEELIE_FORCE] = 1e9
    assert launch_torque(0.0, 1e6, re, uncapped) == pytest.approx(free)
    assert launch_torque(0.0, 1e6, re, p) == pytest.approx(launch["wheelie_force"] * re / k)
    assert launch_torque(0.0, 500.0, re, p) == pytest.approx(launch["tc_friction"] * 500.0 * re / k)
    assert launch_torque(0.0, 0.0, re, p) == 0.0
    sprocket = 8000.0 / ratio * math.pi / 30.0                     # the engine at 8,000 rpm, clutch locked
    assert launch_torque(sprocket, 1e6, re, uncapped) == pytest.approx(ratio * engine_torque(8000.0, p))
    assert launch_torque(11001.0 / ratio * math.pi / 30.0, 1e6, re, uncapped) == 0.0


def test_a_launch_keeps_to_its_limits_at_every_step(vehicle, launch):
    """Table 11's design on sine:0.04:3: the recorded torque never asks more than the wheelie force or
    tc_friction times the rear load of the tyre (through R_WS / R_ES and R_e), is zero whenever the rear
    tyre is off the road, and equals the smallest of its limits while the clutch slips; the launch
    takes the bike further than the paper's 150 N m."""
    road = Road.parse("sine:0.04:3")
    r = simulate(TABLE11, road, SimSettings(series=True, series_stride=1), launch)
    assert r.ok, r.reason
    s = r.series
    torque, fz, re = s["drive_torque_nm"], s["fz_rear_n"], s["effective_radius_m"]
    k = launch["sprocket_ratio"]
    caps = np.minimum(launch["wheelie_force"], launch["tc_friction"] * np.maximum(fz, 0.0)) * re / k
    assert (torque <= caps * (1 + 1e-12)).all()
    assert (fz <= 0.0).any() and (torque[fz <= 0.0] == 0.0).all()
    ratio = launch["primary_ratio"] * launch["first_gear_ratio"]
    slipping = s["wheel_speed_rad_s"] * k * ratio * 30 / math.pi < 0.8 * launch["launch_speed"]  # clutch slips
    p = pack_parameters(launch, TABLE11, SimSettings())
    free = ratio * engine_torque(launch["launch_speed"], p)
    assert slipping.mean() > 0.3
    assert np.allclose(torque[slipping], np.minimum(caps[slipping], free), rtol=1e-12, atol=0.0)
    assert (torque[slipping] >= launch["wheelie_force"] * re[slipping] / k * (1 - 1e-12)).mean() > 0.2  # it binds
    paper = simulate(TABLE11, road, SimSettings(), vehicle)
    assert r.distance_m > paper.distance_m + 5.0


@pytest.mark.parametrize("method", ["fast", "reference"])
def test_the_ledger_closes_with_the_launch_drive(launch, method):
    """sine:0.08:3: the rear tyre leaves the road and the torque is cut and restored many times; the
    drive's work (the torque times the sprocket's speed, whatever the torque) still balances what is
    stored and dissipated, to 3x the measured closure."""
    r = simulate(TABLE11, Road.parse("sine:0.08:3"), SimSettings(method=method), launch)
    assert r.ok, r.reason
    assert r.airborne_rear_s > 1.0
    assert abs(r.ledger_residual_j) < 3 * MEASURED_CLOSURE[method] * r.drive_work_j


@pytest.mark.parametrize("road", sorted(MEASURED_METHODS_M))
def test_the_two_methods_agree_on_a_launch(launch, road):
    fast = simulate(TABLE11, Road.parse(road), SimSettings(), launch)
    ref = simulate(TABLE11, Road.parse(road), SimSettings(method="reference"), launch)
    assert fast.ok and ref.ok
    assert abs(fast.distance_m - ref.distance_m) < 3 * MEASURED_METHODS_M[road]


def test_a_vehicle_file_without_the_launch_is_the_papers_and_bad_values_are_named(vehicle):
    data = vehicle.to_dict()
    for key in [k for k in data["parameters"]["drive"] if k not in ("torque", "sprocket_ratio") and
                not k.startswith(("target", "calibration"))]:
        del data["parameters"]["drive"][key]
    old = load_vehicle_dict(json.loads(json.dumps(data)))
    assert old["drive_model"] == 0.0 and old.packed().tolist() == vehicle.packed().tolist()
    assert "absent from the file" in dict(old.sources)["engine_torque_2"]
    with pytest.raises(VehicleError, match="drive_model"):
        vehicle.replace(drive_model=0.5)
    with pytest.raises(VehicleError, match="engine_speed"):
        vehicle.replace(engine_speed_3=vehicle["engine_speed_2"])
    with pytest.raises(VehicleError, match="wheelie_force"):
        vehicle.replace(wheelie_force=0.0)
    with pytest.raises(VehicleError, match="drive_model"):  # the paper's torque: nothing to calibrate
        solve_torque(vehicle.replace(drive_model=1.0))
