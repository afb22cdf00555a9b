"""The paper's 23 roads as presets, each with its paper reference row.

Roads (paper section 5.1; Tables 11-13), built with :class:`engine.model.road.Road`; a road is
named by its spec everywhere (inputs and outputs):

- ``flat`` (Table 11);
- 16 sinusoids ``sine:H:LAMBDA``: H_y = 0.01, 0.02, 0.03, 0.04 m x lambda = 2, 3, 4, 5 m,
  H_y outer (Table 12 row order), e.g. ``sine:0.04:3``;
- 6 Gaussian bumps ``bump:H:SIGMA:5``: H_y = 0.02, 0.04 m x sigma = 0.2, 0.5, 1 m, H_y outer
  (Table 13 row order, inferred: docs/engine.md#reading-notes-extraction-faults), centre
  mu = 5.0 m (a reference choice: docs/engine.md#reading-notes-reference-choices; the paper gives
  none), e.g. ``bump:0.04:0.2:5``.

Earlier versions named the presets ``sine-h{H}cm-l{lambda}m`` and ``bump-h{H}cm-s{sigma}cm``;
those names are still read (:data:`ALIASES`, so that stored jobs resolve), never printed.

Groups: ``paper`` (all 23 in the order Table 11, Table 12 rows, Table 13 rows),
``sine`` and ``bump``.

Each preset's ``paper`` dict is its row of Tables 11-13 (the DE optimum the paper found) in
the outputs' names (docs/fields.md, :func:`paper_row`): ``a2_deg, l2_m, rws_m, slack_m,
squat_ratio, fitness_m`` (Table 12 prints a2 = 371.0 deg for ``sine:0.04:2``: angles wrap,
371 deg = 11 deg; it is kept as printed). The rows are read from the shipped
``engine/data/paper_tables.json``, which keeps the paper's own column names (``L2_m``,
``R_WS_m``, ``slack_mm``, ``SR``, ``d_m``).
"""

from __future__ import annotations

import functools
import importlib.resources
import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from finaldrive.engine.model.road import DEFAULT_BUMP_CENTRE_M, Road, RoadError

#: Keys of a preset's paper reference row (Tables 11-13).
PAPER_KEYS = ("a2_deg", "l2_m", "rws_m", "slack_m", "squat_ratio", "fitness_m")
#: The paper's column names in paper_tables.json -> the outputs' names (slack_mm is converted to m).
_PAPER_NAMES = {"L2_m": "l2_m", "R_WS_m": "rws_m", "SR": "squat_ratio", "d_m": "distance_m", "slack_mm": "slack_m"}

GROUPS = ("paper", "sine", "bump")


@dataclass(frozen=True)
class NamedRoad:
    """A road with its name (its spec, or ``profile:ID`` for a measured profile) and, on the
    paper's presets, the paper's optimum on it (``paper``, else None)."""

    name: str
    road: Road
    paper: dict[str, float] | None = None
    description: str = ""

    @property
    def spec(self) -> str:
        """The road's spec string (``Road.parse(spec) == road``)."""
        return self.road.spec


@functools.cache
def paper_tables() -> dict[str, Any]:
    """The paper's tables as shipped in ``engine/data/paper_tables.json`` (do not mutate)."""
    path = importlib.resources.files("finaldrive.engine") / "data" / "paper_tables.json"
    tables: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return tables


def _cm(metres: float) -> int:
    return round(metres * 100)


def paper_row(row: dict[str, Any]) -> dict[str, Any]:
    """A row of paper_tables.json in the outputs' names and units (docs/fields.md)."""
    return {_PAPER_NAMES.get(k, k): (v / 1000.0 if k == "slack_mm" and v is not None else v) for k, v in row.items()}


def _reference(row: dict[str, Any]) -> dict[str, float]:
    named = paper_row(row)
    return {key: float(named[key]) for key in PAPER_KEYS}


def _build() -> tuple[dict[str, NamedRoad], dict[str, str]]:
    """The presets by spec, and the earlier names -> spec."""
    tables = paper_tables()
    presets = {"flat": NamedRoad("flat", Road("flat"), _reference(tables["table11_flat"][0]), "flat road (Table 11)")}
    aliases = {}
    for i, row in enumerate(tables["table12_sine"], start=1):
        h, lam = row["H_y_m"], row["lambda_m"]
        road = Road("sine", height=h, wavelength=lam)
        presets[road.spec] = NamedRoad(road.spec, road, _reference(row),
                                       f"sinusoid H_y = {_cm(h)} cm, lambda = {lam:g} m (Table 12 row {i})")
        aliases[f"sine-h{_cm(h)}cm-l{lam:g}m"] = road.spec
    for i, row in enumerate(tables["table13_gaussian"], start=1):
        h, sigma = row["H_y_m"], row["sigma_m"]
        road = Road("bump", height=h, sigma=sigma, mu=DEFAULT_BUMP_CENTRE_M)
        presets[road.spec] = NamedRoad(road.spec, road, _reference(row),
                                       f"Gaussian bump H_y = {_cm(h)} cm, sigma = {sigma:g} m, "
                                       f"mu = {DEFAULT_BUMP_CENTRE_M:g} m (Table 13 row {i})")
        aliases[f"bump-h{_cm(h)}cm-s{_cm(sigma)}cm"] = road.spec
    return presets, aliases


#: The 23 presets by spec, in the paper's table order; the earlier names of the presets -> spec.
PRESETS, ALIASES = _build()


def preset_group(name: str) -> list[NamedRoad]:
    """Presets of a group: ``paper`` (23), ``sine`` (16) or ``bump`` (6), in table order."""
    key = name.strip().lower()
    if key == "paper":
        return list(PRESETS.values())
    if key in ("sine", "bump"):
        return [p for p in PRESETS.values() if p.road.kind == key]
    raise ValueError(f"unknown preset group {name!r}: expected one of {', '.join(GROUPS)}")


#: Turns the part after ``profile:`` into a road (the caller reads files or a database).
ProfileResolver = Callable[[str], Road]


def resolve_roads(text: str, profiles: ProfileResolver | None = None) -> list[NamedRoad]:
    """Roads from a comma-separated list of group names and road specs.

    ``"paper"``, ``"flat,sine:0.04:3"``, ``"sine:0.04:3,bump:0.03:0.4:6"``. A road spec
    equal to a preset's road resolves to that preset (so it carries the paper row), and so does an
    earlier preset name (:data:`ALIASES`). ``profile:NAME`` items are passed to ``profiles`` (the
    engine reads no files). Order is kept; repeated roads are dropped after their first occurrence.
    Raises ValueError naming the bad item.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError("road list must be a non-empty string")
    by_road = {p.road: p for p in PRESETS.values()}
    out: list[NamedRoad] = []
    seen: set[Road] = set()
    for raw in text.split(","):
        item = raw.strip()
        if not item:
            raise ValueError(f"empty item in road list {text!r}")
        key = item.lower()
        if key in GROUPS:
            found = preset_group(key)
        elif key in PRESETS or key in ALIASES:
            found = [PRESETS[ALIASES.get(key, key)]]
        elif key.startswith("profile:"):
            if profiles is None:
                raise ValueError(f"road {item!r}: measured profiles are not available here")
            road = profiles(item[len("profile:"):])
            found = [NamedRoad(item, road)]
        elif ":" in item:
            try:
                road = Road.parse(item)
            except RoadError as exc:
                raise ValueError(f"bad road {item!r}: {exc}") from None
            found = [by_road.get(road, NamedRoad(road.spec, road))]
        else:
            raise ValueError(
                f"unknown road {item!r}: expected a group ({', '.join(GROUPS)}), a spec (flat, "
                "sine:H:LAMBDA[:PHASE_DEG], bump:H:SIGMA[:MU]) or profile:..."
            )
        for entry in found:
            if entry.road not in seen:
                seen.add(entry.road)
                out.append(entry)
    return out
