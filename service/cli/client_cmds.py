"""Job client commands: submit, jobs, status, results, best, cancel, record, plot, demo.

They speak only HTTP to the service (``--server``, default ``$FINALDRIVE_SERVER`` or
http://127.0.0.1:8000; bearer token from ``$FINALDRIVE_API_TOKEN``). ``record`` and
``plot`` also work locally, without a server. Exit codes: see :data:`EXIT_CODES`.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from service.cli import UsageError
from service.cli.engine_cmds import print_json, road_from_arg
from service.cli.study_cmds import add_de_args

EXIT_OK = 0
EXIT_FAILED = 1          # the thing asked for failed (a simulation, a recording)
EXIT_USAGE = 2           # bad arguments
EXIT_JOB_NOT_SUCCEEDED = 3  # --follow: the job ended failed or cancelled
EXIT_HTTP = 4            # the service answered 4xx/5xx
EXIT_UNREACHABLE = 5     # no answer from the service
EXIT_CODES = {EXIT_OK: "success", EXIT_FAILED: "the simulation or recording failed", EXIT_USAGE: "bad arguments",
              EXIT_JOB_NOT_SUCCEEDED: "--follow: the job ended failed or cancelled",
              EXIT_HTTP: "the service answered with an HTTP error (4xx/5xx)",
              EXIT_UNREACHABLE: "the service could not be reached"}
TERMINAL = ("succeeded", "failed", "cancelled")

Runner = Callable[..., int]


def _client(args: argparse.Namespace) -> Any:
    from service.client import ServiceClient

    return ServiceClient(getattr(args, "server", None))


def client_command(fn: Runner) -> Runner:
    """Map the client's errors to one line on stderr and an exit code."""

    @functools.wraps(fn)
    def run(*args: Any) -> int:
        from service.client import ApiError, Unreachable

        try:
            return fn(*args)
        except ApiError as exc:
            print(f"finaldrive: error: {exc}", file=sys.stderr)
            return EXIT_HTTP
        except Unreachable as exc:
            print(f"finaldrive: error: {exc}", file=sys.stderr)
            return EXIT_UNREACHABLE

    return run


# --- progress -------------------------------------------------------------------------------

def best_fitness(job: dict[str, Any]) -> float | None:
    """Best fitness so far over the job's roads (robust-de: the aggregate score)."""
    if job.get("robust_best") and job["robust_best"].get("score_m") is not None:
        return float(job["robust_best"]["score_m"])
    values = [r["best"]["fitness_m"] for r in job["roads"] if r.get("best") and r["best"]["fitness_m"] is not None]
    return max(values) if values else None


def progress_line(job: dict[str, Any], width: int = 24) -> str:
    """``job 3 running [#####.....] 40/84 failed 1 best 20.31 m ETA 12 s``."""
    total = max(int(job["total"]), 1)
    completed = job["done"] + job["failed"]
    filled = min(width, int(width * completed / total))
    best = best_fitness(job)
    eta = job.get("eta_s")
    parts = [f"job {job['id']} {job['state']:<9} [{'#' * filled}{'.' * (width - filled)}] {completed}/{total}",
             f"failed {job['failed']}", f"best {best:.3f} m" if best is not None else "best -"]
    if eta is not None and job["state"] == "running":
        parts.append(f"ETA {_duration(eta)}")
    return "  ".join(parts)


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60}m{seconds % 60:02d}s" if seconds >= 60 else f"{seconds}s"


def follow(client: Any, job_id: int, *, out: TextIO | None = None, interval: float = 0.5,
           sleep: Callable[[float], None] = time.sleep) -> dict[str, Any]:
    """Poll the job until it is finished, drawing the progress bar on ``out`` (stderr); returns the job."""
    out = out or sys.stderr
    tty = out.isatty()
    last = ""
    while True:
        job = client.job(job_id)
        line = progress_line(job)
        if line != last:
            out.write(("\r" + line + "\033[K") if tty else line + "\n")
            out.flush()
            last = line
        if job["state"] in TERMINAL:
            if tty:
                out.write("\n")
            return dict(job)
        sleep(interval)


def _finished(job: dict[str, Any]) -> int:
    if job["state"] != "succeeded":
        print(f"finaldrive: job {job['id']} {job['state']}" + (f": {job['error']}" if job.get("error") else ""),
              file=sys.stderr)
        return EXIT_JOB_NOT_SUCCEEDED
    return EXIT_OK


# --- submit / jobs / status / results / best / cancel ---------------------------------------

def job_spec(args: argparse.Namespace) -> dict[str, Any]:
    """The service's job spec from the submit options."""
    roads = list(args.road or []) + [r.strip() for text in (args.roads or []) for r in text.split(",") if r.strip()]
    if not roads:
        raise UsageError("give at least one --road or --roads")
    settings: dict[str, Any] = {"duration": args.duration, "method": args.method}
    if args.dt is not None:
        settings["dt"] = args.dt
    spec: dict[str, Any] = {"kind": args.kind, "roads": roads, "seed": args.seed, "settings": settings}
    if args.vehicle is not None:
        try:
            spec["vehicle"] = json.loads(Path(args.vehicle).read_text())
        except (OSError, ValueError) as exc:
            raise UsageError(f"--vehicle {args.vehicle!r}: {exc}") from None
    if args.kind == "sweep":
        if args.grid is not None:
            spec["grid"] = args.grid
        return spec
    if args.grid is not None:
        raise UsageError(f"--grid is only for sweep, not {args.kind}")
    de = {"np": args.np, "iters": args.iters, "f": args.f, "cp": args.cp, "mp": args.mp, "mr_fraction": args.mr}
    de.update({k: v for k, v in (("patience", args.patience), ("max_evals", args.max_evals)) if v is not None})
    spec["de"] = de
    if args.bounds is not None:
        from service.cli.study_cmds import parse_bounds

        lower, upper = parse_bounds(args.bounds)
        spec["bounds"] = {"a2_deg": [math.degrees(lower[0]), math.degrees(upper[0])],
                          "l2_m": [lower[1], upper[1]], "rws_m": [lower[2], upper[2]]}
    if args.kind == "robust-de":
        spec["aggregate"] = args.objective
    elif args.objective != "mean":
        raise UsageError("--objective is only for robust-de")
    return spec


@client_command
def run_submit(args: argparse.Namespace) -> int:
    spec = job_spec(args)
    with _client(args) as client:
        job = client.submit(spec, idempotency_key=args.idempotency_key)
        if args.follow:
            job = follow(client, job["id"])
    if args.json:
        print_json(job)
    else:
        print(f"job {job['id']}: {job['kind']} on {len(job['roads'])} road(s), {job['total']} evaluations, "
              f"{job['state']}")
        if args.follow:
            _print_best(job)
    return _finished(job) if args.follow else EXIT_OK


@client_command
def run_jobs(args: argparse.Namespace) -> int:
    with _client(args) as client:
        items = client.jobs(state=args.state, kind=args.kind, limit=args.limit)
    if args.json:
        print_json(items)
        return EXIT_OK
    print(f"{'id':>5}  {'kind':<9}  {'state':<11}  {'progress':>13}  {'best [m]':>9}  created")
    for job in items:
        best = best_fitness(job)
        done = f"{job['done'] + job['failed']}/{job['total']}"
        print(f"{job['id']:>5}  {job['kind']:<9}  {job['state']:<11}  {done:>13}  "
              f"{'-' if best is None else f'{best:.3f}':>9}  {job['created_at'][:19]}")
    return EXIT_OK


@client_command
def run_status(args: argparse.Namespace) -> int:
    with _client(args) as client:
        job = follow(client, args.id) if args.follow else client.job(args.id)
    if args.json:
        print_json(job)
    else:
        if not args.follow:
            print(progress_line(job))
        if job.get("error"):
            print(f"error: {job['error']}")
    return _finished(job) if args.follow else EXIT_OK


@client_command
def run_results(args: argparse.Namespace) -> int:
    with _client(args) as client:
        if args.json:
            items: list[dict[str, Any]] = []
            cursor = None
            while True:
                params: dict[str, Any] = {"limit": 10_000, **({"road": args.road} if args.road else {}),
                                          **({"cursor": cursor} if cursor else {})}
                page = client.json("GET", f"/v1/jobs/{args.id}/evaluations", params=params)
                items.extend(page["items"])
                cursor = page["next_cursor"]
                if not cursor:
                    break
            print_json(items)
            return EXIT_OK
        text = "".join(client.evaluations_csv(args.id, args.road))
    if args.csv:
        Path(args.csv).write_text(text)
        print(f"wrote {max(text.count(chr(10)) - 1, 0)} evaluations to {args.csv}")
    else:
        sys.stdout.write(text)
    return EXIT_OK


def _print_best(best: dict[str, Any]) -> None:
    print(f"{'road':<18} {'a2_deg':>8} {'l2 [m]':>8} {'rws [m]':>8} {'fitness [m]':>12} {'distance [m]':>13}")
    for road in best["roads"]:
        b = road.get("best")
        if b is None:
            print(f"{road['name']:<18} {'(no successful evaluation)':>52}")
        else:
            print(f"{road['name']:<18} {b['a2_deg']:>8.1f} {b['l2']:>8.4f} {b['rws']:>8.4f} "
                  f"{b['fitness_m']:>12.3f} {b['distance_m']:>13.3f}")
    rb = best.get("robust_best")
    if rb:
        score = "-" if rb["score_m"] is None else f"{rb['score_m']:.3f}"
        print(f"robust ({rb['aggregate']}): a2_deg {rb['a2_deg']:.1f}  l2 {rb['l2']:.4f}  rws {rb['rws']:.4f}  "
              f"score {score} m")


@client_command
def run_best(args: argparse.Namespace) -> int:
    with _client(args) as client:
        best = client.best(args.id)
    if args.json:
        print_json(best)
    else:
        _print_best(best)
    return EXIT_OK


@client_command
def run_cancel(args: argparse.Namespace) -> int:
    with _client(args) as client:
        job = client.cancel(args.id)
    if args.json:
        print_json(job)
    else:
        print(f"job {job['id']}: {job['state']}")
    return EXIT_OK


# --- record ---------------------------------------------------------------------------------

def parse_design(text: str) -> tuple[float, float, float]:
    """``"A,L,R"``: a2 [deg], L2 [m], R_WS [m]."""
    try:
        a2, l2, rws = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"design {text!r}: expected A2_DEG,L2,RWS (e.g. 0,0.0,0.093)") from None
    return a2, l2, rws


def _designs(texts: list[str]) -> list[tuple[str, Any]]:
    from engine import Design, DesignError

    out = []
    for text in texts:
        a2, l2, rws = parse_design(text)
        try:
            out.append((f"a2={a2:g} L2={l2:g} Rws={rws:g}", Design.from_deg(a2, l2, rws)))
        except DesignError as exc:
            raise UsageError(f"design {text!r}: {exc}") from None
    return out


def run_record(args: argparse.Namespace) -> int:
    if args.server or args.job is not None:
        return _record_remote(args)
    if not args.designs:
        raise UsageError("give --compare/--design (local) or --job/--server (through the service)")
    if args.road is None:
        raise UsageError("--road is required for a local recording")
    from service.recording import RecordingError, record

    road = road_from_arg(args.road)
    try:
        runs = record(args.out, _designs(args.designs), road, duration=args.duration, fps=args.fps)
    except RecordingError as exc:
        print(f"finaldrive: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    summary = {"out": args.out, "road": road.spec, "frames": len(runs[0].series["t"]),
               "geometries": [{"label": r.label, "distance_m": float(r.series["distance"][-1])} for r in runs]}
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {args.out}: {len(runs)} geometries, {summary['frames']} frames on {road.spec} (open: rerun {args.out})")
    return EXIT_OK


@client_command
def _record_remote(args: argparse.Namespace) -> int:
    body: dict[str, Any] = {"duration": args.duration, "fps": args.fps}
    if args.job is not None:
        body["job_id"] = args.job
    if args.road is not None:
        body["road"] = args.road
    body["designs"] = [dict(zip(("a2_deg", "l2", "rws"), parse_design(t))) for t in args.designs or []]
    with _client(args) as client:
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
        size = client.download_recording(rec["id"], Path(args.out))
    if args.json:
        print_json({**rec, "out": args.out, "bytes": size})
    else:
        labels = ", ".join(d["label"] for d in rec["designs"])
        print(f"wrote {args.out} (recording {rec['id']}, {size} bytes, {rec['frames']} frames): {labels} on {rec['road']}")
    return EXIT_OK


# --- plot -----------------------------------------------------------------------------------

def run_plot(args: argparse.Namespace) -> int:
    if args.id is not None:
        return _plot_remote(args)
    if not args.series or args.road is None:
        raise UsageError("give a job ID (through the service) or --series DESIGN... --road ROAD (local)")
    from engine import SimSettings
    from service import plots
    from service.recording import RecordingError, simulate_runs

    road = road_from_arg(args.road)
    try:
        runs = simulate_runs(_designs(args.series), road, SimSettings(duration=args.duration, series=True, series_stride=5))
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
    with _client(args) as client:
        png = client.plot(args.id, args.kind, args.road)
    Path(args.out).write_bytes(png)
    _wrote(args, len(png))
    return EXIT_OK


# --- demo -----------------------------------------------------------------------------------

def run_demo(args: argparse.Namespace) -> int:
    from service.cli.demo import run_demo as demo

    return demo(args)


# --- registration ---------------------------------------------------------------------------

def _common(p: argparse.ArgumentParser, *, server_default: bool = True) -> None:
    help_ = "service URL (default $FINALDRIVE_SERVER or http://127.0.0.1:8000)"
    if not server_default:
        help_ = "record/plot through this service instead of locally"
    p.add_argument("--server", metavar="URL", help=help_)
    p.add_argument("--json", action="store_true", help="print JSON (for scripts)")


def register(sub: Any) -> None:
    codes = "; ".join(f"{k} {v}" for k, v in EXIT_CODES.items())

    p = sub.add_parser("submit", help="submit a sweep, de or robust-de job to the service",
                       epilog=f"exit codes: {codes}")
    p.add_argument("kind", choices=("sweep", "de", "robust-de"))
    p.add_argument("--road", action="append", help="a road (repeatable): preset, group or spec")
    p.add_argument("--roads", action="append", help="comma-separated roads or a group (paper, sine, bump)")
    p.add_argument("--grid", help='sweep: "table9" (default) or e.g. "a2_deg=0:350:10,l2=0:0.2:0.02,rws=0.093"')
    add_de_args(p)
    p.add_argument("--bounds", metavar="SPEC", help="DE box: a2_deg=LO:HI,l2=LO:HI,rws=LO:HI (default Table 8)")
    p.add_argument("--vehicle", metavar="FILE", help="vehicle parameter file (JSON, as engine/data/vehicle.json)")
    p.add_argument("--objective", choices=("mean", "worst"), default="mean", help="robust-de aggregate")
    p.add_argument("--duration", type=float, default=3.5, help="simulated time [s] (default 3.5)")
    p.add_argument("--dt", type=float, help="time step [s]")
    p.add_argument("--method", choices=("fast", "reference"), default="fast", help="engine (default fast)")
    p.add_argument("--idempotency-key", help="resubmitting with the same key returns the same job")
    p.add_argument("--follow", action="store_true", help="show progress until the job ends")
    _common(p)
    p.set_defaults(run=run_submit)

    p = sub.add_parser("jobs", help="list the service's jobs, newest first")
    p.add_argument("--state", choices=("queued", "running", "succeeded", "failed", "cancelled", "interrupted"))
    p.add_argument("--kind", choices=("sweep", "de", "robust-de", "paper-study"))
    p.add_argument("--limit", type=int, default=20)
    _common(p)
    p.set_defaults(run=run_jobs)

    p = sub.add_parser("status", help="a job's progress; --follow draws a progress bar until it ends",
                       epilog=f"exit codes: {codes}")
    p.add_argument("id", type=int)
    p.add_argument("--follow", action="store_true", help=f"wait; exit {EXIT_JOB_NOT_SUCCEEDED} if the job fails or is cancelled")
    _common(p)
    p.set_defaults(run=run_status)

    p = sub.add_parser("results", help="a job's evaluations as CSV (stdout or --csv FILE)")
    p.add_argument("id", type=int)
    p.add_argument("--csv", metavar="FILE", help="write the CSV here")
    p.add_argument("--road", help="only this road (name, spec or index)")
    _common(p)
    p.set_defaults(run=run_results)

    p = sub.add_parser("best", help="a job's best design per road")
    p.add_argument("id", type=int)
    _common(p)
    p.set_defaults(run=run_best)

    p = sub.add_parser("cancel", help="cancel a job")
    p.add_argument("id", type=int)
    _common(p)
    p.set_defaults(run=run_cancel)

    p = sub.add_parser("record", help="a Rerun .rrd of designs side by side on a road (local, or --job/--server)",
                       epilog='e.g. finaldrive record --compare "0,0,0.093" "270,0.15,0.15" --road sine:0.04:3 --out g.rrd')
    p.add_argument("--compare", dest="designs", nargs="+", action="extend", metavar="A2,L2,RWS",
                   help="designs: a2 [deg], L2 [m], R_WS [m]")
    p.add_argument("--design", dest="designs", action="append", metavar="A2,L2,RWS", help="one more design")
    p.add_argument("--job", type=int, help="through the service: record this job's best design first")
    p.add_argument("--road", help="road spec or preset (with --job: one of the job's roads; default its first)")
    p.add_argument("--out", required=True, metavar="FILE.rrd")
    p.add_argument("--duration", type=float, default=3.5, help="simulated time [s] (default 3.5)")
    p.add_argument("--fps", type=int, default=50, help="frames per simulated second (default 50)")
    p.add_argument("--timeout", type=float, default=300, help="service: seconds to wait for the file")
    _common(p, server_default=False)
    p.set_defaults(run=run_record)

    p = sub.add_parser("plot", help="PNG: a job's sweep map or DE history (service), or Fig. 13 series (local)")
    p.add_argument("id", type=int, nargs="?", help="job id (through the service)")
    p.add_argument("--kind", choices=("sweep-map", "de-history"), default="sweep-map")
    p.add_argument("--road", help="road (job: name, spec or index; --series: spec or preset)")
    p.add_argument("--series", nargs="+", metavar="A2,L2,RWS", help="local: simulate these designs, plot Fig. 13")
    p.add_argument("--duration", type=float, default=3.5, help="--series: simulated time [s]")
    p.add_argument("--out", required=True, metavar="FILE.png")
    _common(p)
    p.set_defaults(run=run_plot)

    p = sub.add_parser("demo", help="start a local service (Ray executor), run a small DE, print the best, stop")
    p.add_argument("--port", type=int, help="port (default: a free one)")
    p.add_argument("--db", default="sqlite:///./finaldrive.db", help="database URL (default ./finaldrive.db)")
    p.add_argument("--executor", choices=("serial", "process", "ray"), default="ray")
    p.add_argument("--np", type=int, default=12)
    p.add_argument("--iters", type=int, default=6)
    p.add_argument("--road", default="sine:0.04:3")
    p.add_argument("--json", action="store_true", help="print the best design as JSON")
    p.set_defaults(run=run_demo)

