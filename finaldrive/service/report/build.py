"""docs/paper-study.md (and .json, and figures) from a stored paper-study.

Deterministic: the same stored study gives byte-identical files (sorted keys, rounded
floats, no timestamps but the job's own, figures without dates).
"""

from __future__ import annotations

import json
import os
import platform
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from finaldrive.engine import DEFAULT_TOLERANCE_PCT, near_mask
from finaldrive.service.machine import cpu_model
from finaldrive.service.report import analysis as A
from finaldrive.service.report.data import StudyData
from finaldrive.service.report.markdown import render
from finaldrive.service.report.table14 import GEOMETRIES, run_table14


@dataclass(frozen=True)
class ReportFiles:
    markdown: Path
    json: Path
    figures: list[Path]


def machine() -> dict[str, Any]:
    """The host generating the report (the lead runs study and report on the same machine)."""
    return {"cpu": cpu_model(), "logical_cores": os.cpu_count(), "os": platform.platform(terse=True),
            "python": platform.python_version()}


def build_paper_study(data: StudyData) -> tuple[dict[str, Any], dict[str, Any]]:
    """(report dict, series of the Table 14 runs) for a stored study."""
    roads = A.per_road(data)
    A.add_bands(data, roads)
    table14, series = run_table14(data.spec)
    l2 = tuple(data.spec["bounds"]["l2_m"])
    report = {
        "job": {"id": data.job_id, "spec": data.spec, "roads": [{"name": n, "spec": s} for n, s in data.roads]},
        "run": A.run_stats(data), "machine": machine(), "roads": roads,
        "robust": A.robust(data, roads), "table14": table14,
        "fitness_vs_paper": A.fitness_vs_paper(roads),
        "conclusions": A.conclusions(roads, table14, (float(l2[0]), float(l2[1]))),
    }
    return report, series


def write_paper_study(data: StudyData, out: Path, *, figures: bool = True) -> ReportFiles:
    """Write ``out`` (markdown), ``out`` with suffix .json, and PNGs in ``<out stem>/``."""
    out = Path(out)
    report, series = build_paper_study(data)
    fig_dir = out.parent / out.stem
    pngs = _figures(data, report, series, fig_dir) if figures else {}
    rel = {k: p.relative_to(out.parent).as_posix() for k, p in pngs.items()}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render(report, rel), encoding="utf-8")
    json_path = out.with_suffix(".json")
    json_path.write_text(json.dumps(report, indent=1, sort_keys=True, allow_nan=False) + "\n", encoding="utf-8")
    return ReportFiles(out, json_path, sorted(pngs.values()))


def _figures(data: StudyData, report: dict[str, Any], series: dict[str, Any], fig_dir: Path) -> dict[str, Path]:
    """Sweep map and DE history per road, Table 14 time series; keys ``map:i``, ``de:i``, ``table14``."""
    from finaldrive.service.media.plots import de_history_png, series_png, sweep_map_png

    fig_dir.mkdir(parents=True, exist_ok=True)
    out: dict[str, Path] = {}
    designs, _ = A.sweep_table(data)
    e = data.evals
    np_size = int(data.spec["de"]["np"])
    for road in report["roads"]:
        i, name = road["index"], road["name"]
        stem = re.sub(r"[^A-Za-z0-9._-]", "_", name)
        m = (e["road_index"] == i) & (e["step"] == A.SWEEP_STEP)
        if m.any():
            distance = np.full(len(designs), np.nan)
            ok = m & e["ok"]
            distance[e["candidate"][ok]] = e["distance_m"][ok]
            fitness = np.full(len(designs), np.nan)
            fitness[e["candidate"][ok]] = e["fitness_m"][ok]
            best = int(np.nanargmax(distance)) if np.isfinite(distance).any() else None
            path = fig_dir / f"sweep-{i:02d}-{stem}.png"
            sweep_map_png(path, designs, distance, title=f"Sweep (Table 9): {name} ({road['spec']})",
                          best=None if best is None else (float(designs[best, 0]), float(designs[best, 1])),
                          near=near_mask(fitness, DEFAULT_TOLERANCE_PCT)[0],
                          near_label=f"fitness within {DEFAULT_TOLERANCE_PCT:g} % of the sweep's best")
            out[f"map:{i}"] = path
        history = A.de_history(data, i, np_size)
        if history:
            path = fig_dir / f"de-{i:02d}-{stem}.png"
            method = data.spec["de"].get("optimiser", "de")
            de_history_png(path, history, A.de_population(data, i, np_size), title=f"{method}: {name}")
            out[f"de:{i}"] = path
    if len(series) == 2:
        path = fig_dir / "table14-series.png"
        series_png(path, [(f"{k} (a2, L2, R_WS = {', '.join(f'{v:g}' for v in g)})", series[k])
                          for k, g in GEOMETRIES.items()],
                   title="Fig. 13 style: the two geometries of Table 14 on sine:0.04:3")
        out["table14"] = path
    return out
