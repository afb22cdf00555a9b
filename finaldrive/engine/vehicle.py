"""Vehicle parameters: the paper's bike by default, or a user's file of the same shape.

The file (engine/data/vehicle.json) groups parameters; each is ``{"value", "unit", "source"}``.
Loading validates every key: a missing key, a non-number, a value beyond :data:`VEHICLE_VALUE_LIMIT`,
or a physically impossible value (negative mass, zero stiffness, ...) raises :class:`VehicleError`
naming the key. The file also bounds the designs it can carry (group ``design_limits``, see
:meth:`Vehicle.check_design`).
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from finaldrive.engine.api import Design, DesignError

#: A rule: (lower bound, lower inclusive, upper bound); None = unbounded.
Rule = tuple[float | None, bool, float | None]
_POSITIVE = (0.0, False, None)
_NON_NEGATIVE = (0.0, True, None)
_FRACTION = (0.0, True, 1.0)
_ANY = (None, True, None)

#: Largest magnitude of any vehicle value (SI units): far above every parameter of a motorcycle
#: (docs/engine.md's Fz_max = 1e9 N, which switches the load range off, included), far below where
#: the model's arithmetic overflows. Positive values are also at least POSITIVE_MIN.
VEHICLE_VALUE_LIMIT = 1.0e10
POSITIVE_MIN = 1.0e-9

#: The model's vehicle parameters, in the order the compiled model packs them (engine.model.params is
#: generated from this list), each with its rule: (lower bound, lower inclusive, upper bound).
PARAMETERS: tuple[tuple[str, Rule], ...] = (
    ("L3", _NON_NEGATIVE), ("a3", _ANY), ("L4", _POSITIVE), ("a4", _ANY), ("L5", _POSITIVE), ("a5", _ANY),
    ("L7", _POSITIVE), ("L_SA", _POSITIVE), ("theta0", _ANY), ("phi0", _ANY), ("rt0", _POSITIVE),
    ("ft0", _POSITIVE), ("L8", _POSITIVE), ("k_rs", _POSITIVE), ("c_rs", _NON_NEGATIVE), ("s_rs", _POSITIVE),
    ("k_fs", _POSITIVE), ("c_fs", _NON_NEGATIVE), ("s_fs", _POSITIVE), ("k_rt", _POSITIVE),
    ("c_rt", _NON_NEGATIVE), ("rt_bottoming", _POSITIVE), ("k_rt_bottoming", _NON_NEGATIVE), ("k_ft", _POSITIVE),
    ("c_ft", _NON_NEGATIVE), ("m_chassis", _POSITIVE),
    ("I_chassis", _POSITIVE), ("m_swingarm", _POSITIVE), ("I_swingarm", _POSITIVE), ("m_sprocket", _POSITIVE),
    ("I_sprocket", _POSITIVE), ("m_rear_wheel", _POSITIVE), ("I_rear_wheel", _POSITIVE), ("m_fork", _POSITIVE),
    ("I_fork", _POSITIVE), ("m_front_wheel", _POSITIVE), ("swingarm_cog_fraction", _FRACTION),
    ("fork_cog_fraction", _FRACTION), ("chassis_cog_x", _ANY), ("chassis_cog_y", _ANY), ("pCx1", _POSITIVE),
    ("pDx1", _POSITIVE), ("pDx2", _ANY), ("pEx1", _ANY), ("pEx2", _ANY), ("pEx3", _ANY), ("pEx4", _ANY),
    ("pKx1", _POSITIVE), ("pKx2", _ANY), ("pKx3", _ANY), ("Fz0", _POSITIVE), ("Fz_min", _NON_NEGATIVE),
    ("Fz_max", _POSITIVE), ("fx_lever_loaded", _FRACTION), ("K_vlow0", _NON_NEGATIVE),
    ("sigma_k0", _POSITIVE), ("sigma_min", _POSITIVE), ("eps_F", _POSITIVE), ("V_low", _POSITIVE),
    ("torque", _ANY), ("sprocket_ratio", _POSITIVE), ("gravity", _POSITIVE), ("eps1", _NON_NEGATIVE),
    ("eps2", _NON_NEGATIVE), ("sr_optimum", _ANY), ("floor", _FRACTION), ("squat_K", _POSITIVE),
    ("chain_runs", (1.0, True, 2.0)), ("chain_free_play", _POSITIVE),
    ("suspension_stops", (0.0, True, 1.0)), ("k_stop", _NON_NEGATIVE), ("fork_travel", _POSITIVE),
    ("tyre_airborne_relax", (0.0, True, 1.0)),
    ("drive_model", (0.0, True, 1.0)), ("primary_ratio", _POSITIVE), ("first_gear_ratio", _POSITIVE),
    ("engine_speed_1", _POSITIVE), ("engine_speed_2", _POSITIVE), ("engine_speed_3", _POSITIVE),
    ("engine_speed_4", _POSITIVE), ("engine_torque_1", _NON_NEGATIVE), ("engine_torque_2", _NON_NEGATIVE),
    ("engine_torque_3", _NON_NEGATIVE), ("engine_torque_4", _NON_NEGATIVE), ("launch_speed", _POSITIVE),
    ("tc_friction", _POSITIVE), ("wheelie_force", _POSITIVE),
    ("I_front_wheel", _POSITIVE), ("front_wheel_spin", (0.0, True, 1.0)),
    ("chain_compliance", (0.0, True, 1.0)), ("k_chain", _POSITIVE), ("k_cush", _POSITIVE), ("c_cush", _NON_NEGATIVE),
)
#: The launch drive (docs/engine.md#the-launch-drive), added after files were written: (key, value, unit). A
#: file without them has the paper's constant torque (drive_model 0) and these values, engine/data/vehicle.json's.
LAUNCH_DEFAULTS: tuple[tuple[str, float, str], ...] = (
    ("drive_model", 0.0, "-"), ("primary_ratio", 1.596, "-"), ("first_gear_ratio", 2.615, "-"),
    ("engine_speed_1", 3000.0, "rpm"), ("engine_speed_2", 7200.0, "rpm"), ("engine_speed_3", 9500.0, "rpm"),
    ("engine_speed_4", 11000.0, "rpm"), ("engine_torque_1", 100.0, "N m"), ("engine_torque_2", 146.0, "N m"),
    ("engine_torque_3", 137.0, "N m"), ("engine_torque_4", 110.0, "N m"), ("launch_speed", 6000.0, "rpm"),
    ("tc_friction", 1.0, "-"), ("wheelie_force", 2400.0, "N"),
)
#: Parameters added after files were written: a file without one takes this (group, value, unit), the
#: model as it was before (the paper's springs and tyre, Table 8's smallest R_WS allowed), and says so
#: in its source.
ADDED_LATER: dict[str, tuple[str, float, str]] = {
    "suspension_stops": ("suspension", 0.0, "-"),
    "k_stop": ("suspension", 2.0e6, "N/m"),
    "fork_travel": ("suspension", 0.120, "m"),
    "tyre_airborne_relax": ("tyre", 0.0, "-"),
    **{key: ("drive", value, unit) for key, value, unit in LAUNCH_DEFAULTS},
    "I_front_wheel": ("inertia", 0.47, "kg m^2"),
    "front_wheel_spin": ("inertia", 0.0, "-"),
    "chain_compliance": ("chain", 0.0, "-"),
    "k_chain": ("chain", 2.0e6, "N/m"),
    "k_cush": ("chain", 3000.0, "N m/rad"),
    "c_cush": ("chain", 10.0, "N m s/rad"),
    "chain_pitch": ("design_limits", 0.015875, "m"),
    "min_sprocket_teeth": ("design_limits", 9.0, "-"),
}
_RULES: dict[str, Rule] = dict(PARAMETERS)
#: Calibration targets: validated and carried, not packed for the model.
_TARGET_RULES: dict[str, Rule] = {
    "target_rear_share": (0.0, False, 1.0),
    "target_cog_height": _POSITIVE,
    "target_distance": _POSITIVE,
    "calibration_a2_deg": _ANY,
    "calibration_l2": _NON_NEGATIVE,
    "calibration_rws": _POSITIVE,
}
#: Physical limits of a design on this vehicle (group ``design_limits``): validated and carried, not packed.
_LIMIT_RULES: dict[str, Rule] = {
    "l2_max": _POSITIVE,
    "rws_tyre_margin": _NON_NEGATIVE,
    "chain_pitch": _POSITIVE,
    "min_sprocket_teeth": (3.0, True, 1000.0),
}
#: Kinematic limits: validated and carried, read by engine.travel only (not packed for the model).
_KINEMATIC_RULES: dict[str, Rule] = {
    "rear_wheel_travel": _POSITIVE,
}


def sprocket_teeth(pitch_radius: float, pitch: float) -> float:
    """Teeth of a sprocket of ``pitch_radius`` for a chain of ``pitch``: R = p / (2 sin(pi / N)), solved
    for N (not rounded; 0 when the radius is below half a pitch, where no sprocket exists)."""
    if pitch_radius <= pitch / 2.0:
        return 0.0
    return math.pi / math.asin(pitch / (2.0 * pitch_radius))


class VehicleError(ValueError):
    """A vehicle file that is malformed or not physical; the message names the key."""


@dataclass(frozen=True)
class Vehicle:
    """Validated vehicle parameters (SI units), immutable and picklable."""

    name: str
    values: tuple[tuple[str, float], ...]
    units: tuple[tuple[str, str], ...]
    sources: tuple[tuple[str, str], ...]
    groups: tuple[tuple[str, str], ...]

    @cached_property
    def _by_key(self) -> dict[str, float]:
        """The values by name (built once: a run's setup reads several)."""
        return dict(self.values)

    @cached_property
    def _packed(self) -> np.ndarray:
        v = self._by_key
        return np.array([v[k] for k, _ in PARAMETERS], dtype=float)

    def __getitem__(self, key: str) -> float:
        return self._by_key[key]

    def packed(self) -> np.ndarray:
        """The vehicle part of the model's parameter vector P (see engine.model.params), a new array."""
        return self._packed.copy()

    def replace(self, **changes: float) -> Vehicle:
        """A copy with some values changed (validated)."""
        d = self.to_dict()
        for key, value in changes.items():
            group = dict(self.groups).get(key)
            if group is None:
                raise VehicleError(f"unknown vehicle parameter {key!r}")
            d["parameters"][group][key]["value"] = value
        return load_vehicle_dict(d)

    def design_limits(self) -> dict[str, float]:
        """The largest L2 and R_WS a design may have on this vehicle [m]: L2 <= l2_max (the room around
        the swingarm pivot), R_WS <= rt0 - rws_tyre_margin (the wheel sprocket inside the rear tyre)."""
        return {"l2_m": self["l2_max"], "rws_m": round(self["rt0"] - self["rws_tyre_margin"], 12)}

    def rws_min(self) -> float:
        """The smallest R_WS a design may have [m]: its engine sprocket (R_WS / sprocket_ratio) keeps
        ``min_sprocket_teeth`` teeth of the ``chain_pitch``."""
        res = self["chain_pitch"] / (2.0 * math.sin(math.pi / self["min_sprocket_teeth"]))
        return res * self["sprocket_ratio"]

    def check_design(self, design: Design) -> None:
        """Raise :class:`DesignError` naming the variable and the limit if ``design`` does not fit."""
        limits = self.design_limits()
        if design.l2 > limits["l2_m"]:
            raise DesignError(f"l2 = {design.l2:g} m: must be <= l2_max = {limits['l2_m']:g} m "
                              "(vehicle file, design_limits)")
        if design.rws < self.rws_min():
            res = design.rws / self["sprocket_ratio"]
            teeth = sprocket_teeth(res, self["chain_pitch"])
            pitch = f"{self['chain_pitch'] * 1e3:g} mm chain pitch"
            fits = (f"would have {teeth:.3g} teeth of the {pitch}, fewer than" if teeth else
                    f"is less than half the {pitch}: no sprocket fits (at least")
            raise DesignError(f"rws = {design.rws:g} m: the engine sprocket (R_ES = R_WS / {self['sprocket_ratio']:g} "
                              f"= {res:g} m) {fits} min_sprocket_teeth = {self['min_sprocket_teeth']:g}"
                              f"{')' if not teeth else ''} (vehicle file, design_limits)")
        if design.rws > limits["rws_m"]:
            raise DesignError(f"rws = {design.rws:g} m: must be <= {limits['rws_m']:g} m, the rear tyre's radius "
                              f"rt0 = {self['rt0']:g} m less rws_tyre_margin = {self['rws_tyre_margin']:g} m "
                              "(vehicle file)")

    def check_method(self, method: str) -> None:
        """Raise ValueError if the solver ``method`` cannot simulate this vehicle (the two-run chain
        and the elastic chain are modelled by the fast method only)."""
        if self["chain_runs"] == 2 and method == "reference":
            raise ValueError("vehicle chain_runs = 2 (both chain runs) is supported by the fast method only; "
                             "the reference method models the paper's upper run (chain_runs = 1)")
        if self["chain_compliance"] == 1 and method == "reference":
            raise ValueError("vehicle chain_compliance = 1 (the elastic chain and cush drive) is supported by the "
                             "fast method only; the reference method models the paper's rigid chain")

    def to_dict(self) -> dict[str, Any]:
        units, sources, groups = dict(self.units), dict(self.sources), dict(self.groups)
        out: dict[str, Any] = {"name": self.name, "parameters": {}}
        for key, value in self.values:
            out["parameters"].setdefault(groups[key], {})[key] = {
                "value": value, "unit": units[key], "source": sources[key]}
        return out

    def fingerprint(self) -> str:
        """sha256 of the parameter values (not names or sources): a cache key."""
        import hashlib  # here: OpenSSL's ~5 ms, which the static geometry never needs

        canon = json.dumps(sorted(self.values), separators=(",", ":"))
        return hashlib.sha256(canon.encode()).hexdigest()


def _check(key: str, raw: Any, rule: tuple[float | None, bool, float | None]) -> float:
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise VehicleError(f"vehicle parameter {key!r}: value must be a number, got {_show(raw)}")
    try:
        value = float(raw)
    except OverflowError:  # an integer beyond any float
        value = math.inf
    if not math.isfinite(value):
        raise VehicleError(f"vehicle parameter {key!r}: value must be finite, got {_show(raw)}")
    if abs(value) > VEHICLE_VALUE_LIMIT:
        raise VehicleError(f"vehicle parameter {key!r}: magnitude must be <= {VEHICLE_VALUE_LIMIT:g}, got {value:g}")
    lo, lo_inclusive, hi = rule
    if lo is not None and (value < lo or (value == lo and not lo_inclusive)):
        bound = ">=" if lo_inclusive else ">"
        raise VehicleError(f"vehicle parameter {key!r}: must be {bound} {lo:g}, got {value:g}")
    if hi is not None and value > hi:
        raise VehicleError(f"vehicle parameter {key!r}: must be <= {hi:g}, got {value:g}")
    if rule == _POSITIVE and value < POSITIVE_MIN:
        raise VehicleError(f"vehicle parameter {key!r}: must be >= {POSITIVE_MIN:g}, got {value:g}")
    return value


def _show(raw: Any) -> str:
    """A value for a message, never longer than 24 characters (an integer of any size included)."""
    text = repr(raw) if not isinstance(raw, int) or abs(raw) < 10**20 else f"an integer beyond {VEHICLE_VALUE_LIMIT:g}"
    return text if len(text) <= 24 else text[:21] + "..."


def load_vehicle_dict(data: Any) -> Vehicle:
    """Validate a parsed vehicle file."""
    if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict):
        raise VehicleError("vehicle file: top-level object with a 'parameters' object expected")
    found: dict[str, tuple[str, Any, str, str]] = {}
    for group, entries in data["parameters"].items():
        if not isinstance(entries, dict):
            raise VehicleError(f"vehicle group {group!r}: object expected")
        for key, entry in entries.items():
            if not isinstance(entry, dict) or "value" not in entry:
                raise VehicleError(f"vehicle parameter {key!r}: object with a 'value' expected")
            if key in found:
                raise VehicleError(f"vehicle parameter {key!r}: given twice")
            found[key] = (group, entry["value"], str(entry.get("unit", "")), str(entry.get("source", "")))
    rules = {**_RULES, **_TARGET_RULES, **_LIMIT_RULES, **_KINEMATIC_RULES}
    for key, (group, value, unit) in ADDED_LATER.items():
        found.setdefault(key, (group, value, unit, "absent from the file: the model as before (ADDED_LATER)"))
    for key in rules:
        if key not in found:
            raise VehicleError(f"vehicle parameter {key!r}: missing")
    for key in found:
        if key not in rules:
            raise VehicleError(f"vehicle parameter {key!r}: unknown key")
    values = tuple((k, _check(k, found[k][1], rules[k])) for k in rules)
    v = dict(values)
    if v["sigma_min"] > v["sigma_k0"]:
        raise VehicleError("vehicle parameter 'sigma_min': must not exceed sigma_k0")
    if not v["Fz_min"] < v["Fz0"] < v["Fz_max"]:
        raise VehicleError("vehicle parameter 'Fz_max': the load range Fz_min < Fz0 < Fz_max is required")
    if v["rt_bottoming"] >= v["rt0"]:
        raise VehicleError("vehicle parameter 'rt_bottoming': must be less than the unloaded radius rt0")
    if v["suspension_stops"] not in (0.0, 1.0):
        raise VehicleError("vehicle parameter 'suspension_stops': must be 0 (the paper's springs) or 1 (travel stops)")
    if v["tyre_airborne_relax"] not in (0.0, 1.0):
        raise VehicleError("vehicle parameter 'tyre_airborne_relax': must be 0 (eq. 42 as printed) or 1 (relaxed "
                           "while airborne)")
    if v["front_wheel_spin"] not in (0.0, 1.0):
        raise VehicleError("vehicle parameter 'front_wheel_spin': must be 0 (the paper: no front wheel rotation) or 1 "
                           "(the front wheel's inertia, rolling)")
    if v["drive_model"] not in (0.0, 1.0):
        raise VehicleError("vehicle parameter 'drive_model': must be 0 (the paper's constant torque) or 1 (the launch "
                           "drive)")
    speeds = [v[f"engine_speed_{i}"] for i in range(1, 5)]
    if any(b <= a for a, b in itertools.pairwise(speeds)):
        raise VehicleError("vehicle parameter 'engine_speed_4': engine_speed_1 < ... < engine_speed_4 is required")
    if v["fork_travel"] >= v["s_fs"]:
        raise VehicleError("vehicle parameter 'fork_travel': must be less than the fork's unloaded length s_fs")
    if v["chain_runs"] not in (1.0, 2.0):
        raise VehicleError("vehicle parameter 'chain_runs': must be 1 (the paper's upper run) or 2 (both runs)")
    if v["chain_compliance"] not in (0.0, 1.0):
        raise VehicleError("vehicle parameter 'chain_compliance': must be 0 (the paper's rigid chain) or 1 (the chain "
                           "and the cush drive elastic)")
    if v["chain_compliance"] == 1.0 and v["chain_runs"] == 2.0:
        raise VehicleError("vehicle parameter 'chain_compliance': the elastic chain is the paper's upper run made "
                           "elastic (chain_runs = 1); it is not combined with both runs (chain_runs = 2)")
    if v["rws_tyre_margin"] >= v["rt0"]:
        raise VehicleError("vehicle parameter 'rws_tyre_margin': must be less than the rear tyre's radius rt0")
    return Vehicle(
        name=str(data.get("name", "")),
        values=values,
        units=tuple((k, found[k][2]) for k in rules),
        sources=tuple((k, found[k][3]) for k in rules),
        groups=tuple((k, found[k][0]) for k in rules),
    )


def load_vehicle(path: str | Path) -> Vehicle:
    """Read and validate a vehicle JSON file."""
    try:
        data = json.loads(Path(path).read_text())
    except OSError as exc:
        raise VehicleError(f"vehicle file {str(path)!r}: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise VehicleError(f"vehicle file {str(path)!r}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    return load_vehicle_dict(data)


@lru_cache(maxsize=1)
def default_vehicle() -> Vehicle:
    """The paper's motorcycle (engine/data/vehicle.json)."""
    # read beside this module, not by importlib.resources (~10 ms of imports for `finaldrive geometry`): the
    # package is always installed as files
    text = (Path(__file__).parent / "data" / "vehicle.json").read_text()
    return load_vehicle_dict(json.loads(text))
