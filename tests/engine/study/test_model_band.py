"""Model bands (engine.study.model_band): the designs under each documented modelling alternative,
checked against simulations of the changed vehicle or road and against what the changes must do."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import ALTERNATIVES, Design, Road, SimSettings, default_vehicle, enveloped, evaluate, model_bands
from finaldrive.engine.study.model_band import ENVELOPE_MARGIN_M, RUN_ACCELERATION_BOUND

DESIGNS = np.array([Design.from_deg(*d).row() for d in
                    [(195.3, 0.037, 0.088), (270.0, 0.15, 0.05), (0.0, 0.1, 0.1), (120.0, 0.05, 0.07)]])
SETTINGS = SimSettings(duration=1.0)


def test_each_alternative_is_the_changed_model_simulated() -> None:
    road, vehicle = Road.parse("sine:0.04:3"), default_vehicle()
    out = model_bands(DESIGNS, road, SETTINGS, vehicle)
    assert set(out["alternatives"]) == {a.name for a in ALTERNATIVES} and out["skipped"] == []
    assert out["baseline"]["rank_correlation"] == pytest.approx(1.0) and out["baseline"]["same_best"]
    low = evaluate(DESIGNS, road, SETTINGS, vehicle.replace(Fz_max=4800.0))
    assert out["alternatives"]["tyre_load_range_4800"]["fitness_m"] == low.fitness_m.tolist()
    shifted = evaluate(DESIGNS, Road.parse("sine:0.04:3:180"), SETTINGS, vehicle)
    assert out["alternatives"]["road_phase_180"]["fitness_m"] == shifted.fitness_m.tolist()
    assert out["alternatives"]["road_phase_180"]["road"] == "sine:0.04:3:180"
    launch = evaluate(DESIGNS, road, SETTINGS, vehicle.replace(drive_model=1.0))
    assert out["alternatives"]["drive_launch"]["fitness_m"] == launch.fitness_m.tolist()
    assert "drive_launch" in model_bands(DESIGNS[:1], road, SETTINGS, vehicle.replace(drive_model=1.0))["skipped"]
    spin = evaluate(DESIGNS, road, SETTINGS, vehicle.replace(front_wheel_spin=1.0))
    assert out["alternatives"]["front_wheel_spin"]["fitness_m"] == spin.fitness_m.tolist()
    chain = evaluate(DESIGNS, road, SETTINGS, vehicle.replace(chain_compliance=1.0))
    assert out["alternatives"]["chain_elastic"]["fitness_m"] == chain.fitness_m.tolist()
    ring = out["alternatives"]["road_enveloped"]
    assert ring["road"] == "profile:sine:0.04:3~ring0.3" and ring["failed"] == [""] * len(DESIGNS)
    covered = enveloped(road, vehicle["rt0"], -ENVELOPE_MARGIN_M, 0.5 * RUN_ACCELERATION_BOUND + ENVELOPE_MARGIN_M)
    assert ring["fitness_m"] == evaluate(DESIGNS, covered, SETTINGS, vehicle).fitness_m.tolist()
    for alt in out["alternatives"].values():
        assert alt["rank_correlation"] is None or -1.0 <= alt["rank_correlation"] <= 1.0


def test_what_the_changes_must_do_on_flat_ground() -> None:
    """Flat: no tyre load reaches 4.8 kN, so the lower load range changes nothing (to the bit); more
    drive torque takes every design further, less less far; a road phase and enveloping do not apply."""
    road = Road.parse("flat")
    base = evaluate(DESIGNS, road, SETTINGS)
    assert base.fz_rear_max_n.max() < 4800.0 and base.fz_front_max_n.max() < 4800.0
    out = model_bands(DESIGNS, road, SETTINGS)
    low = out["alternatives"]["tyre_load_range_4800"]
    assert low["largest_change_m"] == 0.0 and low["rank_correlation"] == pytest.approx(1.0)
    base_d = np.array(out["baseline"]["distance_m"])
    assert (np.array(out["alternatives"]["drive_double"]["distance_m"]) > base_d + 0.1).all()
    assert (np.array(out["alternatives"]["drive_half"]["distance_m"]) < base_d - 0.1).all()
    assert (np.array(out["alternatives"]["front_wheel_spin"]["distance_m"]) < base_d - 0.01).all()  # more inertia
    assert out["skipped"] == ["road_phase_90", "road_phase_180", "road_enveloped"]
