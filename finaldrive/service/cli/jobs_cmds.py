"""Job client commands: submit, jobs, status, results, best, cancel (HTTP to the service)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from finaldrive.service.cli import remote
from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import (
    UsageError,
    add_de_args,
    add_tolerance_arg,
    de_from_args,
    de_options,
    load_vehicle_arg,
    parser_options,
    print_json,
    writable,
)
from finaldrive.service.cli.remote import (
    EXIT_JOB_NOT_SUCCEEDED,
    EXIT_OK,
    add_server_args,
    best_fitness,
    client_command,
    exit_codes_epilog,
    finished,
    follow,
    progress_line,
)
from finaldrive.service.cli.sharpness_view import (
    band_lines,
    model_band_lines,
    near_lines,
    sensitivity_lines,
    spread_text,
)

if TYPE_CHECKING:
    from finaldrive.service.client import ServiceClient


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
    if args.drive is not None:  # the whole vehicle goes with the job: the file's or the paper's, with this drive
        spec["vehicle"] = load_vehicle_arg(args.vehicle, args.drive).to_dict()
    if args.kind == "sweep":
        if args.grid is not None:
            spec["grid"] = args.grid
        return spec
    if args.grid is not None:
        raise UsageError(f"--grid is only for sweep, not {args.kind}")
    # checked here (an error names the option); the server resolves what was not given
    bounds, _ = de_from_args(args, "paper" if args.kind == "paper-study" else "default")
    spec["de"] = de_options(args)
    spec["bounds"] = {k: list(v) for k, v in vars(bounds).items()}
    if args.kind == "robust-de":
        spec["aggregate"] = args.aggregate
    elif args.aggregate != "mean":
        raise UsageError("--aggregate is only for robust-de")
    return spec


def upload_profiles(client: ServiceClient, roads: list[str]) -> list[str]:
    """The roads with each ``profile:FILE`` uploaded (POST /v1/roads) and named ``profile:ID``."""
    from finaldrive.service.client import ApiError

    out = []
    for road in roads:
        path = Path(road[len("profile:"):]) if road.lower().startswith("profile:") else None
        if path is None or (road[len("profile:"):].isdigit() and not path.exists()):
            out.append(road)  # a preset, spec or stored profile:ID
            continue
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise UsageError(f"road profile {str(path)!r}: {getattr(exc, 'strerror', None) or exc}") from None
        try:
            out.append(client.upload_profile(text, name=path.name[:64])["spec"])
        except ApiError as exc:
            raise UsageError(f"road profile {str(path)!r}: {exc.detail}") from None
    return out


@client_command
def run_submit(args: argparse.Namespace) -> int:
    spec = job_spec(args)
    with remote.connect(args) as client:
        spec["roads"] = upload_profiles(client, spec["roads"])
        job = client.submit(spec, idempotency_key=args.idempotency_key)
        best = None
        if args.follow:
            job = follow(client, job["id"])
            if not args.json and job["done"]:   # each best with its near-optimal set, as `finaldrive best` prints it
                best = client.best(job["id"])
    if args.json:
        print_json(job)
    else:
        print(f"job {job['id']}: {job['kind']} on {len(job['roads'])} road(s), {job['total']} evaluations, "
              f"{job['state']}")
        if args.follow:
            _print_best(best or job)
    return finished(job) if args.follow else EXIT_OK


@client_command
def run_jobs(args: argparse.Namespace) -> int:
    with remote.connect(args) as client:
        items = client.jobs(state=args.state, kind=args.kind, limit=args.limit)
    if args.json:
        print_json(items)
        return EXIT_OK
    print(f"{'id':>5}  {'kind':<9}  {'state':<11}  {'progress':>13}  {'fitness_m':>9}  created_at")
    for job in items:
        best = best_fitness(job)
        done = f"{job['done'] + job['failed']}/{job['total']}"
        print(f"{job['id']:>5}  {job['kind']:<9}  {job['state']:<11}  {done:>13}  "
              f"{'-' if best is None else f'{best:.3f}':>9}  {job['created_at'][:19]}")
    return EXIT_OK


@client_command
def run_status(args: argparse.Namespace) -> int:
    with remote.connect(args) as client:
        job = follow(client, args.id) if args.follow else client.job(args.id)
    if args.json:
        print_json(job)
    else:
        if not args.follow:
            print(progress_line(job))
        if job.get("error"):
            print(f"error: {job['error']}")
    return finished(job) if args.follow else EXIT_OK


@client_command
def run_results(args: argparse.Namespace) -> int:
    with remote.connect(args) as client:
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
        writable(args.csv, "--csv").write_text(text)
        print(f"wrote {max(text.count(chr(10)) - 1, 0)} evaluations to {args.csv}")
    else:
        sys.stdout.write(text)
    return EXIT_OK


def _print_best(best: dict[str, Any]) -> None:
    print(f"{'road':<18} {'a2_deg':>8} {'l2_m':>8} {'rws_m':>8} {'fitness_m':>12} {'distance_m':>13}")
    for road in best["roads"]:
        b = road.get("best")
        if b is None:
            print(f"{road['name']:<18} {'(no successful evaluation)':>52}")
        else:
            print(f"{road['name']:<18} {b['a2_deg']:>8.1f} {b['l2_m']:>8.4f} {b['rws_m']:>8.4f} "
                  f"{b['fitness_m']:>12.3f} {b['distance_m']:>13.3f}")
    rb = best.get("robust_best")
    if rb:
        score = "-" if rb["score_m"] is None else f"{rb['score_m']:.3f}"
        print(f"robust ({rb['aggregate']}): a2_deg {rb['a2_deg']:.1f}  l2_m {rb['l2_m']:.4f}  rws_m {rb['rws_m']:.4f}  "
              f"score {score} m")
    for sharp in best.get("sharpness", []):
        print(f"\nsharpness on {sharp['road'] or 'all roads (aggregate score)'}:")
        print("\n".join(near_lines(sharp)))
        if sharp.get("sensitivity"):
            print("\n".join(sensitivity_lines(sharp["sensitivity"], sharp["tolerance_m"])))
        if sharp.get("numerical_band"):
            print("\n".join(band_lines(sharp["numerical_band"], sharp["ties"])))
        if sharp.get("model_bands"):
            print("\n".join(model_band_lines(sharp["model_bands"])))
        pop = sharp.get("final_population")
        if pop:
            print(f"  final DE population ({pop['count']} designs): {spread_text(pop['ranges'])}")


@client_command
def run_best(args: argparse.Namespace) -> int:
    with remote.connect(args) as client:
        best = client.best(args.id, args.tolerance_pct, args.sensitivity, band=args.band, model_band=args.model_band)
    if args.json:
        print_json(best)
    else:
        _print_best(best)
    return EXIT_OK


@client_command
def run_cancel(args: argparse.Namespace) -> int:
    with remote.connect(args) as client:
        job = client.cancel(args.id)
    if args.json:
        print_json(job)
    else:
        print(f"job {job['id']}: {job['state']}")
    return EXIT_OK




def register(sub: Any) -> None:
    from finaldrive.service.cli.common import ROAD_HELP, add_settings_args, add_vehicle_arg

    p = sub.add_parser("submit", help=COMMANDS["submit"].help,
                       epilog=exit_codes_epilog(), **parser_options())
    p.add_argument("kind", choices=("sweep", "de", "robust-de"),
                   help="sweep: a design grid on each road; de: the paper's DE on each road; "
                        "robust-de: one DE scored over all the roads")
    p.add_argument("--road", action="append",
                   help=f"a road (repeatable): {ROAD_HELP}; a profile file is uploaded first (profile:ID names "
                        "one uploaded before)")
    p.add_argument("--roads", action="append", help="comma-separated roads, or a group (paper, sine, bump)")
    p.add_argument("--grid", help='sweep: "table9" (the default) or e.g. "a2_deg=0:350:10,l2_m=0:0.2:0.02,rws_m=0.093"')
    add_de_args(p)
    add_vehicle_arg(p)
    p.add_argument("--aggregate", choices=("mean", "worst"), default="mean",
                   help="robust-de: a design's score over the roads")
    add_settings_args(p)
    p.add_argument("--idempotency-key", help="resubmitting with the same key returns the same job")
    p.add_argument("--follow", action="store_true", help="show progress until the job ends, then its best designs")
    add_server_args(p)
    p.set_defaults(run=run_submit)

    p = sub.add_parser("jobs", help=COMMANDS["jobs"].help, **parser_options())
    p.add_argument("--state", choices=("queued", "running", "succeeded", "failed", "cancelled", "interrupted"),
                   help="only jobs in this state (default: any)")
    p.add_argument("--kind", choices=("sweep", "de", "robust-de", "paper-study", "designs"),
                   help="only jobs of this kind (default: any)")
    p.add_argument("--limit", type=int, default=20, help="how many jobs to list")
    add_server_args(p)
    p.set_defaults(run=run_jobs)

    p = sub.add_parser("status", help=COMMANDS["status"].help,
                       epilog=exit_codes_epilog(), **parser_options())
    p.add_argument("id", type=int, help="job id")
    p.add_argument("--follow", action="store_true",
                   help=f"wait for the end; exit {EXIT_JOB_NOT_SUCCEEDED} if the job fails or is cancelled")
    add_server_args(p)
    p.set_defaults(run=run_status)

    p = sub.add_parser("results", help=COMMANDS["results"].help, **parser_options())
    p.add_argument("id", type=int, help="job id")
    p.add_argument("--csv", metavar="FILE", help="write the CSV to this file instead of stdout")
    p.add_argument("--road", help="only this road (name, spec or index; default: every road)")
    add_server_args(p)
    p.set_defaults(run=run_results)

    p = sub.add_parser("best", help=COMMANDS["best"].help,
                       **parser_options())
    p.add_argument("id", type=int, help="job id")
    add_tolerance_arg(p)
    p.add_argument("--sensitivity", action="store_true",
                   help="also the finite differences at each road's best (of a finished job: its scheduler runs 7 "
                   "simulations a road as a job of kind designs; waits for them, at most 10 minutes)")
    p.add_argument("--band", action="store_true",
                   help="also each road's best designs' numerical bands and ties (of a finished job: its scheduler "
                   "re-simulates up to 5 designs a road 100x tighter and with the reference method; waits for them)")
    p.add_argument("--model-band", action="store_true",
                   help="also each road's best designs under each documented modelling alternative, with the rank "
                   "correlation of each (of a finished job: its scheduler simulates them; waits for them)")
    add_server_args(p)
    p.set_defaults(run=run_best)

    p = sub.add_parser("cancel", help=COMMANDS["cancel"].help, **parser_options())
    p.add_argument("id", type=int, help="job id")
    add_server_args(p)
    p.set_defaults(run=run_cancel)
