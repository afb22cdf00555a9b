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

from finaldrive.engine.record import RECORD

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
_RECORD = [_f(v.name, v.meaning, v.digits) for v in RECORD]  # one result record (engine.record)
_STORED = [
    _f("status", "ok, or failed (reason says why)"),
    _f("reason", "why a run failed (empty when ok)"),
    _f("cached", "reused from an earlier identical simulation"),
    _f("compile_s", "time a command spent compiling the engine before simulating, once per machine (not in "
                    "wall_s; null when compiled already)", 1),
    _f("taut_length_m", "length of the chain's taut upper run (geometry: at the static pose; series: over time)", 4),
]
_SERIES = [
    _f("t_s", "simulated time", 3),
    _f("pitch_deg", "chassis pitch angle theta (the model's coordinate, docs/engine.md)", 3),
    _f("chain_tension_n", "chain tension: the upper run's, less the lower run's with two runs", 1),
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
    _f("drive_torque_nm", "torque on the engine sprocket: the paper's constant, or the launch drive's after its "
       "limits", 1),
]
_TRAVEL = [
    _f("travel_m", "rear wheel travel: rear axle height above full extension, chassis frame (engine.travel)", 4),
    _f("swingarm_angle_deg", "swingarm angle at the pose: pivot to rear axle, phi - theta (chassis frame, as a2)", 2),
    _f("anti_squat_pct", "anti-squat, 100 tan(tau) / tan(sigma) (textbook form; docs/engine.md)", 1),
    _f("chain_growth_m", "change of the taut upper run's length from full extension", 5),
    _f("kickback_deg", "rear wheel's backward turn that the chain growth gives with the engine sprocket held: "
                       "chain_growth_m / R_WS", 3),
    _f("anti_rise_pct", "anti-rise under rear braking, caliper on the swingarm: 100 tan(lambda) / tan(sigma), "
                        "lambda the slope from the rear contact point to the swingarm pivot", 1),
    _f("spring_length_m", "the rear spring's length between points 3 and 7 (eq. 13)", 4),
    _f("leverage_ratio", "rear wheel travel per unit of rear spring compression at the pose", 3),
    _f("engine_sprocket_teeth", "teeth of the engine sprocket: pitch radius R_ES and the vehicle's chain_pitch, "
                                "N = pi / asin(p / 2R), not rounded", 2),
    _f("wheel_sprocket_teeth", "teeth of the wheel sprocket (R_WS), as engine_sprocket_teeth", 2),
    _f("chain_pitch_m", "the chain's pitch (vehicle chain_pitch)", 6),
    _f("chain_links", "the whole chain's length at the design pose over its pitch (both runs and wraps, and the "
                      "vehicle's free play), not rounded", 2),
    _f("centre_distance_m", "distance between the sprocket centres", 4),
    _f("chain_angle_deg", "direction of the chain's upper run (rear to front), chassis frame", 2),
    _f("chain_above_pivot_m", "height of the upper run's line above the swingarm pivot", 4),
    _f("engine_sprocket_x_m", "engine sprocket centre relative to the pivot, chassis x", 4),
    _f("engine_sprocket_y_m", "engine sprocket centre relative to the pivot, chassis y", 4),
    _f("extension_angle_deg", "swingarm angle at full extension (rear spring unloaded, eq. 13)", 2),
    _f("compression_angle_deg", "swingarm angle at full compression (rear_wheel_travel)", 2),
    _f("rear_wheel_travel_m", "rear wheel travel from full extension to full compression (vehicle file)", 4),
    _f("travel_static_m", "rear travel at the static sag on flat ground", 4),
    _f("sag_pct", "static sag as a share of the rear wheel travel", 1),
    _f("cog_height_m", "centre of gravity height used by anti-squat (Table 3)", 4),
    _f("wheelbase_m", "wheelbase of the model at the design pose", 4),
    _f("fork_angle_deg", "the fork axis's angle from the vertical at the design pose (rake; points 4-5, eq. 14)", 2),
    _f("anti_dive_pct", "anti-dive under front braking, caliper on the fork slider: -100 tan(epsilon) / tan(sigma), "
                        "epsilon = fork_angle_deg (negative: braking compresses the fork beyond the load transfer)", 1),
    _f("travel_mean_m", "simulated: mean rear travel over the run", 4),
    _f("travel_min_m", "simulated: smallest rear travel over the run", 4),
    _f("travel_max_m", "simulated: largest rear travel over the run", 4),
    _f("squat_mean_m", "simulated: mean rear travel minus its value at the start (positive: squat)", 4),
    _f("pitch_mean_deg", "simulated: mean chassis pitch over the run", 3),
    _f("pitch_min_deg", "simulated: smallest chassis pitch over the run", 3),
    _f("pitch_max_deg", "simulated: largest chassis pitch over the run", 3),
]
_STUDY = [
    _f("tolerance_pct", "near-optimal set: fitness within this share of the best (default 0.1 %)", 3),
    _f("tolerance_m", "near-optimal set: the tolerance in metres of fitness", 4),
    _f("ddistance_da2_m_per_deg", "sensitivity of the distance to a2 at the best design (finite difference)", 6),
    _f("dfitness_da2_m_per_deg", "sensitivity of the fitness to a2 at the best design", 6),
    _f("ddistance_dl2_m_per_m", "sensitivity of the distance to L2 at the best design", 4),
    _f("dfitness_dl2_m_per_m", "sensitivity of the fitness to L2 at the best design", 4),
    _f("ddistance_drws_m_per_m", "sensitivity of the distance to R_WS at the best design", 4),
    _f("dfitness_drws_m_per_m", "sensitivity of the fitness to R_WS at the best design", 4),
    _f("best_fitness_m", "DE: the best fitness found so far (robust DE: the best aggregate score)", 4),
    _f("mean_fitness_m", "DE: the mean fitness of the population's finite members", 4),
    _f("score_m", "robust DE: the aggregate (mean or worst) fitness over the roads", 4),
    _f("numerical_band", "a design's numerical band: band_m, distance_band_m, exceeds_limit and each run's values"),
    _f("band_m", "numerical band of the fitness: its largest change when the run is re-simulated 100x tighter "
                 "and with the reference method where the vehicle allows it (engine.study.band)", 4),
    _f("distance_band_m", "numerical band of the distance, as band_m", 4),
    _f("exceeds_limit", "the band is wider than 1 mm: a 1 mm difference is not decided by the numerics"),
    _f("rank_correlation", "model band: Spearman rank correlation of the designs' fitness under an alternative "
                           "with the model as given (engine.study.model_band)", 3),
    _f("largest_change_m", "model band: the largest change of a design's fitness under an alternative", 4),
    _f("tie", "the design's fitness is within the sum of its band and the best's band of the best's: a tie"),
]


#: every physical output field (the service adds its own records' fields in docs/fields.md)
FIELDS: dict[str, Field] = {f.name: f for f in [*_DESIGN, *_RECORD, *_STORED, *_SERIES, *_TRAVEL, *_STUDY]}


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
