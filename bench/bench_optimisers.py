"""How many simulations each optimiser needs: evaluations to reach 1 mm and 5 mm of a road's optimum.

    python bench/bench_optimisers.py --seeds 10 --workers 2 --json docs/optimisers.json

Every method and setting runs through the product's own path (``DESettings.build``, the protocol of
engine.optimize) on each road, seeds 0..N-1, with the engine's real fitness (eq. 67, the default
SimSettings). For each run the best fitness so far is kept after every evaluation; a run "reaches"
a tolerance at the first evaluation whose best is within it of the road's reference.

The reference of a road is the best fitness of any evaluation made here (every run of every method,
plus ``--reference-runs`` runs of the paper's DE widened to NP 50 x 100 generations), or the
``--known`` value when that is higher (the best of ~120,000 evaluations measured for flat and
sine:0.04:3 in the issue that asked for this bench). Roads: flat, sine:0.04:3, a Gaussian bump and a
profile road: ISO 8608 class B, 40 m at 5 cm, synthetic (random phases, seed 1), simulated through
the measured-profile path (a piecewise-linear ``profile`` road), since no measured road ships with
the repository.

Random search (uniform in the Table 8 box) is the baseline, made here: it is not a product method.
Printed (JSON with ``--json FILE``): per road and setting, the median and worst evaluations to
1 mm and 5 mm (a run that never reaches counts as a miss and as its evaluations, and is reported),
the median evaluations at which runs stopped, the median final gap, with the machine.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import sys
import time
from dataclasses import asdict
from typing import Any

import numpy as np

from finaldrive.engine import Bounds, DESettings, Road, SimSettings, evaluate
from finaldrive.engine.study.presets import resolve_roads
from finaldrive.engine.study.scoring import fitness_values
from finaldrive.service.machine import describe

#: name -> the settings (None: random search, the baseline)
SETTINGS: dict[str, DESettings | None] = {
    "default": DESettings(),
    "de-np16-no-stop": DESettings(np=16, patience=None, iters=60),
    "paper": DESettings.paper(),
    "de-table10-np20": DESettings.preset("paper", np=20, iters=60),
    "cmaes": DESettings(optimiser="cmaes", np=8, patience=None, iters=1000, max_evals=1500),
    "cmaes-np16": DESettings(optimiser="cmaes", np=16, patience=None, iters=1000, max_evals=1500),
    "random": None,
}
ROADS = ("flat", "sine:0.04:3", "bump:0.04:0.2:5", "iso8608-b")
#: the best of ~120,000 evaluations a road (issue "Optimisers", measured on main 90fd7fa)
KNOWN = {"flat": 20.708065, "sine:0.04:3": 20.277744}
RANDOM_EVALS = 1500
TOLERANCES_M = (1e-3, 5e-3)


def iso8608_road(seed: int = 1, length_m: float = 40.0, step_m: float = 0.05, gd0: float = 64e-6) -> Road:
    """A class B road of ISO 8608 (G_d(n0) = 64e-6 m^3 at n0 = 0.1 cycle/m, waviness 2): a sum of
    sinusoids with random phases over 0.011-2.83 cycles/m, starting and ending level."""
    rng = np.random.default_rng(seed)
    n = np.arange(0.011, 2.83, 1.0 / length_m)  # spatial frequencies [cycle/m], one per 1/L
    amplitude = np.sqrt(2.0 * gd0 * (n / 0.1) ** -2.0 * (1.0 / length_m))
    x = np.arange(0.0, length_m + step_m / 2, step_m)
    y = (amplitude[:, None] * np.cos(2 * np.pi * n[:, None] * x + rng.uniform(0, 2 * np.pi, len(n))[:, None])).sum(0)
    y -= y[0]
    y *= np.clip(x / 2.0, 0.0, 1.0)  # the first 2 m ramp in, so the run starts on level ground
    return Road.from_points(x.tolist(), y.tolist(), name="iso8608-b")


def road_of(name: str) -> Road:
    return iso8608_road() if name == "iso8608-b" else resolve_roads(name)[0].road


def run_one(job: tuple[str, str, int]) -> dict[str, Any]:
    """One run: the best so far after each evaluation, and where it stopped."""
    road_name, setting, seed = job
    road, settings = road_of(road_name), SimSettings()
    chosen = SETTINGS.get(setting) if setting != "reference" else DESettings.preset("paper", iters=100)
    bounds = Bounds()
    best, trace = -math.inf, []
    start = time.process_time()
    if chosen is None:  # random search
        x = np.random.default_rng(seed).uniform(bounds.lower, bounds.upper, (RANDOM_EVALS, 3))
        for f in fitness_values(evaluate(x, road, settings)):
            best = max(best, f) if np.isfinite(f) else best
            trace.append(best)
        stop = "budget"
    else:
        opt = chosen.build(bounds, seed)
        while not opt.done:
            x = opt.ask()
            f = fitness_values(evaluate(x, road, settings))
            opt.tell(f)
            for v in f:
                best = max(best, v) if np.isfinite(v) else best
                trace.append(best)
        stop = str(opt.stop_reason)
    return {"road": road_name, "setting": setting, "seed": seed, "trace": trace, "stop_reason": stop,
            "cpu_s": time.process_time() - start}


def reached(trace: list[float], reference: float, tol: float) -> int | None:
    """The evaluation (1-based) at which the best came within ``tol`` of ``reference``."""
    hits = np.flatnonzero(np.asarray(trace) >= reference - tol)
    return int(hits[0]) + 1 if hits.size else None


def summarise(runs: list[dict[str, Any]], reference: float) -> dict[str, Any]:
    out: dict[str, Any] = {"runs": len(runs)}
    for tol in TOLERANCES_M:
        key = f"{tol * 1e3:g}mm"
        hits = [reached(r["trace"], reference, tol) for r in runs]
        cost = [h if h is not None else len(r["trace"]) for h, r in zip(hits, runs, strict=True)]
        out[key] = {"median": float(np.median(cost)), "worst": int(max(cost)), "missed": sum(h is None for h in hits)}
    out["stopped_median"] = float(np.median([len(r["trace"]) for r in runs]))
    out["gap_mm_median"] = float(np.median([1e3 * (reference - r["trace"][-1]) for r in runs]))
    out["stop_reasons"] = sorted({r["stop_reason"] for r in runs})
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--roads", default=",".join(ROADS))
    parser.add_argument("--settings", default=",".join(SETTINGS))
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--reference-runs", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", metavar="FILE", help="write the results (without traces) here")
    args = parser.parse_args()
    roads, settings = args.roads.split(","), args.settings.split(",")
    jobs = [(r, s, seed) for r in roads for s in settings for seed in range(args.seeds)]
    jobs += [(r, "reference", 1000 + k) for r in roads for k in range(args.reference_runs)]
    start = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        results = pool.map(run_one, jobs, chunksize=1)
    report: dict[str, Any] = {"machine": describe(), "seeds": args.seeds,
                              "wall_s": round(time.perf_counter() - start, 1),
                              "settings": {s: (asdict(SETTINGS[s]) if SETTINGS[s] else {"random_evals": RANDOM_EVALS})
                                           for s in settings}, "roads": {}}
    for road in roads:
        mine = [r for r in results if r["road"] == road]
        seen = max(max(r["trace"]) for r in mine)
        reference = max(seen, KNOWN.get(road, -math.inf))
        entry: dict[str, Any] = {"reference_m": reference, "best_seen_here_m": seen, "known_m": KNOWN.get(road)}
        for s in settings:
            entry[s] = summarise([r for r in mine if r["setting"] == s], reference)
        report["roads"][road] = entry
        print(f"\n{road}: reference {reference:.6f} m (best seen here {seen:.6f})")
        print(f"{'setting':18s} {'1 mm med':>9s} {'worst':>6s} {'miss':>4s} {'5 mm med':>9s} {'worst':>6s} "
              f"{'miss':>4s} {'stopped':>8s} {'gap mm':>7s}")
        for s in settings:
            e = entry[s]
            print(f"{s:18s} {e['1mm']['median']:9.0f} {e['1mm']['worst']:6d} {e['1mm']['missed']:4d} "
                  f"{e['5mm']['median']:9.0f} {e['5mm']['worst']:6d} {e['5mm']['missed']:4d} "
                  f"{e['stopped_median']:8.0f} {e['gap_mm_median']:7.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
