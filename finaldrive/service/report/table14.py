"""Table 14: the paper's two geometries on ``sine:0.04:3``, simulated with the study's settings.

Geometry 2 uses R_WS = 0.050 m, the text's value (the table's 0.150 m contradicts its own
squat ratio; docs/engine.md#reading-notes-extraction-faults). Simulations are deterministic, so
re-running the report gives the same numbers; the time series (Fig. 13 quantities) are not
stored by the study.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from finaldrive.engine import Design, Road, SimSettings, Vehicle, load_vehicle_dict, paper_row, paper_tables, simulate

ROAD_SPEC = "sine:0.04:3"
#: (a2 [deg], L2 [m], R_WS [m]) as simulated here.
GEOMETRIES = {"geometry1": (0.0, 0.0, 0.093), "geometry2": (270.0, 0.15, 0.050)}


def _gain(d1: float | None, d2: float | None) -> float | None:
    if d1 is None or d2 is None or not d2:
        return None
    return round(100.0 * (d1 - d2) / d2, 3)


def study_settings(spec: dict[str, Any]) -> tuple[SimSettings, Vehicle | None]:
    """The stored study spec's simulation settings and vehicle (None: the default one)."""
    s = spec["settings"]
    tolerance = {"fast_tolerance": s["fast_tolerance"]} if "fast_tolerance" in s else {}  # older specs lack it
    settings = SimSettings(duration=s["duration"], dt=s["dt"], method=s["method"], **tolerance)
    return settings, None if spec.get("vehicle") is None else load_vehicle_dict(spec["vehicle"])


def run_table14(spec: dict[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, np.ndarray]]]:
    """(JSON-ready comparison, series by geometry) with the study spec's settings and vehicle."""
    settings, vehicle = study_settings(spec)
    settings = settings.with_(series=True)
    road = Road.parse(ROAD_SPEC)
    ours: dict[str, Any] = {}
    series: dict[str, dict[str, np.ndarray]] = {}
    for name, (a2_deg, l2, rws) in GEOMETRIES.items():
        res = simulate(Design.from_deg(a2_deg, l2, rws), road, settings, vehicle)
        ok = res.ok and math.isfinite(res.distance_m)
        ours[name] = {
            "a2_deg": a2_deg, "l2_m": l2, "rws_m": rws, "status": res.status, "reason": res.reason,
            "distance_m": round(res.distance_m, 4) if ok else None,
            "squat_ratio": round(res.squat_ratio, 4) if math.isfinite(res.squat_ratio) else None,
            "slack_m": round(res.slack_m, 7) if ok else None,
            "fitness_m": round(res.fitness_m, 4) if ok else None,
        }
        if res.series is not None:
            series[name] = {k: v for k, v in res.series.items() if k != "q"}
    ours["gain_pct"] = _gain(ours["geometry1"]["distance_m"], ours["geometry2"]["distance_m"])
    paper: dict[str, Any] = {k: paper_row(v) for k, v in paper_tables()["table14_geometries"].items()
                             if k.startswith("geometry")}
    paper["gain_pct"] = _gain(paper["geometry1"]["distance_m"], paper["geometry2"]["distance_m"])
    return {"road": ROAD_SPEC, "ours": ours, "paper": paper}, series
