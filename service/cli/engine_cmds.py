"""Local engine commands: geometry, simulate, evaluate, calibrate (no service needed)."""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.cli import UsageError


# --- argument helpers shared by the local commands -------------------------------------------

def add_vehicle_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicle", metavar="FILE", help="vehicle parameter file (JSON, as engine/data/vehicle.json)")


def add_design_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--a2-deg", type=float, required=True, help="angle of the engine sprocket from the pivot [deg]")
    p.add_argument("--l2", type=float, required=True, help="distance pivot -> engine sprocket axis [m]")
    p.add_argument("--rws", type=float, required=True, help="wheel sprocket pitch radius R_WS [m]")


def add_settings_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=3.5, help="simulated time [s] (default 3.5)")
    p.add_argument("--dt", type=float, default=None, help="time step [s] (default: the method's)")


def load_vehicle_arg(path: str | None) -> Any:
    from engine import VehicleError, default_vehicle, load_vehicle

    if path is None:
        return default_vehicle()
    try:
        return load_vehicle(path)
    except VehicleError as exc:
        raise UsageError(str(exc)) from None


def design_from_args(args: argparse.Namespace) -> Any:
    from engine import Design, DesignError

    try:
        return Design.from_deg(args.a2_deg, args.l2, args.rws)
    except DesignError as exc:
        raise UsageError(str(exc)) from None


def settings_from_args(args: argparse.Namespace, **extra: Any) -> Any:
    from engine import SimSettings

    changes: dict[str, Any] = {"duration": args.duration, **extra}
    if args.dt is not None:
        changes["dt"] = args.dt
    try:
        return SimSettings(**changes)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def road_from_arg(text: str) -> Any:
    """A road: a spec (flat, sine:H:L, bump:H:S[:MU]), a preset name, or profile:FILE.csv."""
    from engine import Road, RoadError

    if text.startswith("profile:"):
        return _profile_road(Path(text[len("profile:"):]))
    try:
        from engine.study.presets import as_road, resolve_roads

        items = resolve_roads(text)
    except (RoadError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    if len(items) != 1:
        raise UsageError(f"--road takes one road, {text!r} names {len(items)}")
    road = as_road(items[0])
    assert isinstance(road, Road)
    return road


def _profile_road(path: Path) -> Any:
    from engine import Road, RoadError

    try:
        rows = [r for r in csv.reader(path.read_text().splitlines()) if r and not r[0].startswith("#")]
    except OSError as exc:
        raise UsageError(f"road profile {str(path)!r}: {exc.strerror or exc}") from None
    if rows and not _is_number(rows[0][0]):
        rows = rows[1:]  # header
    try:
        xs = [float(r[0]) for r in rows]
        ys = [float(r[1]) for r in rows]
        return Road.from_points(xs, ys, name=path.name)
    except (IndexError, ValueError, RoadError) as exc:
        raise UsageError(f"road profile {str(path)!r}: {exc}") from None


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def print_json(obj: Any) -> None:
    print(json.dumps(obj, indent=2, default=_json_default, allow_nan=False))


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def clean(value: float) -> float | None:
    """JSON has no NaN: failed values are null."""
    return None if not math.isfinite(value) else float(value)


# --- geometry -------------------------------------------------------------------------------

def run_geometry(args: argparse.Namespace) -> int:
    from engine.geometry import static_geometry

    vehicle = load_vehicle_arg(args.vehicle)
    design = design_from_args(args)
    start = time.perf_counter()
    try:
        g = static_geometry(design, vehicle)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    g["wall_ms"] = (time.perf_counter() - start) * 1000.0
    if args.json:
        print_json(g)
    else:
        for key, value in g.items():
            print(f"{key:>22}: {value}")
    return 0


# --- simulate -------------------------------------------------------------------------------

SERIES_CSV_COLUMNS = ("t", "distance", "pitch", "chain_tension", "squat_ratio", "fz_rear", "fz_front",
                      "kappa", "fx", "effective_radius", "wheel_speed", "sprocket_speed", "taut_length")


def run_simulate(args: argparse.Namespace) -> int:
    from engine import simulate

    vehicle = load_vehicle_arg(args.vehicle)
    design = design_from_args(args)
    road = road_from_arg(args.road)
    settings = settings_from_args(args, series=bool(args.series), series_stride=args.stride)
    result = simulate(design, road, settings, vehicle)
    summary = {k: (clean(v) if isinstance(v, float) else v) for k, v in result.summary().items()}
    summary.update({"a2_deg": design.a2_deg, "l2": design.l2, "rws": design.rws, "road": road.spec})
    if args.series and result.series is not None:
        _write_series(Path(args.series), result.series)
    if args.record and result.ok:
        from service.recording import record

        label = f"a2={design.a2_deg:g} L2={design.l2:g} Rws={design.rws:g}"
        try:
            record(args.record, [(label, design)], road, duration=settings.duration, fps=args.fps,
                   base=settings, vehicle=vehicle)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        summary["record"] = args.record
    if args.json:
        print_json(summary)
    else:
        for key in ("status", "reason", "distance_m", "squat_ratio", "slack_mm", "fitness_m", "chain_length_m", "wall_s"):
            print(f"{key:>15}: {summary[key]}")
        if "record" in summary:
            print(f"{'record':>15}: {summary['record']}")
    return 0 if result.ok else 1


def _write_series(path: Path, series: dict[str, np.ndarray]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(SERIES_CSV_COLUMNS)
    for row in zip(*(series[c] for c in SERIES_CSV_COLUMNS)):
        w.writerow([f"{v:.9g}" for v in row])
    path.write_text(buf.getvalue())


# --- evaluate -------------------------------------------------------------------------------

EVALUATE_COLUMNS = ("a2_deg", "l2", "rws", "status", "distance_m", "squat_ratio", "slack_mm",
                    "fitness_m", "chain_length_m", "wall_s", "reason")


def read_designs_csv(path: str) -> np.ndarray:
    """Rows (a2 [rad], L2, R_WS) from a CSV with header a2_deg,l2,rws."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise UsageError(f"designs file {path!r}: {exc.strerror or exc}") from None
    reader = csv.DictReader(io.StringIO(text))
    missing = {"a2_deg", "l2", "rws"} - set(reader.fieldnames or ())
    if missing:
        raise UsageError(f"designs file {path!r}: missing column(s) {', '.join(sorted(missing))}")
    rows = []
    for n, row in enumerate(reader, start=2):
        try:
            rows.append([math.radians(float(row["a2_deg"])), float(row["l2"]), float(row["rws"])])
        except (TypeError, ValueError):
            raise UsageError(f"designs file {path!r}, line {n}: a2_deg, l2 and rws must be numbers") from None
    return np.array(rows, dtype=float).reshape(-1, 3)


def batch_rows(batch: Any) -> list[dict[str, Any]]:
    out = []
    for i in range(len(batch)):
        a2, l2, rws = batch.designs[i]
        out.append({
            "a2_deg": math.degrees(a2), "l2": float(l2), "rws": float(rws), "status": batch.status[i],
            "distance_m": clean(batch.distance_m[i]), "squat_ratio": clean(batch.squat_ratio[i]),
            "slack_mm": clean(batch.slack_m[i] * 1000.0), "fitness_m": clean(batch.fitness_m[i]),
            "chain_length_m": clean(batch.chain_length_m[i]), "wall_s": float(batch.wall_s[i]),
            "reason": batch.reason[i],
        })
    return out


def write_rows_csv(rows: list[dict[str, Any]], stream: Any) -> None:
    w = csv.DictWriter(stream, fieldnames=EVALUATE_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in EVALUATE_COLUMNS})


def run_evaluate(args: argparse.Namespace) -> int:
    from engine import evaluate

    vehicle = load_vehicle_arg(args.vehicle)
    road = road_from_arg(args.road)
    designs = read_designs_csv(args.designs)
    settings = settings_from_args(args)
    batch = evaluate(designs, road, settings, vehicle)
    rows = batch_rows(batch)
    if args.json:
        print_json(rows)
    else:
        write_rows_csv(rows, sys.stdout)
    return 0


# --- calibrate ------------------------------------------------------------------------------

def run_calibrate(args: argparse.Namespace) -> int:
    from engine.calibrate import solve_chassis_cog, solve_torque, static_loads

    vehicle = load_vehicle_arg(args.vehicle)
    if not args.skip_cog:
        vehicle = solve_chassis_cog(vehicle)
    if not args.skip_torque:
        vehicle = solve_torque(vehicle)
    loads = static_loads(vehicle)
    Path(args.out).write_text(json.dumps(vehicle.to_dict(), indent=2) + "\n")
    print_json({"chassis_cog_x": vehicle["chassis_cog_x"], "chassis_cog_y": vehicle["chassis_cog_y"],
                "torque": vehicle["torque"], "rear_share": loads.rear_share,
                "cog_height": loads.cog_height, "wheelbase": loads.wheelbase, "out": args.out})
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("geometry", help="a design's static quantities (SR, chain length) without simulating")
    add_design_args(p)
    add_vehicle_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run_geometry)

    p = sub.add_parser("simulate", help="simulate one design on one road, in this process")
    add_design_args(p)
    p.add_argument("--road", required=True, help="flat | sine:H:LAMBDA | bump:H:SIGMA[:MU] | a preset name | profile:FILE.csv")
    add_vehicle_arg(p)
    add_settings_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--series", metavar="FILE.csv", help="write the time series (Fig. 13 quantities)")
    p.add_argument("--stride", type=int, default=10, help="keep every n-th step in the series (default 10)")
    p.add_argument("--record", metavar="FILE.rrd", help="also write a Rerun recording (open with `rerun FILE.rrd`)")
    p.add_argument("--fps", type=int, default=50, help="--record: frames per simulated second (default 50)")
    p.set_defaults(run=run_simulate)

    p = sub.add_parser("evaluate", help="simulate a CSV of designs (a2_deg,l2,rws) in this process")
    p.add_argument("--designs", required=True, metavar="FILE.csv", help="CSV with header a2_deg,l2,rws")
    p.add_argument("--road", required=True, help="road spec or preset name")
    add_vehicle_arg(p)
    add_settings_args(p)
    p.add_argument("--json", action="store_true", help="print a JSON list instead of CSV")
    p.set_defaults(run=run_evaluate)

    p = sub.add_parser("calibrate", help="solve the chassis centre of mass and the drive torque for a vehicle file")
    add_vehicle_arg(p)
    p.add_argument("--out", required=True, metavar="FILE", help="where to write the calibrated vehicle file")
    p.add_argument("--skip-cog", action="store_true", help="keep the chassis centre of mass")
    p.add_argument("--skip-torque", action="store_true", help="keep the drive torque")
    p.set_defaults(run=run_calibrate)
