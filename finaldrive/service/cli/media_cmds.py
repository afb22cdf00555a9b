"""record (a rerun recording) and plot (PNG): locally, or through the service."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from finaldrive.service.cli import remote
from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import ROAD_HELP, UsageError, parser_options, print_json, road_from_arg, writable
from finaldrive.service.cli.remote import EXIT_FAILED, EXIT_OK, add_server_args, client_command


def parse_design(text: str) -> tuple[float, float, float]:
    """``"A,L,R"``: a2 [deg], L2 [m], R_WS [m]."""
    try:
        a2, l2, rws = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"design {text!r}: expected A2_DEG,L2,RWS (e.g. 0,0.0,0.093)") from None
    return a2, l2, rws


def _designs(texts: list[str]) -> list[tuple[str, Any]]:
    from finaldrive.engine import Design, DesignError, default_vehicle, design_label

    out = []
    for text in texts:
        a2, l2, rws = parse_design(text)
        try:
            design = Design.from_deg(a2, l2, rws)
            default_vehicle().check_design(design)
            out.append((design_label(a2, l2, rws), design))
        except DesignError as exc:
            raise UsageError(f"design {text!r}: {exc}") from None
    return out


def run_record(args: argparse.Namespace) -> int:
    if args.server or args.job_id is not None:
        return _record_remote(args)
    if not args.designs:
        raise UsageError("give --compare/--design (local) or --job-id/--server (through the service)")
    if args.road is None:
        raise UsageError("--road is required for a local recording")
    from finaldrive.service.media.recording import RecordingError, record

    road = road_from_arg(args.road)
    out = writable(args.out, "--out")
    try:
        runs = record(out, _designs(args.designs), road, duration=args.duration, fps=args.fps)
    except RecordingError as exc:
        print(f"finaldrive: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    summary = {"out": args.out, "road": road.spec, "frames": len(runs[0].series["t_s"]),
               "geometries": [{"label": r.label, "distance_m": float(r.series["distance_m"][-1])} for r in runs]}
    if args.json:
        print_json(summary)
    else:
        print(
            f"wrote {args.out}: {len(runs)} geometries, {summary['frames']} frames on {road.spec} "
            f"(open: rerun {args.out})"
        )
    return EXIT_OK


@client_command
def _record_remote(args: argparse.Namespace) -> int:
    body: dict[str, Any] = {"duration": args.duration, "fps": args.fps}
    if args.job_id is not None:
        body["job_id"] = args.job_id
    if args.road is not None:
        body["road"] = args.road
    body["designs"] = [dict(zip(("a2_deg", "l2_m", "rws_m"), parse_design(t), strict=True)) for t in args.designs or []]
    out = writable(args.out, "--out")
    with remote.connect(args) as client:
        rec = client.create_recording(body)
        deadline = time.monotonic() + args.timeout
        while rec["status"] not in ("succeeded", "failed"):
            if time.monotonic() > deadline:
                print(f"finaldrive: error: recording {rec['id']} not ready after {args.timeout:g} s "
                      f"(it is {rec['status']}); fetch it later by id", file=sys.stderr)
                return EXIT_FAILED
            time.sleep(0.3)
            rec = client.recording(rec["id"])
        if rec["status"] == "failed":
            print(f"finaldrive: error: recording {rec['id']} failed: {rec['error']}", file=sys.stderr)
            return EXIT_FAILED
        size = client.download_recording(rec["id"], out)
    if args.json:
        print_json({**rec, "out": args.out, "bytes": size})
    else:
        labels = ", ".join(d["label"] for d in rec["designs"])
        print(
            f"wrote {args.out} (recording {rec['id']}, {size} bytes, {rec['frames']} frames): {labels} on {rec['road']}"
        )
    return EXIT_OK


def run_plot(args: argparse.Namespace) -> int:
    if args.id is not None:
        return _plot_remote(args)
    if not args.series or args.road is None:
        raise UsageError("give a job ID (through the service) or --series DESIGN... --road ROAD (local)")
    from finaldrive.engine import SimSettings
    from finaldrive.service.media import plots
    from finaldrive.service.media.recording import RecordingError, simulate_runs

    road = road_from_arg(args.road)
    writable(args.out, "--out")
    try:
        runs = simulate_runs(
            _designs(args.series), road, SimSettings(duration=args.duration, series=True, series_stride=5)
        )
    except RecordingError as exc:
        print(f"finaldrive: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    plots.series_png(args.out, [(r.label, r.series) for r in runs], title=f"Fig. 13 quantities on {road.spec}")
    _wrote(args, Path(args.out).stat().st_size)
    return EXIT_OK


def _wrote(args: argparse.Namespace, size: int) -> None:
    if args.json:
        print_json({"out": args.out, "bytes": size})
    else:
        print(f"wrote {args.out} ({size} bytes)")


@client_command
def _plot_remote(args: argparse.Namespace) -> int:
    out = writable(args.out, "--out")
    with remote.connect(args) as client:
        png = client.plot(args.id, args.kind, args.road)
    out.write_bytes(png)
    _wrote(args, len(png))
    return EXIT_OK




def register(sub: Any) -> None:
    p = sub.add_parser("record", help=COMMANDS["record"].help,
                       epilog='e.g. finaldrive record --compare "0,0,0.093" "270,0.15,0.15" --road sine:0.04:3 '
                              "--out g.rrd", **parser_options())
    p.add_argument("--compare", dest="designs", nargs="+", action="extend", metavar="A2,L2,RWS",
                   help="designs: a2 [deg], L2 [m], R_WS [m]")
    p.add_argument("--design", dest="designs", action="append", metavar="A2,L2,RWS", help="one more design")
    p.add_argument("--job-id", type=int, help="through the service: record this job's best design first")
    p.add_argument("--road", help=f"{ROAD_HELP} (with --job-id: one of the job's roads; default its first)")
    p.add_argument("--out", required=True, metavar="FILE.rrd", help="the recording to write (open it with `rerun`)")
    p.add_argument("--duration", type=float, default=3.5, help="simulated time [s]")
    p.add_argument("--fps", type=int, default=50, help="frames per simulated second")
    p.add_argument("--timeout", type=float, default=300, help="through the service: seconds to wait for the file")
    add_server_args(p, server_default=False)
    p.set_defaults(run=run_record)

    p = sub.add_parser("plot", help=COMMANDS["plot"].help,
                       **parser_options())
    p.add_argument("id", type=int, nargs="?", help="job id (through the service)")
    p.add_argument("--kind", choices=("sweep-map", "de-history"), default="sweep-map",
                   help="with a job id: the polar map of a sweep's results, or a DE's best and mean by generation")
    p.add_argument("--road", help="a job's road (name, spec or index), or with --series the road to simulate")
    p.add_argument("--series", nargs="+", metavar="A2,L2,RWS", help="local: simulate these designs, plot Fig. 13")
    p.add_argument("--duration", type=float, default=3.5, help="--series: simulated time [s]")
    p.add_argument("--out", required=True, metavar="FILE.png", help="the PNG to write")
    add_server_args(p)
    p.set_defaults(run=run_plot)
