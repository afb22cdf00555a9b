"""Local study commands: optimize (the paper's DE, or one DE over several roads) and sweep.

They run in this process and its workers (no service): ``--executor process`` (default on a
multi-core machine) spawns a pool, ``ray`` starts or joins Ray. Progress goes to stderr,
results to stdout.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import time
from contextlib import nullcontext
from typing import IO, Any

import numpy as np

from finaldrive.engine import history_record
from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import (
    ROAD_HELP,
    UsageError,
    add_de_args,
    add_json_arg,
    add_settings_args,
    add_tolerance_arg,
    add_vehicle_arg,
    clean,
    de_from_args,
    load_vehicle_arg,
    parser_options,
    road_list,
    settings_from_args,
    writable,
)
from finaldrive.service.cli.engine_cmds import EVALUATE_COLUMNS, batch_rows
from finaldrive.service.cli.local_run import Tally, default_executor, design_dict, open_executor, run_study
from finaldrive.service.cli.progress import Progress
from finaldrive.service.cli.study_view import print_result


def add_road_args(p: argparse.ArgumentParser) -> None:
    group = p.add_mutually_exclusive_group(required=True)
    group.add_argument("--road", help=f"one road: {ROAD_HELP}")
    group.add_argument("--roads", help="several roads: a group (paper, sine, bump) or a comma-separated list of roads")
    p.add_argument("--aggregate", choices=("mean", "worst"), default="mean",
                   help="with several roads, a design's score: the mean fitness over the roads, or the worst road")


def add_run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--executor", choices=("serial", "process", "ray"), default=None,
                   help=f"where simulations run (default: process on a multi-core machine, else serial; "
                        f"here {default_executor()})")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes / Ray CPUs (default: all cores)")
    add_vehicle_arg(p)
    add_settings_args(p)
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress on stderr (default: only when stderr is a terminal)")
    add_json_arg(p)


def _roads(args: argparse.Namespace) -> tuple[str, ...]:
    text = args.road if args.road is not None else args.roads
    if args.road is not None and len(road_list(text)) != 1:
        raise UsageError(f"--road takes one road, {text!r} names several; use --roads")
    return (text,)


def _plan(kind: str, args: argparse.Namespace, **parts: Any) -> Any:
    from pathlib import Path

    from finaldrive.engine import PlanError, plan_study
    from finaldrive.service.cli.common import read_profile

    try:
        return plan_study(kind, _roads(args), profiles=lambda name: read_profile(Path(name)),
                          vehicle=load_vehicle_arg(args.vehicle, args.drive), **parts)
    except PlanError as exc:
        raise UsageError(str(exc)) from None


def _paper(road: Any) -> dict[str, float] | None:
    return None if road.paper is None else dict(road.paper)


# --- optimize ---------------------------------------------------------------------------------

def run_optimize(args: argparse.Namespace) -> int:
    bounds, de = de_from_args(args)
    if args.repeat < 1:
        raise UsageError("--repeat must be >= 1")
    several = args.roads is not None
    plans = [_plan("robust-de" if several else "de", args, bounds=bounds, de=de,
                   aggregate=args.aggregate if several else None, seed=args.seed + k) for k in range(args.repeat)]
    plan = plans[0]
    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    settings = settings_from_args(args, vehicle)
    tally = Tally(len(plan.roads), Progress(sum(p.total() for p in plans), enabled=args.progress))
    start = time.monotonic()
    kind = args.executor or default_executor()
    with open_executor(kind, args.workers) as executor:
        n_workers = executor.num_workers
        try:
            runs = [one.runs()[0] for one in plans]  # one run a seed: on one road, or robust over several
            for k, run in enumerate(runs):
                run.index = k  # the repeats run at once, each told its own results
            run_study(runs, plan, settings, vehicle, executor, tally)
            de_runs = [run.optimiser for run in runs]
        finally:
            tally.progress.close()
    best_k = max(range(len(de_runs)), key=lambda k: de_runs[k].best_f if np.isfinite(de_runs[k].best_f) else -math.inf)
    de_run = de_runs[best_k]
    on_best = tally.on_roads(de_run.best_x) if np.isfinite(de_run.best_f) else [None] * len(plan.roads)
    best = None
    if np.isfinite(de_run.best_f):
        best = on_best[0] if not several else {
            **design_dict(de_run.best_x), "fitness_m": float(de_run.best_f),
            "distance_m": _mean([r["distance_m"] for r in on_best if r is not None], len(plan.roads))}
    per_road = []
    for r, road in enumerate(plan.roads):
        seen = tally.road_best.get(r, (math.nan, None))[1]
        here = on_best[r]
        regret = None
        if seen and here and seen["fitness_m"] and here["fitness_m"] is not None:
            regret = 100.0 * (seen["fitness_m"] - here["fitness_m"]) / seen["fitness_m"]
        per_road.append({"road": road.name, "spec": road.road.spec, "best_design": here, "best_seen": seen,
                         "regret_pct": regret, "paper": _paper(road)})
    sharp = _sharpness(args, tally, plan, settings, vehicle, de_run.best_x if best is not None else None)
    if best is not None and args.band:
        _bands(sharp, best, per_road, de_run.best_x, tally, plan, settings, vehicle, args.aggregate)
    if best is not None:
        sharp["final_population"] = _population(de_run)
        if len(de_runs) > 1:
            sharp["repeats"] = _repeats(de_runs, args.seed)
    out = {
        "command": "optimize", "roads": [r.name for r in plan.roads], "aggregate": args.aggregate if several else None,
        "best": best, "per_road": per_road, "evaluations": tally.progress.done, "failed": tally.progress.failed,
        "designs_evaluated": de_run.n_evals, "generations": de_run.generation, "stop_reason": de_run.stop_reason,
        "history": [{k: (clean(v) if isinstance(v, float) else v) for k, v in history_record(h).items()}
                    for h in de_run.history],
        "seed": args.seed + best_k, "repeat": args.repeat,
        "de": {"preset": args.preset or "default", **dataclasses.asdict(de)},
        "bounds": {"a2_deg": list(bounds.a2_deg), "l2_m": list(bounds.l2_m), "rws_m": list(bounds.rws_m)},
        "sharpness": sharp,
        "executor": kind, "workers": n_workers, "duration": settings.duration, "wall_s": time.monotonic() - start,
    }
    print_result(out, args.json)
    return 0 if best is not None else 1


def _row(x: np.ndarray) -> dict[str, float]:
    return {"a2_deg": math.degrees(float(x[0])), "l2_m": float(x[1]), "rws_m": float(x[2])}


def _population(de: Any) -> dict[str, Any]:
    """The spread of a DE's final population."""
    from finaldrive.engine import spread

    ok = np.isfinite(de.fitness)
    return {"count": int(ok.sum()), "ranges": spread(de.population[ok], de.fitness[ok])}


def _repeats(de_runs: list[Any], seed: int) -> dict[str, Any]:
    """Each seed's optimum and how far apart they are."""
    from finaldrive.engine import spread

    found = [(seed + k, d) for k, d in enumerate(de_runs) if np.isfinite(d.best_f)]
    optima = [{"seed": s, **_row(d.best_x), "fitness_m": float(d.best_f)} for s, d in found]
    return {"optima": optima, "spread": spread(np.array([d.best_x for _, d in found]),
                                               np.array([d.best_f for _, d in found]))}


def _sharpness(args: argparse.Namespace, tally: Tally, plan: Any, settings: Any, vehicle: Any,
               best_x: np.ndarray | None) -> dict[str, Any]:
    """The near-optimal set of every evaluated design (by the study's score) and, on one road, the
    sensitivities at the best design (engine study.sharpness)."""
    from finaldrive.engine import Design, aggregate, near_optimal, sensitivities

    designs, fitness, distance = tally.arrays()
    several = len(plan.roads) > 1
    score = fitness[0] if not several else aggregate(fitness, args.aggregate)
    dist = distance[0] if not several else distance.mean(axis=0)
    try:
        near = near_optimal(designs, score, dist, args.tolerance_pct)
    except ValueError as exc:
        raise UsageError(f"--tolerance-pct: {exc}") from None
    out: dict[str, Any] = {"near_optimal": near, "sensitivity": None}
    if best_x is None:
        return out
    if several:
        out["sensitivity_note"] = "computed on one road only (--road)"
    else:
        out["sensitivity"] = sensitivities(Design(*(float(v) for v in best_x)), plan.roads[0].road, settings, vehicle)
    return out


def _bands(sharp: dict[str, Any], best: dict[str, Any], per_road: list[dict[str, Any]], best_x: np.ndarray,
           tally: Tally, plan: Any, settings: Any, vehicle: Any, how: Any) -> None:
    """Numerical bands (engine study.band): on one road, of the best and the next best distinct
    designs, with which of them tie with it (``sharpness.ties``); over several roads, of the best
    design on each road and of its score (each re-run's fitness aggregated as the score is)."""
    from finaldrive.engine import BAND_LIMIT_M, aggregate, best_distinct, numerical_bands, tie_flags

    if len(plan.roads) > 1:
        bands = [numerical_bands(best_x[None, :], road.road, settings, vehicle)[0] for road in plan.roads]
        for row, band in zip(per_road, bands, strict=True):
            if row["best_design"] is not None:
                row["best_design"]["numerical_band"] = band
        if all(b["band_m"] is not None for b in bands):
            scores = {label: float(aggregate(np.array([[b["runs"][label]["fitness_m"]] for b in bands]),
                                             how)[0]) for label in bands[0]["runs"]}
            width = max(abs(v - scores["production"]) for v in scores.values())
            best["numerical_band"] = {"fitness_m": scores["production"], "band_m": width,
                                      "exceeds_limit": width > BAND_LIMIT_M,
                                      "runs": {label: {"fitness_m": v} for label, v in scores.items()}}
        return
    designs, fitness, _ = tally.arrays()
    rows = designs[best_distinct(designs, fitness[0])]
    bands = numerical_bands(rows, plan.roads[0].road, settings, vehicle)
    best["numerical_band"] = bands[0]
    sharp["ties"] = [{**design_dict(row), **band, "tie": tie}
                     for row, band, tie in zip(rows, bands, tie_flags(bands), strict=True)]


def _mean(values: list[Any], n: int) -> float | None:
    return float(np.mean(values)) if len(values) == n and None not in values else None


# --- sweep ------------------------------------------------------------------------------------

def sweep_grid(args: argparse.Namespace) -> tuple[str, np.ndarray]:
    """(grid label, designs) from --grid and --rws-m."""
    from finaldrive.engine import TABLE9_DEFAULT_RWS_M, parse_grid, table9_grid

    spec = args.grid.strip()
    try:
        if spec.lower() == "table9":
            rws = TABLE9_DEFAULT_RWS_M if args.rws_m is None else args.rws_m
            return f"table9 (rws_m={rws:g})", table9_grid(rws)
        if args.rws_m is not None:
            if "rws" in spec.lower():
                raise UsageError("give R_WS either in --grid (rws_m=...) or with --rws-m, not both")
            spec = f"{spec},rws_m={args.rws_m!r}" if spec else f"rws_m={args.rws_m!r}"
        return spec, parse_grid(spec)
    except ValueError as exc:
        option = "--rws-m" if args.rws_m is not None and str(exc).startswith("rws") else "--grid"
        raise UsageError(f"{option}: {exc}") from None


def run_sweep(args: argparse.Namespace) -> int:
    from finaldrive.engine import aggregate

    grid_label, designs = sweep_grid(args)
    plan = _plan("sweep", args, grid=designs)
    several = len(plan.roads) > 1
    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    settings = settings_from_args(args, vehicle)
    out_path = writable(args.out, "--out") if args.out else None
    tally = Tally(len(plan.roads), Progress(plan.total(), enabled=args.progress))
    table = np.full((len(plan.roads), len(designs)), np.nan)
    start = time.monotonic()
    kind = args.executor or default_executor()
    with (open(out_path, "w", newline="") if out_path else nullcontext(None)) as stream, \
            open_executor(kind, args.workers) as executor:
        n_workers = executor.num_workers
        writer = _csv_writer(stream) if stream is not None else None

        def on_result(part: Any, batch: Any, fitness: np.ndarray) -> None:
            tally(part, batch, fitness)
            table[part.road, part.candidates] = fitness
            if writer is not None:
                writer.writerows({"road": plan.roads[part.road].name, **row} for row in batch_rows(batch))

        try:
            run_study(plan.runs(), plan, settings, vehicle, executor, on_result)
        finally:
            tally.progress.close()
    score = table[0] if not several else aggregate(table, args.aggregate)
    i = int(np.nanargmax(score)) if np.isfinite(score).any() else None
    best = None
    if i is not None:
        on_roads = tally.on_roads(designs[i])
        best = on_roads[0] if not several else {
            **design_dict(designs[i]), "fitness_m": float(score[i]),
            "distance_m": _mean([r["distance_m"] for r in on_roads if r is not None], len(plan.roads))}
    per_road = [{"road": road.name, "spec": road.road.spec, "best": tally.road_best.get(r, (None, None))[1],
                 "failed": int(np.isnan(table[r]).sum()), "paper": _paper(road)}
                for r, road in enumerate(plan.roads)]
    out = {
        "command": "sweep", "roads": [r.name for r in plan.roads], "aggregate": args.aggregate if several else None,
        "grid": grid_label, "designs": len(designs), "best": best, "per_road": per_road,
        "sharpness": _sharpness(args, tally, plan, settings, vehicle, designs[i] if i is not None else None),
        "evaluations": tally.progress.done, "failed": tally.progress.failed, "out": args.out, "executor": kind,
        "workers": n_workers, "duration": settings.duration, "wall_s": time.monotonic() - start,
    }
    print_result(out, args.json)
    return 0 if best is not None else 1


def _csv_writer(stream: IO[str]) -> csv.DictWriter[str]:
    writer = csv.DictWriter(stream, fieldnames=("road", *EVALUATE_COLUMNS), lineterminator="\n")
    writer.writeheader()
    return writer


def register(sub: Any) -> None:
    p = sub.add_parser("optimize", help=COMMANDS["optimize"].help,
                       description="An optimiser (DE by default; --preset paper: Table 10) over the Table 8 box "
                                   "(--bounds). --road: the paper's per-road optimisation; --roads: one design "
                                   "scored on every road (--aggregate mean|worst). Failed simulations score NaN "
                                   "and are counted.",
                       **parser_options())
    add_road_args(p)
    add_de_args(p)
    p.add_argument("--repeat", type=int, default=1, metavar="K",
                   help="run the DE K times (seeds SEED..SEED+K-1) and report how far apart their optima are")
    add_tolerance_arg(p)
    p.add_argument("--no-band", dest="band", action="store_false",
                   help="skip the numerical bands (the best re-simulated 100x tighter and with the reference "
                        "method; one road: the next best too, with which of them tie)")
    add_run_args(p)
    p.set_defaults(run=run_optimize)

    p = sub.add_parser("sweep", help=COMMANDS["sweep"].help,
                       **parser_options())
    add_road_args(p)
    p.add_argument("--grid", default="table9",
                   help="table9, or a grid spec such as a2_deg=0:358:2,l2_m=0:0.2:0.02,rws_m=0.093")
    p.add_argument("--rws-m", type=float, default=None, help="R_WS [m] of the grid (default 0.093, Table 9)")
    p.add_argument("--out", metavar="FILE.csv", help="write every result (road, design, outcome) as CSV")
    add_tolerance_arg(p)
    add_run_args(p)
    p.set_defaults(run=run_sweep)
