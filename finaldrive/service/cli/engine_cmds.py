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

from finaldrive.engine import VALUES, design_label, human
from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import (
    ROAD_HELP,
    UsageError,
    add_design_args,
    add_json_arg,
    add_settings_args,
    add_vehicle_arg,
    clean,
    compile_first,
    design_from_args,
    load_vehicle_arg,
    parser_options,
    print_json,
    read_designs_csv,
    road_from_arg,
    settings_from_args,
    writable,
)
from finaldrive.service.cli.travel_view import drive_lines, travel_lines

# --- geometry -------------------------------------------------------------------------------

def run_geometry(args: argparse.Namespace) -> int:
    from finaldrive.engine import drive_squat, static_geometry, travel_kinematics

    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    design = design_from_args(args, vehicle)
    road = road_from_arg(args.road) if args.road else None
    settings = settings_from_args(args, vehicle) if road is not None else None
    png = writable(args.png, "--png") if args.png else None
    start = time.perf_counter()
    try:
        g = static_geometry(design, vehicle)
        points = {"points": args.points} if args.points is not None else {}
        travel = travel_kinematics(design, vehicle, **points) if args.travel or png else None
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    g["wall_s"] = time.perf_counter() - start
    drive = drive_squat(design, road, settings, vehicle) if road is not None and settings is not None else None
    if png is not None and travel is not None:
        from finaldrive.service.media.plots import travel_png

        travel_png(png, travel, title=design_label(design.a2_deg, design.l2, design.rws))
    if args.json:
        print_json({**g, **({"travel_curve": travel} if travel is not None else {}),
                    **({"drive_squat": drive} if drive is not None else {})})
        return 0
    for key, value in g.items():
        print(f"{key:>22}: {human(key, value)}")
    if travel is not None:
        print("\n".join(["", *travel_lines(travel)]))
    if drive is not None:
        print("\n".join(["", *drive_lines(drive)]))
    return 0


# --- simulate -------------------------------------------------------------------------------

SERIES_CSV_COLUMNS = ("t_s", "distance_m", "pitch_deg", "chain_tension_n", "squat_ratio", "fz_rear_n", "fz_front_n",
                      "kappa", "fx_n", "effective_radius_m", "wheel_speed_rad_s", "sprocket_speed_rad_s",
                      "taut_length_m", "drive_torque_nm")


def run_simulate(args: argparse.Namespace) -> int:
    from finaldrive.engine import simulate

    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    design = design_from_args(args, vehicle)
    road = road_from_arg(args.road)
    settings = settings_from_args(args, vehicle, series=bool(args.series), series_stride=args.stride)
    series_path = writable(args.series, "--series") if args.series else None
    record_path = writable(args.record, "--record") if args.record else None
    compile_s = compile_first(settings.method)
    result = simulate(design, road, settings, vehicle)
    summary = {k: (clean(v) if isinstance(v, float) else v) for k, v in result.summary().items()}
    summary["compile_s"] = compile_s
    summary.update({"a2_deg": design.a2_deg, "l2_m": design.l2, "rws_m": design.rws, "road": road.spec})
    if series_path is not None and result.series is not None:
        _write_series(series_path, result.series)
    if record_path is not None and result.ok:
        from finaldrive.service.media.recording import record

        label = design_label(design.a2_deg, design.l2, design.rws)
        try:
            record(record_path, [(label, design)], road, duration=settings.duration, fps=args.fps,
                   base=settings, vehicle=vehicle)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        summary["record"] = args.record
    if args.json:
        print_json(summary)
    else:
        for key in (
            "status",
            "reason",
            "distance_m",
            "squat_ratio",
            "slack_m",
            "fitness_m",
            "chain_length_m",
            "wall_s",
            *(["compile_s"] if compile_s is not None else []),
        ):
            print(f"{key:>15}: {human(key, summary[key])}")
        if "record" in summary:
            print(f"{'record':>15}: {summary['record']}")
    return 0 if result.ok else 1


def _write_series(path: Path, series: dict[str, np.ndarray]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(SERIES_CSV_COLUMNS)
    for row in zip(*(series[c] for c in SERIES_CSV_COLUMNS), strict=True):
        w.writerow([f"{v:.9g}" for v in row])
    path.write_text(buf.getvalue())


# --- evaluate -------------------------------------------------------------------------------

EVALUATE_COLUMNS = ("a2_deg", "l2_m", "rws_m", "status", *VALUES, "reason")


def batch_rows(batch: Any) -> list[dict[str, Any]]:
    out = []
    for i in range(len(batch)):
        a2, l2, rws = batch.designs[i]
        out.append({
            "a2_deg": math.degrees(a2), "l2_m": float(l2), "rws_m": float(rws), "status": batch.status[i],
            **{name: clean(v) for name, v in zip(VALUES, batch.values[i].tolist(), strict=True)},
            "reason": batch.reason[i],
        })
    return out


def write_rows_csv(rows: list[dict[str, Any]], stream: Any) -> None:
    w = csv.DictWriter(stream, fieldnames=EVALUATE_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in EVALUATE_COLUMNS})


def run_evaluate(args: argparse.Namespace) -> int:
    from finaldrive.engine import evaluate

    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    road = road_from_arg(args.road)
    designs = _checked_designs(args.designs, vehicle)
    settings = settings_from_args(args, vehicle)
    compile_first(settings.method)
    batch = evaluate(designs, road, settings, vehicle)
    rows = batch_rows(batch)
    if args.json:
        print_json(rows)
    else:
        write_rows_csv(rows, sys.stdout)
    return 0


# --- model-band -----------------------------------------------------------------------------

def run_model_band(args: argparse.Namespace) -> int:
    from finaldrive.engine import model_bands

    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    road = road_from_arg(args.road)
    designs = _checked_designs(args.designs, vehicle)
    if len(designs) < 2:
        raise UsageError(f"designs file {args.designs!r}: a ranking needs at least 2 designs")
    out = {"road": road.spec, "designs": [{"a2_deg": math.degrees(a2), "l2_m": l2, "rws_m": rws}
                                          for a2, l2, rws in designs.tolist()],
           **model_bands(designs, road, settings_from_args(args, vehicle), vehicle)}
    if args.json:
        print_json(out)
        return 0
    base = out["baseline"]
    best = "none" if base["best"] is None else f"design {base['best'] + 1} (line {base['best'] + 2} of the file)"
    print(f"{len(designs)} designs on {road.spec}; the best with the model as given: {best}")
    print(f"{'alternative':<22} {'rank_correlation':>16} {'same_best':>9} {'largest_change_m':>16} {'failed':>6}  what")
    for name, alt in out["alternatives"].items():
        rho = "-" if alt["rank_correlation"] is None else f"{alt['rank_correlation']:.3f}"
        change = "-" if alt["largest_change_m"] is None else f"{alt['largest_change_m']:.4f}"
        failed = sum(f is None for f in alt["fitness_m"])
        print(f"{name:<22} {rho:>16} {'yes' if alt['same_best'] else 'no':>9} {change:>16} {failed:>6}  {alt['what']}")
    if out["skipped"]:
        print(f"not applicable to this road: {', '.join(out['skipped'])}")
    return 0


def _checked_designs(path: str, vehicle: Any) -> Any:
    """A designs CSV (a2_deg,l2_m,rws_m) as rows (a2 [rad], L2, R_WS), each a design the vehicle allows."""
    from finaldrive.engine import Design, DesignError

    designs = read_designs_csv(path)
    for line, (a2, l2, rws) in enumerate(designs.tolist(), start=2):
        try:
            vehicle.check_design(Design(a2, l2, rws))
        except DesignError as exc:
            raise UsageError(f"designs file {path!r}, line {line}: {exc}") from None
    return designs


# --- calibrate ------------------------------------------------------------------------------

def run_calibrate(args: argparse.Namespace) -> int:
    from finaldrive.engine import VehicleError, solve_chassis_cog, solve_torque, static_loads

    vehicle = load_vehicle_arg(args.vehicle, args.drive)
    out = writable(args.out, "--out")
    if not args.skip_cog:
        vehicle = solve_chassis_cog(vehicle)
    if not args.skip_torque:
        try:
            vehicle = solve_torque(vehicle)
        except VehicleError as exc:
            raise UsageError(f"{exc} (--skip-torque keeps it)") from None
    loads = static_loads(vehicle)
    out.write_text(json.dumps(vehicle.to_dict(), indent=2) + "\n")
    print_json({"chassis_cog_x_m": vehicle["chassis_cog_x"], "chassis_cog_y_m": vehicle["chassis_cog_y"],
                "torque_nm": vehicle["torque"], "rear_share": loads.rear_share,
                "cog_height_m": loads.cog_height, "wheelbase_m": loads.wheelbase, "out": args.out})
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("geometry", help=COMMANDS["geometry"].help,
                       **parser_options())
    add_design_args(p)
    add_vehicle_arg(p)
    add_json_arg(p)
    p.add_argument("--travel", action="store_true", help="also SR, anti-squat %%, chain growth and the sprocket-pivot "
                   "geometry from full extension to full compression of the rear suspension, static sag marked")
    p.add_argument("--points", type=int, default=None, help="--travel: points of the curve (2-201; default 25)")
    p.add_argument("--png", metavar="FILE.png", help="plot the travel curve to FILE (implies --travel)")
    p.add_argument("--road", help="also simulate once on this road and report the rear travel and chassis pitch "
                   "under drive beside the static prediction; " + ROAD_HELP)
    add_settings_args(p)
    p.set_defaults(run=run_geometry)

    p = sub.add_parser("simulate", help=COMMANDS["simulate"].help, **parser_options())
    add_design_args(p)
    p.add_argument("--road", required=True, help=ROAD_HELP)
    add_vehicle_arg(p)
    add_settings_args(p)
    add_json_arg(p)
    p.add_argument("--series", metavar="FILE.csv", help="also write the time series (Fig. 13 quantities) as CSV")
    p.add_argument("--stride", type=int, default=10, help="--series: keep every n-th output interval")
    p.add_argument("--record", metavar="FILE.rrd", help="also write a rerun recording (open it with `rerun FILE.rrd`)")
    p.add_argument("--fps", type=int, default=50, help="--record: frames per simulated second")
    p.set_defaults(run=run_simulate)

    p = sub.add_parser("evaluate", help=COMMANDS["evaluate"].help,
                       **parser_options())
    p.add_argument("--designs", required=True, metavar="FILE.csv", help="CSV with the header a2_deg,l2_m,rws_m")
    p.add_argument("--road", required=True, help=ROAD_HELP)
    add_vehicle_arg(p)
    add_settings_args(p)
    add_json_arg(p, "print a JSON list instead of CSV")
    p.set_defaults(run=run_evaluate)

    p = sub.add_parser("model-band", help=COMMANDS["model-band"].help, **parser_options())
    p.add_argument("--designs", required=True, metavar="FILE.csv", help="CSV with the header a2_deg,l2_m,rws_m "
                   "(at least 2 designs)")
    p.add_argument("--road", required=True, help=ROAD_HELP)
    add_vehicle_arg(p)
    add_settings_args(p)
    add_json_arg(p, "print JSON: every design's fitness and distance under each alternative")
    p.set_defaults(run=run_model_band)

    p = sub.add_parser("calibrate", help=COMMANDS["calibrate"].help,
                       **parser_options())
    add_vehicle_arg(p)
    p.add_argument("--out", required=True, metavar="FILE", help="where to write the calibrated vehicle file")
    p.add_argument("--skip-cog", action="store_true", help="keep the chassis centre of mass")
    p.add_argument("--skip-torque", action="store_true", help="keep the drive torque")
    p.set_defaults(run=run_calibrate)
