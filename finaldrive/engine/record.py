"""The result record: what one simulation reports, declared once.

Every place a result travels follows from :data:`VALUES`: the engine's results (:class:`SimResult`
holds one record, :class:`BatchResult` a block of them, one row a design), the workers' returned
blocks, the scheduler's hand-over to the store, the store's columns, the API's fields and
docs/fields.md (through ``finaldrive.engine.fields``). A record is its design, ``status``, ``reason``
and the float64 values below, in this order; units are in the names (docs/fields.md's rule).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class Value:
    """One number a result reports: name (unit in it), meaning, decimals people read, and whether
    it is a diagnostic (tracked at every integrator step, docs/engine.md "Extremes and the energy
    ledger") rather than the outcome the fitness is made of."""

    name: str
    meaning: str
    digits: int
    diagnostic: bool = False


def _d(name: str, meaning: str, digits: int) -> Value:
    return Value(name, meaning, digits, diagnostic=True)


_LOAD_MIN = ("0 when airborne, negative while its damper pulls as the tyre springs back "
             "(eqs. 36-37 as printed)")

#: The float64 values of a result record, in order (NaN when the run did not produce them).
RECORD: tuple[Value, ...] = (
    Value("distance_m", "distance d travelled by the chassis in the run (the fitness's first factor, eq. 67)", 4),
    Value("squat_ratio", "squat ratio SR at the design pose (section 5; 1 = neutral squat, as the paper reads it)", 4),
    Value("slack_m", "chain slack: 2 (max - min) of the taut upper run's length over the run, eq. (68)", 6),
    Value("fitness_m", "the paper's fitness: the distance scaled down for squat ratio and slack, eq. (67)", 4),
    Value("chain_length_m", "chain length L of the design, eq. (69)", 4),
    Value("wall_s", "wall time the simulation took", 3),
    _d("chain_tension_max_n", "largest tension of the chain's upper run", 1),
    _d("chain_tension_min_n", "smallest chain tension: negative when the upper run pushes (the paper's chain) or "
                              "the lower run pulls (two runs); never below 0 for the elastic chain", 1),
    _d("chain_compression_s", "time in overrun: the upper run pushing (the paper's chain) or not taut (two runs); 0 "
                              "for the elastic chain, which does not push", 3),
    _d("fz_rear_max_n", "largest vertical load of the rear tyre", 1),
    _d("fz_rear_min_n", f"smallest vertical load of the rear tyre: {_LOAD_MIN}", 1),
    _d("fz_front_max_n", "largest vertical load of the front tyre", 1),
    _d("fz_front_min_n", f"smallest vertical load of the front tyre: {_LOAD_MIN}", 1),
    _d("slip_max", "largest |kappa'|, the rear tyre's transient longitudinal slip", 4),
    _d("airborne_rear_s", "time the rear wheel spends off the road", 3),
    _d("airborne_front_s", "time the front wheel spends off the road", 3),
    _d("tyre_compression_rear_max_m", "largest radial compression of the rear tyre", 5),
    _d("tyre_compression_front_max_m", "largest radial compression of the front tyre", 5),
    _d("drive_work_j", "work of the drive torque", 3),
    _d("kinetic_energy_j", "kinetic energy at the end", 3),
    _d("potential_energy_j", "change of the potential energy (gravity, springs, bump stop)", 3),
    _d("damper_dissipation_j", "energy the suspension and tyre dampers (and the two-run chain's impacts) "
                               "dissipated", 3),
    _d("tyre_slip_work_j", "work the longitudinal tyre force took by slip: carcass energy + dissipation", 3),
    _d("tyre_carcass_energy_j", "energy stored in the tyre carcass's deflection at the end", 3),
    _d("tyre_dissipation_j", "energy the tyre dissipated by slip (>= 0)", 3),
    _d("tyre_lever_work_j", "work the tyre force created through a lever arm other than R_e (0 by default)", 3),
    _d("ledger_residual_j", "drive + lever work - (kinetic + potential + dampers + slip): the ledger's error", 3),
    _d("tyre_dissipation_min_w", "smallest slip dissipation power at any step (>= 0: no energy created)", 3),
)

#: The record's value names, in order: the columns of :attr:`BatchResult.values`.
VALUES: tuple[str, ...] = tuple(v.name for v in RECORD)
#: The diagnostics among them (every value after the outcome).
DIAGNOSTICS: tuple[str, ...] = tuple(v.name for v in RECORD if v.diagnostic)
#: value name -> its column
COLUMN: dict[str, int] = {name: i for i, name in enumerate(VALUES)}
#: What a block of records holds per value (one float64 column each).
DTYPE = np.dtype(np.float64)


def empty(n: int) -> np.ndarray:
    """``n`` records' values, all NaN (nothing produced yet)."""
    return np.full((n, len(VALUES)), np.nan, dtype=DTYPE)


def values_of(**named: float) -> np.ndarray:
    """One record's values from names (each a :data:`VALUES` name; the ones left out are NaN)."""
    out: np.ndarray = empty(1)[0]
    for name, value in named.items():
        out[COLUMN[name]] = value  # a KeyError names a value the record does not declare
    return out
