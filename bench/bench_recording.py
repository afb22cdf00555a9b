"""Writing a recording: wall time of ``write_recording`` (the scene's frames and the .rrd; the simulations
are run once, before, and not timed), the file's size and its chunks per entity, for the paper's Table 14
geometries on its Fig. 13 road (3.5 s at 50 fps: 176 frames). Median of --repeat writes. Prints a markdown table.

    python bench/bench_recording.py [--repeat 5] [--duration 3.5] [--fps 50]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from finaldrive.engine import Design, Road
from finaldrive.service.media.recording import chunk_counts, series_settings, simulate_runs, write_recording

ROAD = "sine:0.04:3"
DESIGNS = [("geometry 1", Design.from_deg(0.0, 0.0, 0.093)), ("geometry 2", Design.from_deg(270.0, 0.15, 0.15))]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--duration", type=float, default=3.5)
    ap.add_argument("--fps", type=int, default=50)
    args = ap.parse_args()
    road = Road.parse(ROAD)
    start = time.perf_counter()
    runs = simulate_runs(DESIGNS, road, series_settings(args.duration, args.fps))
    simulate_s = time.perf_counter() - start
    walls, sizes, totals, worst = [], [], [], []
    with tempfile.TemporaryDirectory(prefix="bench-recording-") as tmp:
        for i in range(args.repeat):
            path = Path(tmp) / f"{i}.rrd"
            start = time.perf_counter()
            write_recording(path, runs, road, name="bench")
            walls.append(time.perf_counter() - start)
            sizes.append(path.stat().st_size)
            counts = chunk_counts(path)
            totals.append(sum(counts.values()))
            worst.append(max(counts.values()))
    frames = len(runs[0].series["t_s"])
    print(f"{len(runs)} geometries, {frames} frames on {ROAD}; simulations (not timed below): {simulate_s:.1f} s")
    print(f"| | median of {args.repeat} | runs |")
    print("|---|---|---|")
    print(f"| write_recording [s] | {statistics.median(walls):.2f} | {', '.join(f'{w:.2f}' for w in walls)} |")
    print(f"| file [MB] | {statistics.median(sizes) / 1e6:.2f} | {', '.join(f'{s / 1e6:.2f}' for s in sizes)} |")
    print(f"| chunks, all entities | {statistics.median(totals):.0f} | {', '.join(map(str, totals))} |")
    print(f"| chunks, most on one entity | {statistics.median(worst):.0f} | {', '.join(map(str, worst))} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
