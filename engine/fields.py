"""One vocabulary for every output: each field's name, unit and meaning, and how people read it.

The rule, applied to the CLI (JSON, text, CSV), the API, the database and the recordings: a field
that carries a physical quantity ends in its unit (``_m``, ``_s``, ``_deg``, ``_n``, ``_nm``, ``_j``,
``_w``, ``_kg``, ``_rad_s``, ``_pct``, ``_bytes``, or a ratio such as ``_m_per_deg``); SI units,
but angles in degrees; ratios, counts and labels carry none. A quantity has one name and one unit
everywhere. docs/fields.md is generated from :data:`FIELDS` (``python -m finaldrive.engine.fields``).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

#: unit suffix -> unit as printed (longest suffixes first when matching)
UNITS: dict[str, str] = {
    "_m_per_deg": "m/deg", "_m_per_m": "m/m", "_rad_s": "rad/s", "_bytes": "bytes", "_pct": "%",
    "_deg": "deg", "_kg": "kg", "_nm": "N m", "_m": "m", "_s": "s", "_n": "N", "_j": "J", "_w": "W",
}


@dataclass(frozen=True, slots=True)
class Field:
    """An output field: name, unit ("" for none), meaning, decimals shown to people."""

    name: str
    unit: str
    meaning: str
    digits: int | None = None  # None: not a number (or an integer), printed as it is


def unit_of(name: str) -> str:
    """The unit a field's name declares by its suffix ("" for none)."""
    for suffix, unit in sorted(UNITS.items(), key=lambda kv: -len(kv[0])):
        if name.endswith(suffix):
            return unit
    return ""


def base_of(name: str) -> str:
    """The name without its unit suffix: two fields with one base and two units are two spellings."""
    for suffix in sorted(UNITS, key=len, reverse=True):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def _f(name: str, meaning: str, digits: int | None = None) -> Field:
    return Field(name, unit_of(name), meaning, digits)


_DESIGN = [
    _f("a2_deg", "sprocket angle a2: direction of the engine sprocket from the swingarm pivot, chassis frame", 2),
    _f("l2_m", "L2: distance from the swingarm pivot to the engine sprocket axis", 4),
    _f("rws_m", "R_WS: wheel sprocket pitch radius", 4),
    _f("res_m", "R_ES: engine sprocket pitch radius (R_WS over the final-drive ratio)", 4),
]
_RESULT = [
    _f("distance_m", "distance d travelled by the chassis in the run (the fitness's first factor, eq. 67)", 4),
    _f("squat_ratio", "squat ratio SR at the design pose (section 5; 1 = neutral squat, as the paper reads it)", 4),
    _f("slack_m", "chain slack: 2 (max - min) of the taut upper run's length over the run, eq. (68)", 6),
    _f("fitness_m", "the paper's fitness: the distance scaled down for squat ratio and slack, eq. (67)", 4),
    _f("chain_length_m", "chain length L of the design, eq. (69)", 4),
    _f("taut_length_m", "length of the chain's taut upper run (geometry: at the static pose; series: over time)", 4),
    _f("sprocket_centre_m", "engine sprocket centre relative to the swingarm pivot, chassis frame (x, y)", 4),
    _f("wall_s", "wall time the simulation took", 3),
    _f("status", "ok, or failed (reason says why)"),
    _f("reason", "why a run failed (empty when ok)"),
    _f("cached", "reused from an earlier identical simulation"),
]
_DIAGNOSTIC_DIGITS = {"_n": 1, "_s": 3, "_m": 5, "_j": 3, "_w": 3}
_SERIES = [
    _f("t_s", "simulated time", 3),
    _f("pitch_deg", "chassis pitch angle theta (the model's coordinate, docs/engine.md)", 3),
    _f("chain_tension_n", "tension of the chain's upper run", 1),
    _f("fz_rear_n", "vertical load of the rear tyre", 1),
    _f("fz_front_n", "vertical load of the front tyre", 1),
    _f("kappa", "rear tyre's transient longitudinal slip kappa'", 4),
    _f("fx_n", "rear tyre's longitudinal force", 1),
    _f("effective_radius_m", "rear tyre's effective rolling radius R_e", 5),
    _f("wheel_speed_rad_s", "rear wheel's angular speed", 3),
    _f("sprocket_speed_rad_s", "engine sprocket's angular speed", 3),
    _f("tyre_u_m", "rear tyre's longitudinal carcass deflection u (relaxation state)", 6),
    _f("sigma_m", "rear tyre's relaxation length sigma*", 5),
    _f("residual_m", "largest constraint residual (reference method only)", 9),
]
_STUDY = [
    _f("best_fitness_m", "DE: the best fitness found so far (robust DE: the best aggregate score)", 4),
    _f("mean_fitness_m", "DE: the mean fitness of the population's finite members", 4),
    _f("score_m", "robust DE: the aggregate (mean or worst) fitness over the roads", 4),
]


def _diagnostics() -> list[Field]:
    from finaldrive.engine.api import DIAGNOSTIC_MEANINGS

    out = []
    for name, meaning in DIAGNOSTIC_MEANINGS.items():
        digits = next((d for s, d in _DIAGNOSTIC_DIGITS.items() if name.endswith(s)), 4)
        out.append(_f(name, meaning.rsplit(" [", 1)[0], digits))
    return out


#: every physical output field (the service adds its own records' fields in docs/fields.md)
FIELDS: dict[str, Field] = {f.name: f for f in [*_DESIGN, *_RESULT, *_diagnostics(), *_SERIES, *_STUDY]}


def human(name: str, value: object) -> str:
    """``value`` of field ``name`` as people read it: meaningful digits and the unit."""
    spec = FIELDS.get(name)
    if spec is None or spec.digits is None or isinstance(value, bool):
        return str(value)
    if isinstance(value, (list, tuple)):
        text = "(" + ", ".join(_number(v, spec.digits) for v in value) + ")"
    elif isinstance(value, (int, float)):
        text = _number(value, spec.digits)
    else:
        return str(value)
    return f"{text} {spec.unit}" if spec.unit and text != "-" else text


def history_record(record: dict[str, Any]) -> dict[str, Any]:
    """A DE generation record (the optimiser's ``best_f``, ``mean_f``: it knows no units) in the
    outputs' names: generation, n_evals, best_fitness_m, mean_fitness_m, n_failed."""
    names = {"best_f": "best_fitness_m", "mean_f": "mean_fitness_m"}
    return {names.get(key, key): value for key, value in record.items()}


def design_label(a2_deg: float, l2_m: float, rws_m: float) -> str:
    """A design as people read it, e.g. ``a2 = 270 deg, L2 = 0.150 m, R_WS = 0.150 m``."""
    return f"a2 = {a2_deg:g} deg, L2 = {l2_m:.3f} m, R_WS = {rws_m:.3f} m"


def _number(value: object, digits: int) -> str:
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return "-"
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # no "-0.0000"


def table_markdown() -> str:
    """The table of docs/fields.md."""
    rows = ["| field | unit | meaning |", "|---|---|---|"]
    rows += [f"| `{f.name}` | {f.unit or '-'} | {f.meaning} |" for f in FIELDS.values()]
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    sys.stdout.write(table_markdown())
