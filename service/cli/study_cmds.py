"""Local study commands: optimize (the paper's DE, or robust over roads), sweep, roads.

They run in this process and its workers (no service): ``--executor process`` (default
on a multi-core machine) spawns a pool, ``ray`` starts or joins Ray; the executor is
always closed, also on Ctrl-C. Progress goes to stderr, results to stdout.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from service.cli import UsageError
from service.cli.engine_cmds import (
    EVALUATE_COLUMNS, add_settings_args, add_vehicle_arg, batch_rows, clean, load_vehicle_arg,
    print_json, road_from_arg, settings_from_args,
)
from service.cli.progress import Progress

if TYPE_CHECKING:
    from engine.api import BatchResult, SimSettings
    from engine.model.road import Road
    from engine.optimize.de import DifferentialEvolution
    from engine.vehicle import Vehicle
    from workers import Executor

#: Table 8 search box (a2 [deg], L2 [m], R_WS [m]).
TABLE8_BOUNDS: dict[str, tuple[float, float]] = {"a2_deg": (0.0, 360.0), "l2": (0.0, 0.2), "rws": (0.05, 0.15)}
#: Smallest DE population the CLI accepts (best/1 needs the best and two others).
MIN_NP = 4


# --- arguments -------------------------------------------------------------------------------

def default_executor() -> str:
    """``process`` when this machine has more than one core, else ``serial``."""
    return "process" if (os.cpu_count() or 1) > 1 else "serial"


def add_road_args(p: argparse.ArgumentParser) -> None:
    group = p.add_mutually_exclusive_group(required=True)
    group.add_argument("--road", help="one road: a preset name, a spec (flat, sine:H:LAMBDA, bump:H:SIGMA[:MU]) "
                                      "or profile:FILE.csv")
    group.add_argument("--roads", help="several roads: a group (paper, sine, bump) or a comma-separated list "
                                       "of preset names and specs")
    p.add_argument("--objective", choices=("mean", "worst"), default="mean",
                   help="with several roads, a design's score: mean fitness over the roads, or the worst road "
                        "(default mean)")


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
    p.add_argument("--json", action="store_true", help="print one JSON object")


@dataclass(frozen=True)
class NamedRoad:
    label: str
    road: Road
    paper: dict[str, float] | None     # the paper's optimum on a preset road


def roads_from_args(args: argparse.Namespace) -> list[NamedRoad]:
    from engine.study.presets import RoadPreset, as_road, resolve_roads, road_label

    if args.road is not None and args.road.startswith("profile:"):
        road = road_from_arg(args.road)
        return [NamedRoad(road.spec, road, None)]
    text = args.road if args.road is not None else args.roads
    try:
        items = resolve_roads(text)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.road is not None and len(items) != 1:
        raise UsageError(f"--road takes one road, {text!r} names {len(items)}; use --roads")
    return [NamedRoad(road_label(i), as_road(i), i.paper if isinstance(i, RoadPreset) else None) for i in items]


def parse_bounds(text: str | None) -> tuple[np.ndarray, np.ndarray]:
    """Engine-unit (lower, upper) from ``a2_deg=LO:HI,l2=LO:HI,rws=LO:HI`` (missing: Table 8)."""
    box = dict(TABLE8_BOUNDS)
    for raw in (text or "").split(","):
        if not raw.strip():
            continue
        name, _, values = (s.strip() for s in raw.partition("="))
        if name not in box:
            raise UsageError(f"--bounds: unknown variable {name!r}: expected a2_deg, l2 or rws")
        try:
            lo, hi = (float(v) for v in values.split(":"))
        except ValueError:
            raise UsageError(f"--bounds: {name}={values!r}: expected LOWER:UPPER") from None
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise UsageError(f"--bounds: {name}: bounds must be finite")
        if lo > hi or (name == "a2_deg" and lo == hi):
            raise UsageError(f"--bounds: {name}: lower bound {lo:g} is not below upper bound {hi:g}")
        box[name] = (lo, hi)
    if box["a2_deg"][1] - box["a2_deg"][0] > 360:
        raise UsageError("--bounds: a2_deg: the range may not exceed 360 deg")
    if box["l2"][0] < 0:
        raise UsageError("--bounds: l2: must be >= 0 m")
    if box["rws"][0] <= 0:
        raise UsageError("--bounds: rws: must be > 0 m")
    lower = np.array([math.radians(box["a2_deg"][0]), box["l2"][0], box["rws"][0]])
    upper = np.array([math.radians(box["a2_deg"][1]), box["l2"][1], box["rws"][1]])
    return lower, upper


def open_executor(kind: str, workers: int | None) -> Executor:
    from workers import make_executor

    if workers is not None and workers < 1:
        raise UsageError("--workers must be >= 1")
    try:
        return make_executor(kind, num_workers=workers)  # type: ignore[arg-type]
    except ImportError as exc:
        raise UsageError(str(exc)) from None


# --- running designs on roads ----------------------------------------------------------------

def fitness_of(batch: BatchResult) -> np.ndarray:
    """Fitness per design; NaN for a failed simulation (status or non-finite value)."""
    f = np.array(batch.fitness_m, dtype=float)
    f[~(batch.ok & np.isfinite(f))] = np.nan
    return f


def run_plan(
    executor: Executor, plan: Sequence[tuple[Road, np.ndarray]], settings: SimSettings, vehicle: Vehicle,
    progress: Progress, on_road: Callable[[int, BatchResult], None] | None = None,
) -> list[BatchResult]:
    """Every road's results in input order; ``on_road(index, results)`` as each road completes, in order."""
    from engine.api import BatchResult
    from workers import evaluate_roads_stream

    parts: list[dict[int, Any]] = [{} for _ in plan]
    left = [len(designs) for _, designs in plan]
    out: list[BatchResult] = []
    ready = 0
    single = len(plan) == 1
    for r, rows, result in evaluate_roads_stream(executor, plan, settings, vehicle):
        parts[r][int(rows[0])] = result
        left[r] -= len(rows)
        f = fitness_of(result)
        best = float(np.nanmax(f)) if single and np.isfinite(f).any() else None
        progress.update(done=len(rows), failed=int(np.isnan(f).sum()),
                        best=None if best is None or best <= progress.best else best)
        while ready < len(plan) and left[ready] == 0:
            out.append(BatchResult.concat([parts[ready][k] for k in sorted(parts[ready])]))
            if on_road is not None:
                on_road(ready, out[ready])
            ready += 1
    return out


def design_dict(x: np.ndarray) -> dict[str, float]:
    return {"a2_deg": math.degrees(float(x[0])), "l2": float(x[1]), "rws": float(x[2])}


def result_dict(batch: BatchResult, i: int) -> dict[str, Any]:
    """Design and outcome of row ``i`` of a batch (JSON-ready)."""
    return {**design_dict(batch.designs[i]), "fitness_m": clean(fitness_of(batch)[i]),
            "distance_m": clean(batch.distance_m[i]), "squat_ratio": clean(batch.squat_ratio[i]),
            "slack_mm": clean(batch.slack_m[i] * 1000.0)}


def best_index(score: np.ndarray) -> int | None:
    """First index of the largest finite score; None when every score is NaN."""
    return int(np.nanargmax(score)) if np.isfinite(score).any() else None


def paper_ref(road: NamedRoad) -> dict[str, float] | None:
    return None if road.paper is None else dict(road.paper)


# --- optimize ---------------------------------------------------------------------------------

@dataclass
class Incumbent:
    """The best design so far with its results on every road (the DE's own best_x)."""

    score: float = -math.inf
    x: np.ndarray | None = None
    per_road: list[dict[str, Any]] | None = None


def build_de(args: argparse.Namespace, lower: np.ndarray, upper: np.ndarray) -> DifferentialEvolution:
    """The optimiser from the DE options; a2 is periodic only when its range is the full circle."""
    from engine.optimize.de import DifferentialEvolution

    if args.np < MIN_NP:
        raise UsageError(f"--np must be >= {MIN_NP}, got {args.np}")
    from engine.study.space import periodic_mask

    try:
        return DifferentialEvolution(
            lower, upper, periodic=periodic_mask(lower, upper), pop_size=args.np, f=args.f, cp=args.cp,
            mp=args.mp, mr_fraction=args.mr, max_iter=args.iters, max_evals=args.max_evals,
            patience=args.patience, seed=args.seed,
        )
    except ValueError as exc:
        raise UsageError(str(exc).replace("pop_size", "--np").replace("max_iter", "--iters")
                         .replace("max_evals", "--max-evals").replace("mr_fraction", "--mr")) from None


def run_optimize(args: argparse.Namespace) -> int:
    from engine.study.robust import aggregate

    roads = roads_from_args(args)
    lower, upper = parse_bounds(args.bounds)
    de = build_de(args, lower, upper)
    settings = settings_from_args(args)
    vehicle = load_vehicle_arg(args.vehicle)
    planned = args.np * (args.iters + 1)
    total = len(roads) * (min(planned, args.max_evals) if args.max_evals else planned)
    incumbent = Incumbent()
    seen = [Incumbent() for _ in roads]          # each road's best evaluated design
    progress = Progress(total, enabled=args.progress)
    start = time.monotonic()
    kind = args.executor or default_executor()
    with open_executor(kind, args.workers) as executor:
        n_workers = executor.num_workers
        try:
            while not de.done:
                x = de.ask()
                results = run_plan(executor, [(nr.road, x) for nr in roads], settings, vehicle, progress)
                table = np.stack([fitness_of(b) for b in results])
                score = table[0] if len(roads) == 1 else aggregate(table, args.objective)
                de.tell(score)
                _update(incumbent, seen, x, score, table, results)
                progress.update(best=de.best_f)
        finally:
            progress.close()
    out = {
        "command": "optimize",
        "roads": [nr.label for nr in roads],
        "objective": args.objective if len(roads) > 1 else None,
        "best": _best_summary(incumbent, len(roads)),
        "per_road": [_road_summary(nr, incumbent, s, i) for i, (nr, s) in enumerate(zip(roads, seen))],
        "evaluations": progress.done,
        "failed": progress.failed,
        "designs_evaluated": de.n_evals,
        "generations": de.generation,
        "stop_reason": de.stop_reason,
        "history": [{k: (clean(v) if isinstance(v, float) else v) for k, v in h.items()} for h in de.history],
        "seed": args.seed,
        "de": {"np": args.np, "iters": args.iters, "f": args.f, "cp": args.cp, "mp": args.mp, "mr": args.mr,
               "patience": args.patience, "max_evals": args.max_evals},
        "bounds": {"a2_deg": [math.degrees(lower[0]), math.degrees(upper[0])],
                   "l2": [lower[1], upper[1]], "rws": [lower[2], upper[2]]},
        "executor": kind,
        "workers": n_workers,
        "duration_s": settings.duration,
        "wall_s": time.monotonic() - start,
    }
    _print_result(out, args.json)
    return 0 if out["best"] is not None else 1


def _update(incumbent: Incumbent, seen: list[Incumbent], x: np.ndarray, score: np.ndarray,
            table: np.ndarray, results: list[BatchResult]) -> None:
    """Follow the DE's best (ties go to the newer design, as in its selection) and each road's best."""
    i = best_index(score)
    if i is not None and score[i] >= incumbent.score:
        incumbent.score, incumbent.x = float(score[i]), x[i].copy()
        incumbent.per_road = [result_dict(b, i) for b in results]
    for r, b in enumerate(results):
        j = best_index(table[r])
        if j is not None and table[r, j] > seen[r].score:
            seen[r].score, seen[r].x, seen[r].per_road = float(table[r, j]), x[j].copy(), [result_dict(b, j)]


def _best_summary(incumbent: Incumbent, n_roads: int) -> dict[str, Any] | None:
    if incumbent.x is None or incumbent.per_road is None:
        return None
    if n_roads == 1:
        return incumbent.per_road[0]
    distances = [r["distance_m"] for r in incumbent.per_road]
    return {**design_dict(incumbent.x), "fitness_m": incumbent.score,
            "distance_m": float(np.mean(distances)) if None not in distances else None}


def _road_summary(nr: NamedRoad, incumbent: Incumbent, seen: Incumbent, i: int) -> dict[str, Any]:
    best_here = seen.per_road[0] if seen.per_road else None
    on_best = incumbent.per_road[i] if incumbent.per_road else None
    regret = None
    if best_here and on_best and best_here["fitness_m"] and on_best["fitness_m"] is not None:
        regret = 100.0 * (best_here["fitness_m"] - on_best["fitness_m"]) / best_here["fitness_m"]
    return {"road": nr.label, "spec": nr.road.spec, "best_design": on_best, "best_seen": best_here,
            "regret_pct": regret, "paper": paper_ref(nr)}


# --- sweep ------------------------------------------------------------------------------------

def sweep_grid(args: argparse.Namespace) -> tuple[str, np.ndarray]:
    """(grid label, designs) from --grid and --rws."""
    from engine.study.sweep import TABLE9_DEFAULT_RWS_M, parse_grid, table9_grid

    spec = args.grid.strip()
    try:
        if spec.lower() == "table9":
            rws = TABLE9_DEFAULT_RWS_M if args.rws is None else args.rws
            return f"table9 (rws={rws:g})", table9_grid(rws)
        if args.rws is not None:
            if "rws" in spec.lower():
                raise UsageError("give R_WS either in --grid (rws=...) or with --rws, not both")
            spec = f"{spec},rws={args.rws!r}" if spec else f"rws={args.rws!r}"
        return spec, parse_grid(spec)
    except ValueError as exc:
        option = "--rws" if args.rws is not None and str(exc).startswith("rws") else "--grid"
        raise UsageError(f"{option}: {exc}") from None


def run_sweep(args: argparse.Namespace) -> int:
    from engine.study.robust import aggregate

    roads = roads_from_args(args)
    grid_label, designs = sweep_grid(args)
    settings = settings_from_args(args)
    vehicle = load_vehicle_arg(args.vehicle)
    progress = Progress(len(designs) * len(roads), enabled=args.progress)
    start = time.monotonic()
    kind = args.executor or default_executor()
    with _open_out(args.out) as stream, open_executor(kind, args.workers) as executor:
        n_workers = executor.num_workers
        writer = _csv_writer(stream) if stream is not None else None

        def write(r: int, batch: Any) -> None:
            if writer is not None:
                writer.writerows({"road": roads[r].label, **row} for row in batch_rows(batch))
                stream.flush()

        try:
            results = run_plan(executor, [(nr.road, designs) for nr in roads], settings, vehicle, progress, write)
        finally:
            progress.close()
    table = np.stack([fitness_of(b) for b in results])
    score = table[0] if len(roads) == 1 else aggregate(table, args.objective)
    i = best_index(score)
    best = None
    if i is not None:
        best = result_dict(results[0], i) if len(roads) == 1 else {
            **design_dict(designs[i]), "fitness_m": float(score[i]),
            "distance_m": clean(float(np.mean([b.distance_m[i] for b in results]))),
        }
    per_road = []
    for r, (nr, batch) in enumerate(zip(roads, results)):
        j = best_index(table[r])
        per_road.append({"road": nr.label, "spec": nr.road.spec, "best": None if j is None else result_dict(batch, j),
                         "failed": int(np.isnan(table[r]).sum()), "paper": paper_ref(nr)})
    out = {
        "command": "sweep", "roads": [nr.label for nr in roads],
        "objective": args.objective if len(roads) > 1 else None, "grid": grid_label, "designs": len(designs),
        "best": best, "per_road": per_road, "evaluations": progress.done, "failed": progress.failed,
        "out": args.out, "executor": kind, "workers": n_workers, "duration_s": settings.duration,
        "wall_s": time.monotonic() - start,
    }
    _print_result(out, args.json)
    return 0 if best is not None else 1


def _open_out(path: str | None) -> Any:
    if path is None:
        return nullcontext(None)
    try:
        return open(path, "w", newline="")
    except OSError as exc:
        raise UsageError(f"--out {path!r}: {exc.strerror or exc}") from None


def _csv_writer(stream: IO[str]) -> csv.DictWriter[str]:
    writer = csv.DictWriter(stream, fieldnames=("road", *EVALUATE_COLUMNS), lineterminator="\n")
    writer.writeheader()
    return writer


# --- output -----------------------------------------------------------------------------------

def _print_result(out: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print_json(out)
        return
    print(f"best: {_design_text(out['best'])}" + (f"  ({out['objective']} over {len(out['roads'])} roads)"
                                                  if out["objective"] else f"  on {out['roads'][0]}"))
    if len(out["roads"]) > 1:
        for road in out["per_road"]:
            here = road.get("best") or road.get("best_design")
            print(f"  {road['road']:<22} {_design_text(here)}")
    extra = f", {out['generations']} generations, stop: {out['stop_reason']}" if out["command"] == "optimize" else ""
    print(f"evaluations: {out['evaluations']} ({out['failed']} failed){extra}, "
          f"executor {out['executor']}, {out['wall_s']:.1f} s")
    if out.get("out"):
        print(f"results: {out['out']}")


def _design_text(d: dict[str, Any] | None) -> str:
    if d is None:
        return "none (every simulation failed)"
    fitness = "failed" if d["fitness_m"] is None else f"{d['fitness_m']:.4f} m"
    distance = "-" if d.get("distance_m") is None else f"{d['distance_m']:.3f} m"
    return (f"a2 = {d['a2_deg']:.2f} deg, L2 = {d['l2']:.4f} m, R_WS = {d['rws']:.4f} m, "
            f"fitness {fitness}, distance {distance}")


# --- roads ------------------------------------------------------------------------------------

def run_roads(args: argparse.Namespace) -> int:
    from engine.study.presets import PRESETS

    rows = [{"name": p.name, "spec": p.spec, "description": p.description, "paper": p.paper}
            for p in PRESETS.values()]
    if args.json:
        print_json(rows)
        return 0
    print(f"{'name':<20} {'spec':<20} {'a2 deg':>7} {'L2 m':>6} {'R_WS m':>7} {'fit m':>7}  description")
    for row in rows:
        ref = row["paper"] or {}
        print(f"{row['name']:<20} {row['spec']:<20} {ref.get('a2_deg', math.nan):7.1f} {ref.get('L2_m', math.nan):6.3f} "
              f"{ref.get('R_WS_m', math.nan):7.3f} {ref.get('fitness_m', math.nan):7.3f}  {row['description']}")
    return 0


# --- registration -----------------------------------------------------------------------------

def add_de_args(p: argparse.ArgumentParser) -> None:
    """The DE options (Table 10 defaults), shared by ``optimize`` and ``submit``."""
    p.add_argument("--np", type=int, default=50, help="population size NP (default 50, >= 4)")
    p.add_argument("--iters", type=int, default=50, help="generations after the initial population (default 50)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--f", type=float, default=0.6, help="differential weight F (default 0.6)")
    p.add_argument("--cp", type=float, default=0.6, help="crossover probability CP (default 0.6)")
    p.add_argument("--mp", type=float, default=0.1, help="mutation probability MP (default 0.1)")
    p.add_argument("--mr", type=float, default=0.2, help="mutation range MR as a fraction of each range (default 0.2)")
    p.add_argument("--patience", type=int, default=None, help="stop after N generations without improvement")
    p.add_argument("--max-evals", type=int, default=None, help="design evaluation budget (>= --np)")


def register(sub: Any) -> None:
    p = sub.add_parser("optimize", help="the paper's DE on one road, or a robust DE over several roads (local)",
                       description="Differential evolution (Table 10 defaults) over the Table 8 box. --road: the "
                                   "paper's per-road optimisation; --roads: one design scored on every road "
                                   "(--objective mean|worst). Failed simulations score NaN and are counted.")
    add_road_args(p)
    add_de_args(p)
    p.add_argument("--bounds", default=None, metavar="SPEC",
                   help="override Table 8: a2_deg=LO:HI,l2=LO:HI,rws=LO:HI (any subset; default "
                        "a2_deg=0:360,l2=0:0.2,rws=0.05:0.15). a2 is periodic only over a full 360 deg")
    add_run_args(p)
    p.set_defaults(run=run_optimize)

    p = sub.add_parser("sweep", help="simulate a design grid (Table 9 by default) on one or more roads (local)")
    add_road_args(p)
    p.add_argument("--grid", default="table9",
                   help="table9 (default) or a grid spec, e.g. a2_deg=0:358:2,l2=0:0.2:0.02,rws=0.093")
    p.add_argument("--rws", type=float, default=None, help="R_WS [m] for the grid (default 0.093)")
    p.add_argument("--out", metavar="FILE.csv", help="write every result (road, design, outcome) as CSV")
    add_run_args(p)
    p.set_defaults(run=run_sweep)

    p = sub.add_parser("roads", help="the paper's 23 road presets with its optimum on each")
    p.add_argument("--json", action="store_true", help="print a JSON list")
    p.set_defaults(run=run_roads)
