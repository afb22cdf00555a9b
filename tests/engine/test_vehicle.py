"""Vehicle files: the default loads; a bad file is refused naming the key."""

from __future__ import annotations

import json

import pytest

from finaldrive.engine import VehicleError, default_vehicle, load_vehicle, load_vehicle_dict


def test_every_default_value_has_a_unit_and_a_source():
    d = default_vehicle().to_dict()
    entries = [e for group in d["parameters"].values() for e in group.values()]
    assert len(entries) == 68
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
    with pytest.raises(VehicleError, match="missing.json"):
        load_vehicle(tmp_path / "missing.json")


def test_replace_changes_the_fingerprint():
    v = default_vehicle()
    assert v.replace(torque=100.0).fingerprint() != v.fingerprint()
