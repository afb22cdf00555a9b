"""Regenerate the images of docs/usage.md: ``python docs/images/make_images.py`` (about 20 s)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from finaldrive.engine import Design, Road, SimSettings, evaluate
from finaldrive.engine.model import coordinates as C
from finaldrive.engine.study.sweep import parse_grid
from finaldrive.service.media import plots
from finaldrive.service.media.recording import record, scene_at

HERE = Path(__file__).resolve().parent
ROAD = Road.parse("sine:0.04:3")
TABLE14 = [("geometry 1 (a2 0°, L2 0, R_WS 93 mm)", Design.from_deg(0.0, 0.0, 0.093)),
           ("geometry 2 (a2 270°, L2 150 mm, R_WS 150 mm)", Design.from_deg(270.0, 0.15, 0.15))]


def sweep_map() -> None:
    grid = parse_grid("a2_deg=0:354:6,l2_m=0:0.2:0.02,rws_m=0.093")
    batch = evaluate(grid, ROAD, SimSettings())
    best = int(np.nanargmax(batch.fitness_m))
    plots.sweep_map_png(HERE / "sweep-map.png", grid, batch.distance_m, best=(grid[best, 0], grid[best, 1]),
                        best_label="best fitness (eq. 67)",
                        title="Distance in 3.5 s on sine:0.04:3 (R_WS = 93 mm), as the paper's Fig. 10")


def recording_frame(t: float = 2.0) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "table14.rrd"
        runs = record(rrd, TABLE14, ROAD)
        strips, arrows = scene_at(rrd, t)
    k = round(t * 50)
    xs = [r.series["q"][k][[C.X6, C.X13]] for r in runs]
    plots.scene_png(
        HERE / "recording-frame.png",
        strips,
        arrows,
        xlim=(float(np.min(xs)) - 0.7, float(np.max(xs)) + 0.7),
        title=f"One frame (t = {t:.2f} s) read back from the .rrd, sine:0.04:3; orange: tyre forces (1 m = 5 kN)\n"
        f"blue: {TABLE14[0][0]}    red: {TABLE14[1][0]}",
    )
    plots.series_png(HERE / "series.png", [(r.label, r.series) for r in runs],
                     title="Fig. 13 quantities of the Table 14 geometries on sine:0.04:3")


if __name__ == "__main__":
    sweep_map()
    recording_frame()
    print("wrote", ", ".join(sorted(p.name for p in HERE.glob("*.png"))))
