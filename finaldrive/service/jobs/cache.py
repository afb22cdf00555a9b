"""Keys of the result cache: one simulation = design + road + vehicle + settings + engine.

Two evaluations with the same key give the same result, so the store reuses the first
one (within a job and across jobs). Designs are rounded to 1e-12 (rad, m) so that a value
that went through JSON or the database still matches.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import fields

import numpy as np

from finaldrive.engine import Road, SimSettings, Vehicle, default_vehicle
from finaldrive.service.profiles import content_hash

#: SimSettings fields that change what is returned or when a run is given up, never a result that
#: finishes: the series and its stride (interpolated; the steps do not land on it) and the
#: wall-time limit (a run stopped by it is a transient failure, never reused).
_OUTPUT_ONLY = frozenset({"series", "series_stride", "max_wall_s"})
DESIGN_DECIMALS = 12


def road_key(road: Road) -> str:
    """``Road.spec``, or for a user profile the hash of its points (the spec names only the label or id)."""
    if road.kind != "profile":
        return road.spec
    return "profile:" + content_hash(road)


def settings_key(settings: SimSettings) -> dict[str, object]:
    return {f.name: getattr(settings, f.name) for f in fields(settings) if f.name not in _OUTPUT_ONLY}


def context_prefix(road: Road, settings: SimSettings, vehicle: Vehicle | None, engine_version: str) -> str:
    """Everything but the design, serialised once per road (hashed with each design)."""
    context = {
        "road": road_key(road),
        "vehicle": (vehicle or default_vehicle()).fingerprint(),
        "settings": settings_key(settings),
        "engine": engine_version,
    }
    return json.dumps(context, sort_keys=True, separators=(",", ":"))


def design_keys(prefix: str, designs: np.ndarray) -> list[str]:
    """sha256 per design row of ``"{prefix}|{a2!r},{l2!r},{rws!r}"`` (the design rounded; the context
    prefix hashed once, its state copied for each design)."""
    rounded = np.round(np.asarray(designs, dtype=float), DESIGN_DECIMALS) + 0.0  # -0.0 -> 0.0
    context = hashlib.sha256(f"{prefix}|".encode())
    keys = []
    for a2, l2, rws in rounded.tolist():
        key = context.copy()
        key.update(f"{a2!r},{l2!r},{rws!r}".encode())
        keys.append(key.hexdigest())
    return keys
