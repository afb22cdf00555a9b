"""Suspension travel stops (vehicle ``suspension_stops = 1``): springs that push only, top-out and
bump stops; the force against its energy, the ledger with the stops engaged, and what they change
on the paper's designs (nothing, but for Table 14's geometry 2). docs/engine.md#suspension-travel-stops."""

from __future__ import annotations

import json

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings, simulate
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import FS, RS
from finaldrive.engine.model.elements import spring_energy, spring_force
from finaldrive.engine.model.rear_travel import compressed_spring_length
from finaldrive.engine.setup import pack_parameters
from finaldrive.engine.vehicle import VehicleError, load_vehicle_dict

GEOMETRY1 = Design.from_deg(0.0, 0.0, 0.093)
GEOMETRY2 = Design.from_deg(270.0, 0.15, 0.050)
TABLE11 = Design.from_deg(195.3, 0.037, 0.088)
#: |ledger residual| / drive work of geometry 2 on sine:0.08:3 with the stops, measured 2026-12-05
#: as tests/engine/test_energy.py's (its fork reaches both stops, the rear spring its top-out).
MEASURED_CLOSURE = 1.3e-4


@pytest.fixture
def stops(vehicle):
    return vehicle.replace(suspension_stops=1.0)


@pytest.mark.parametrize("on", [0.0, 1.0])
def test_spring_force_is_minus_the_slope_of_its_energy(vehicle, on):
    """Central differences of spring_energy at lengths in every regime (below the bump length, between,
    beyond the unloaded length), for both springs; without the stops, the paper's -k (l - s) exactly."""
    p = pack_parameters(vehicle.replace(suspension_stops=on), TABLE11, SimSettings())
    p[P.RS_BUMP] = compressed_spring_length(vehicle)
    p[P.FS_BUMP] = vehicle["s_fs"] - vehicle["fork_travel"]
    h = 1e-7
    for k, s, bump in ((p[P.K_RS], p[P.S_RS], p[P.RS_BUMP]), (p[P.K_FS], p[P.S_FS], p[P.FS_BUMP])):
        for length in np.linspace(bump - 0.02, s + 0.02, 41):
            if min(abs(length - s), abs(length - bump)) < 10 * h:
                continue  # a kink inside the difference
            slope = (spring_energy(length + h, k, s, bump, p) - spring_energy(length - h, k, s, bump, p)) / (2 * h)
            force = spring_force(length, k, s, bump, p)
            assert force == pytest.approx(-slope, rel=1e-6, abs=1e-3)
            if not on:
                assert force == -k * (length - s)
            elif length > s:
                assert force == pytest.approx(-p[P.K_STOP] * (length - s))  # the top-out stop, not the spring
            elif length < bump:
                assert force > -k * (length - s)                            # the bump stop adds


def test_the_ledger_closes_with_every_stop_engaged(vehicle, stops):
    """Geometry 2 on sine:0.08:3: the fork reaches its bump stop and its top-out, the rear spring its
    top-out; energy in, stored and dissipated still balance (3x the measured closure)."""
    r = simulate(GEOMETRY2, Road.parse("sine:0.08:3"), SimSettings(series=True, series_stride=1), stops)
    assert r.ok, r.reason
    q = r.series["q"]
    assert q[:, FS].min() < vehicle["s_fs"] - vehicle["fork_travel"]      # the fork's bump stop
    assert q[:, FS].max() > vehicle["s_fs"] and q[:, RS].max() > vehicle["s_rs"]  # both top-outs
    assert q[:, RS].max() - vehicle["s_rs"] < 0.005 and q[:, FS].max() - vehicle["s_fs"] < 0.005  # held there
    assert abs(r.ledger_residual_j) < 3 * MEASURED_CLOSURE * r.drive_work_j


def test_geometry_2s_rear_spring_no_longer_pulls(vehicle, stops):
    """The issue's case: geometry 2 on sine:0.04:3 has its rear spring beyond its unloaded length most
    of the run; the paper's spring pulls it back (up to kN), the stops hold it at full extension. The
    23 paper optima and geometry 1 never reach a stop: their results are bit-identical."""
    road = Road.parse("sine:0.04:3")
    paper = simulate(GEOMETRY2, road, SimSettings(series=True, series_stride=1), vehicle)
    held = simulate(GEOMETRY2, road, SimSettings(series=True, series_stride=1), stops)
    extended = paper.series["q"][:, RS] > vehicle["s_rs"]
    pull = vehicle["k_rs"] * (paper.series["q"][extended, RS] - vehicle["s_rs"])
    assert extended.mean() > 0.5 and pull.max() > 1000.0               # the paper's spring pulls, > 1 kN
    assert held.series["q"][:, RS].max() - vehicle["s_rs"] < 0.005     # the top-out holds it
    assert held.distance_m != paper.distance_m
    for design, spec in ((GEOMETRY1, "sine:0.04:3"), (TABLE11, "flat"), (Design.from_deg(371.0, 0.2, 0.05),
                                                                         "sine:0.04:2")):
        a = simulate(design, Road.parse(spec), SimSettings(), vehicle)
        b = simulate(design, Road.parse(spec), SimSettings(), stops)
        assert (a.fitness_m, a.distance_m) == (b.fitness_m, b.distance_m)


def test_a_vehicle_file_without_the_stops_is_the_papers_and_bad_values_are_named(vehicle):
    data = vehicle.to_dict()
    for key in ("suspension_stops", "k_stop", "fork_travel"):
        del data["parameters"]["suspension"][key]
    old = load_vehicle_dict(json.loads(json.dumps(data)))
    assert old["suspension_stops"] == 0.0 and old.packed().tolist() == vehicle.packed().tolist()
    assert "absent from the file" in dict(old.sources)["suspension_stops"]
    with pytest.raises(VehicleError, match="suspension_stops"):
        vehicle.replace(suspension_stops=0.5)
    with pytest.raises(VehicleError, match="fork_travel"):
        vehicle.replace(fork_travel=vehicle["s_fs"])
