"""Keys of the result cache: one simulation = design + road + vehicle + settings + engine.

Two evaluations with the same key give the same result, so the store reuses the first
one (within a job and across jobs). A key is 64 characters: 32 hex digits (128 bits) of the
sha256 of everything but the design (the context, hashed once a road), then the design itself,
its three float64 values rounded to 1e-12 (rad, m), so that a value that went through JSON or
the database still matches, as base64 of their big-endian bits (32 characters). The design is in
the key as it is, not hashed: two designs never share a key, and a job's keys are made without a
hash a design (sha256 a design was a fifth of the scheduler's loop, issue 27).
"""

from __future__ import annotations

import base64
import hashlib
import json
from dataclasses import fields

import numpy as np

from finaldrive.engine import Road, SimSettings, Vehicle, default_vehicle
from finaldrive.service.db.results import CONTEXT_DIGITS, DESIGN_CHARS
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


def context_digest(road: Road, settings: SimSettings, vehicle: Vehicle | None, engine_version: str) -> str:
    """Everything but the design, serialised and hashed once a road: the first 32 hex digits of its sha256."""
    context = {
        "road": road_key(road),
        "vehicle": (vehicle or default_vehicle()).fingerprint(),
        "settings": settings_key(settings),
        "engine": engine_version,
    }
    text = json.dumps(context, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:CONTEXT_DIGITS]


def design_keys(context: str, designs: np.ndarray) -> list[str]:
    """The key of each design row (a2, L2, R_WS) in ``context`` (:func:`context_digest`): the context's
    digits, then the design rounded, as base64 of its three big-endian float64 values (24 bytes a
    design, so the base64 of a request's designs is theirs end to end, without padding)."""
    rounded = np.round(np.asarray(designs, dtype=float).reshape(-1, 3), DESIGN_DECIMALS) + 0.0  # -0.0 -> 0.0
    text = base64.b64encode(rounded.astype(">f8").tobytes()).decode()
    return [context + text[at:at + DESIGN_CHARS] for at in range(0, len(text), DESIGN_CHARS)]
