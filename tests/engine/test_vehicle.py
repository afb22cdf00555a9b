"""Vehicle files: the default loads; a bad file is refused naming the key."""

from __future__ import annotations

import json
from importlib import resources

import pytest

from finaldrive.engine import VehicleError, default_vehicle, load_vehicle, load_vehicle_dict
from finaldrive.engine.vehicle import PARAMETERS


def test_every_default_value_has_a_unit_and_a_source():
    d = default_vehicle().to_dict()
    entries = [e for group in d["parameters"].values() for e in group.values()]
    assert len(entries) == 74
    assert all(e["source"] and e["unit"] for e in entries)


def _with(change):
    d = default_vehicle().to_dict()
    change(d["parameters"])
    return d


@pytest.mark.parametrize("change, key", [
    (lambda p: p["inertia"].pop("m_chassis"), "m_chassis"),
    (lambda p: p["inertia"]["m_swingarm"].update(value=-10.0), "m_swingarm"),
    (lambda p: p["suspension"]["k_rs"].update(value=0), "k_rs"),
    (lambda p: p["tyre"]["pKx1"].update(value="25,939"), "pKx1"),
    (lambda p: p["relaxation"]["sigma_min"].update(value=1.0), "sigma_min"),
    (lambda p: p["geometry"].update(L99={"value": 1.0}), "L99"),
    (lambda p: p["suspension"]["c_rs"].update(value=float("nan")), "c_rs"),
    (lambda p: p["tyre"]["Fz_max"].update(value=1000.0), "Fz_max"),            # below Fz0
    (lambda p: p["tyre"]["fx_lever_loaded"].update(value=1.5), "fx_lever_loaded"),
    (lambda p: p["suspension"]["rt_bottoming"].update(value=0.3), "rt_bottoming"),  # the whole radius
])
def test_bad_values_name_the_key(change, key):
    with pytest.raises(VehicleError, match=key):
        load_vehicle_dict(_with(change))


def test_file_round_trip_and_malformed_json(tmp_path):
    path = tmp_path / "bike.json"
    path.write_text(json.dumps(default_vehicle().to_dict()))
    assert load_vehicle(path) == default_vehicle()
    assert load_vehicle(path).fingerprint() == default_vehicle().fingerprint()
    path.write_text("{ not json")
    with pytest.raises(VehicleError, match="not valid JSON"):
        load_vehicle(path)
    with pytest.raises(VehicleError, match=r"missing\.json"):
        load_vehicle(tmp_path / "missing.json")


def test_replace_changes_the_fingerprint():
    v = default_vehicle()
    assert v.replace(torque=100.0).fingerprint() != v.fingerprint()


def test_the_parameter_layout_is_generated_from_the_one_list() -> None:
    from finaldrive.engine.model import params as P
    from finaldrive.engine.model.params_layout import path, render

    assert path().read_text() == render(), "run: python -m finaldrive.engine.model.params_layout"
    assert tuple(key for key, _ in PARAMETERS) == P.VEHICLE_KEYS


def test_every_key_of_the_vehicle_file_maps_to_exactly_one_slot() -> None:
    import json

    from finaldrive.engine.model import params as P

    data = json.loads(resources.files("finaldrive.engine").joinpath("data/vehicle.json").read_text())
    keys = [key for group in data["parameters"].values() for key in group]
    assert len(keys) == len(set(keys))
    kinematic = set(data["parameters"]["kinematics"])  # read by engine.travel, not packed
    model_keys = [k for k in keys if not k.startswith(("target_", "calibration_")) and k not in kinematic]
    slots = [getattr(P, key.upper()) for key in model_keys]
    assert sorted(slots) == list(range(P.N_VEHICLE))
    vehicle = default_vehicle()
    packed = vehicle.packed()
    for key, slot in zip(model_keys, slots, strict=True):
        assert packed[slot] == vehicle[key]
