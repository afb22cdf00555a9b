"""Numerical bands over random designs, by the fast method's tolerance: how far a production run's
fitness is from the same design re-simulated 100x tighter than the default (5e-7) and with the
reference method (the band of docs/optimisation.md#numerical-bands-and-ties, for every tolerance
against the same two re-runs), split into what the tolerance controls (the production run against the
tight one) and what it cannot (the tight run against the reference method), and what each tolerance
costs. Prints a markdown table.

    python bench/bench_bands.py [--designs 40] [--tolerances 5e-5,2e-5,1e-5,5e-6] [--repeat 3]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from finaldrive.engine import Bounds, SimSettings, default_vehicle, evaluate, resolve_roads

ROADS = ("flat", "sine:0.04:3", "sine:0.04:2", "sine:0.01:1", "bump:0.04:0.2")
TIGHT = 5e-7


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=40)
    ap.add_argument("--tolerances", default="5e-5,2e-5,1e-5,5e-6")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--drive", choices=("paper", "launch"), default="paper")
    args = ap.parse_args()
    tolerances = [float(t) for t in args.tolerances.split(",")]
    box = Bounds()
    rng = np.random.default_rng(args.seed)
    designs = rng.uniform([np.radians(box.a2_deg[0]), box.l2_m[0], box.rws_m[0]],
                          [np.radians(box.a2_deg[1]), box.l2_m[1], box.rws_m[1]], size=(args.designs, 3))
    vehicle = default_vehicle().replace(drive_model=float(args.drive == "launch"))
    machine = platform.processor() or platform.machine()
    print(f"{args.designs} random designs in Table 8's box (seed {args.seed}), {args.drive} drive; {machine}")
    print()
    print("| road | tolerance | band median [mm] | p90 [mm] | largest [mm] | <= 0.2 mm | <= 1 mm | "
          "vs tight: median [mm] | p90 [mm] | tight vs reference: median [mm] | "
          f"ms a design (median of {args.repeat}) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for spec in ROADS:
        road = resolve_roads(spec)[0].road
        tight = evaluate(designs, road, SimSettings(fast_tolerance=TIGHT), vehicle).fitness_m
        ref = evaluate(designs, road, SimSettings(method="reference"), vehicle).fitness_m
        for tol in tolerances:
            settings = SimSettings(fast_tolerance=tol)
            prod = evaluate(designs, road, settings, vehicle).fitness_m
            times = []
            for _ in range(args.repeat):
                start = time.perf_counter()
                evaluate(designs, road, settings, vehicle)
                times.append((time.perf_counter() - start) / len(designs))
            band = 1e3 * np.fmax(np.abs(prod - tight), np.abs(prod - ref))  # a failed re-run is left out
            band = band[np.isfinite(band)]
            vs_tight = 1e3 * np.abs(prod - tight)
            vs_tight = vs_tight[np.isfinite(vs_tight)]
            methods = 1e3 * np.abs(tight - ref)
            print(f"| {spec} | {tol:g} | {np.median(band):.3f} | {np.percentile(band, 90):.3f} | {band.max():.3f} | "
                  f"{np.mean(band <= 0.2):.0%} | {np.mean(band <= 1.0):.0%} | {np.median(vs_tight):.3f} | "
                  f"{np.percentile(vs_tight, 90):.3f} | {np.nanmedian(methods):.3f} | "
                  f"{1e3 * statistics.median(times):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
