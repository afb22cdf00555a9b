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
    assert len(entries) == 104
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
    (lambda p: p["geometry"]["L3"].update(value=10**400), "L3.*must be finite, got an integer beyond"),
    (lambda p: p["inertia"]["m_chassis"].update(value=1e300), "m_chassis.*magnitude must be <= 1e\\+10"),
    (lambda p: p["inertia"]["I_sprocket"].update(value=1e-300), "I_sprocket.*must be >= 1e-09"),
    (lambda p: p["design_limits"].pop("l2_max"), "l2_max.*missing"),
    (lambda p: p["design_limits"]["rws_tyre_margin"].update(value=0.3), "rws_tyre_margin"),
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
    limits = set(data["parameters"]["design_limits"])
    kinematic = set(data["parameters"]["kinematics"])  # read by engine.travel, not packed
    model_keys = [k for k in keys if not k.startswith(("target_", "calibration_")) and k not in limits | kinematic]
    slots = [getattr(P, key.upper()) for key in model_keys]
    assert sorted(slots) == list(range(P.N_VEHICLE))
    vehicle = default_vehicle()
    packed = vehicle.packed()
    for key, slot in zip(model_keys, slots, strict=True):
        assert packed[slot] == vehicle[key]


def test_designs_are_held_to_the_vehicles_limits() -> None:
    from finaldrive.engine import Design, DesignError, Road, simulate, static_geometry

    v = default_vehicle()
    assert v.design_limits() == {"l2_m": 0.2, "rws_m": 0.2}
    v.check_design(Design.from_deg(0, 0.2, 0.2))
    for design, fragment in ((Design.from_deg(0, 0.21, 0.09), "l2 = 0.21 m: must be <= l2_max = 0.2 m"),
                             (Design.from_deg(0, 0.1, 0.25), "rws = 0.25 m: must be <= 0.2 m")):
        with pytest.raises(DesignError, match=fragment):
            v.check_design(design)
        with pytest.raises(DesignError, match=fragment):
            static_geometry(design, v)
        result = simulate(design, Road())
        assert result.status == "failed" and result.reason.startswith("invalid design")
    roomy = v.replace(l2_max=0.5, rws_tyre_margin=0.0)
    assert roomy.design_limits() == {"l2_m": 0.5, "rws_m": 0.3}
