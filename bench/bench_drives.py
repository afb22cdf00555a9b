"""The paper's drive against the launch drive (docs/engine.md#the-launch-drive) over random designs:
per road and drive, the runs that succeed, the distance's median and spread over the designs, the
engine's time a design (median of --repeat timed batches, after one untimed), and the energy ledger's
largest closure. Prints a markdown table.

    python bench/bench_drives.py [--designs 60] [--repeat 3] [--seed 7]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from finaldrive.engine import Bounds, default_vehicle, evaluate, resolve_roads

ROADS = ("flat", "sine:0.04:3", "sine:0.04:2", "sine:0.01:1", "bump:0.04:0.2")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    box = Bounds()  # Table 8
    rng = np.random.default_rng(args.seed)
    lo = [np.radians(box.a2_deg[0]), box.l2_m[0], box.rws_m[0]]
    hi = [np.radians(box.a2_deg[1]), box.l2_m[1], box.rws_m[1]]
    designs = rng.uniform(lo, hi, size=(args.designs, 3))
    paper = default_vehicle()
    drives = {"paper": paper, "launch": paper.replace(drive_model=1.0)}
    machine = platform.processor() or platform.machine()
    print(f"{args.designs} random designs in Table 8's box (seed {args.seed}); {machine}")
    print()
    print("| road | drive | ok | distance, median [m] | spread over the designs [m] | ms a design (median of "
          f"{args.repeat}) | ledger closure, largest |")
    print("|---|---|---|---|---|---|---|")
    for spec in ROADS:
        road = resolve_roads(spec)[0].road
        for name, vehicle in drives.items():
            batch = evaluate(designs, road, vehicle=vehicle)  # untimed: compiles, warms the caches
            times = []
            for _ in range(args.repeat):
                start = time.perf_counter()
                evaluate(designs, road, vehicle=vehicle)
                times.append((time.perf_counter() - start) / len(designs))
            ok = batch.ok
            closure = np.abs(batch.ledger_residual_j[ok] / batch.drive_work_j[ok])
            print(f"| {spec} | {name} | {ok.sum()}/{len(ok)} | {np.median(batch.distance_m[ok]):.2f} | "
                  f"{np.ptp(batch.distance_m[ok]):.2f} | {1e3 * statistics.median(times):.1f} | {closure.max():.1e} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
