"""Whether a ranking of designs survives the modelling choices: the same designs under documented
alternatives to the model, with the rank correlation of each against the vehicle as given.

The differences between good designs (millimetres) are smaller than some modelling choices move a
run (the issue measured up to 155 mm from the Magic Formula's load range, and a reversed ranking from
a harder drive). :data:`ALTERNATIVES` are those choices, each a named change of the vehicle or the
road; a road it does not apply to (a phase of a road that is not a sine) is skipped.
See docs/optimisation.md#model-bands.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.stats import spearmanr

from finaldrive.engine.api import STATUS_OK, SimSettings
from finaldrive.engine.model.road_envelope import enveloped
from finaldrive.engine.simulation import evaluate
from finaldrive.engine.vehicle import default_vehicle

if TYPE_CHECKING:
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.vehicle import Vehicle

Change = Callable[["Road", "Vehicle", SimSettings], "tuple[Road, Vehicle] | None"]


@dataclass(frozen=True)
class Alternative:
    """A documented alternative to the model: its name, what it changes, and the change (None where
    it does not apply); ``changes``: "vehicle" (the change does not read the road, and gives it back as
    it is) or "road"."""

    name: str
    what: str
    change: Change
    changes: str = "vehicle"


def _vehicle(**scale: float) -> Change:
    def change(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle]:
        return road, vehicle.replace(**{key: vehicle[key] * factor for key, factor in scale.items()})
    return change


def _load_range(fz_max_n: float) -> Change:
    def change(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle] | None:
        if not vehicle["Fz0"] < fz_max_n < vehicle["Fz_max"]:   # a lower bound than the vehicle's only
            return None
        return road, vehicle.replace(Fz_max=fz_max_n)
    return change


def _phase(degrees: float) -> Change:
    def change(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle] | None:
        if road.kind != "sine":
            return None
        return dataclasses.replace(road, phase_deg=(road.phase_deg + degrees) % 360.0), vehicle
    return change


def _launch(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle] | None:
    return None if vehicle["drive_model"] == 1.0 else (road, vehicle.replace(drive_model=1.0))


def _front_wheel_spin(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle] | None:
    return None if vehicle["front_wheel_spin"] == 1.0 else (road, vehicle.replace(front_wheel_spin=1.0))


def _elastic_chain(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle] | None:
    if vehicle["chain_compliance"] == 1.0 or vehicle["chain_runs"] == 2.0 or settings.method != "fast":
        return None
    return road, vehicle.replace(chain_compliance=1.0)


#: Largest mean acceleration of a run [m/s^2], for the length an enveloped road must cover: 1.5 g, above
#: what the rear tyre can drive (tc_friction 1.0: about 1 g) on any of the alternatives.
RUN_ACCELERATION_BOUND = 1.5 * 9.81
#: An enveloped road starts this far behind the rear tyre's start and ends this far past the bound [m].
ENVELOPE_MARGIN_M = 3.0


def _enveloped(road: Road, vehicle: Vehicle, settings: SimSettings) -> tuple[Road, Vehicle] | None:
    if road.kind == "flat":
        return None
    reach = 0.5 * RUN_ACCELERATION_BOUND * settings.duration ** 2 + ENVELOPE_MARGIN_M
    return enveloped(road, vehicle["rt0"], -ENVELOPE_MARGIN_M, reach), vehicle


#: The Magic Formula's upper load bound the issue compared (vehicle file: Fz_max 6,400 N, 4 Fz0).
LOW_LOAD_RANGE_N = 4800.0

ALTERNATIVES: tuple[Alternative, ...] = (
    Alternative("tyre_load_range_4800", f"the Magic Formula's loads held within {LOW_LOAD_RANGE_N:g} N (the vehicle "
                "file's Fz_max: 6,400 N; docs/engine.md#magic-formula-load-range; skipped for a vehicle whose range "
                "is narrower already or whose Fz0 is not below it)", _load_range(LOW_LOAD_RANGE_N)),
    Alternative("drive_half", "the drive torque halved (a gentler launch than the paper's constant 150 N m)",
                _vehicle(torque=0.5)),
    Alternative("drive_double", "the drive torque doubled (300 N m: a harder launch)", _vehicle(torque=2.0)),
    Alternative("drive_launch", "the launch drive: the engine through the gearbox with traction and wheelie limits "
                "(docs/engine.md#the-launch-drive; skipped when the vehicle has it already)", _launch),
    Alternative("front_wheel_spin", "the front wheel turns, rolling, with Table 2's inertia 0.47 kg m^2 (the paper's "
                "does not turn; docs/engine.md#front-wheel-rotation; skipped when the vehicle has it already)",
                _front_wheel_spin),
    Alternative("chain_elastic", "the chain and the rear wheel's cush drive elastic (docs/engine.md#the-elastic-chain-"
                "and-cush-drive; fast method only; skipped when the vehicle has it already or has two chain runs)",
                _elastic_chain),
    Alternative("road_phase_90", "a sine road started a quarter period later (sine roads only)", _phase(90.0), "road"),
    Alternative("road_phase_180", "a sine road started half a period later (sine roads only)", _phase(180.0),
                "road"),
    Alternative("road_enveloped", "the road under a rigid ring of the rear tyre's unloaded radius rt0 (a tyre "
                "bridges dips narrower than itself; docs/engine.md#road-enveloping; not for flat)", _enveloped, "road"),
)


def model_bands(designs: np.ndarray, road: Road, settings: SimSettings = SimSettings(),
                vehicle: Vehicle | None = None) -> dict[str, Any]:
    """Design rows (a2 [rad], L2 [m], R_WS [m]) simulated with the vehicle and road as given
    (``baseline``) and under each applicable alternative: per alternative each design's fitness and
    distance, the Spearman rank correlation of its fitness with the baseline's over the designs that
    succeeded in both (``rank_correlation``; None below 3 of them), the best design's index and
    whether it is the baseline's, and the largest change of a fitness."""
    rows = np.asarray(designs, dtype=float).reshape(-1, 3)
    vehicle = vehicle or default_vehicle()
    base = evaluate(rows, road, settings, vehicle)
    base_f = _fitness(base)
    out: dict[str, Any] = {"baseline": ranking_change(base_f, base.distance_m, base.reason, base_f),
                           "alternatives": {}, "skipped": []}
    for alt in ALTERNATIVES:
        changed = alt.change(road, vehicle, settings)
        if changed is None:
            out["skipped"].append(alt.name)
            continue
        batch = evaluate(rows, changed[0], settings, changed[1])
        out["alternatives"][alt.name] = {"what": alt.what, "road": changed[0].spec,
                                         **ranking_change(_fitness(batch), batch.distance_m, batch.reason, base_f)}
    return out


def _fitness(batch: Any) -> np.ndarray:
    ok = np.array([s == STATUS_OK for s in batch.status])
    return np.where(ok, batch.fitness_m, np.nan)


def ranking_change(fitness: np.ndarray, distance: np.ndarray, failed: Sequence[str],
                   base: np.ndarray) -> dict[str, Any]:
    """The designs' ``fitness`` and ``distance`` under an alternative (NaN fitness: failed, with its
    reason in ``failed``; "" where it succeeded) against their fitness as given (``base``): the record of
    :func:`model_bands`' alternatives."""
    fitness, base = np.asarray(fitness, dtype=float), np.asarray(base, dtype=float)
    both = np.isfinite(fitness) & np.isfinite(base)
    rho = None
    if both.sum() >= 3:
        value = float(spearmanr(base[both], fitness[both]).statistic)
        rho = value if math.isfinite(value) else None
    best = int(np.nanargmax(fitness)) if np.isfinite(fitness).any() else None
    base_best = int(np.nanargmax(base)) if np.isfinite(base).any() else None
    return {
        "fitness_m": [_plain(v) for v in fitness], "distance_m": [_plain(float(v)) for v in distance],
        "failed": list(failed), "rank_correlation": rho, "best": best,
        "same_best": best is not None and best == base_best,
        "largest_change_m": _plain(float(np.max(np.abs(fitness[both] - base[both])))) if both.any() else None,
    }


def _plain(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None
