"""``finaldrive demo``: a local service in a subprocess, a small DE through it, the best design.

The server (``finaldrive serve``) runs on a free 127.0.0.1 port with ``--db`` (default
./finaldrive.db) and the chosen executor (default Ray); its log goes to
./finaldrive-demo.log. It is stopped with SIGTERM (then SIGKILL after 30 s) on every exit path.
The engine's compilation (a fresh machine's) starts before the server, so it overlaps the
server's and Ray's start.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import UsageError, parser_options, print_json, stop_process
from finaldrive.service.cli.remote import EXIT_FAILED, EXIT_OK, client_command, follow
from finaldrive.service.cli.sharpness_view import near_lines
from finaldrive.service.machine import free_port

LOG = Path("finaldrive-demo.log")
#: the demo's store: the one `finaldrive serve` opens by default, so the dashboard finds the job there
DEFAULT_DB = "sqlite:///./finaldrive.db"
#: How long the demo waits for its service to be ready by default [s] (--timeout): a loaded machine's
#: first start (imports, the engine's compilation, Ray) took minutes (docs/usage.md).
START_TIMEOUT_S = 900.0
#: When the demo first says what it still waits for, and how often after that [s].
NOTE_FIRST_S, NOTE_EVERY_S = 2.0, 10.0


def start_server(port: int, db: str, executor: str, log: Path) -> subprocess.Popen[bytes]:
    """``finaldrive serve`` for the demo, its simulations at the normal priority (FINALDRIVE_NICENESS=0): they
    are the user's foreground work, which a service runs at niceness 10 so that its API keeps a core; on a
    loaded machine the demo's 84 simulations took 178 s at 10 (docs/usage.md)."""
    cmd = [sys.executable, "-m", "finaldrive.service.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
           "--db", db, "--executor", executor]
    env = {**os.environ, "FINALDRIVE_NICENESS": "0"}
    with log.open("ab") as out:
        return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)


def waiting_for(health: dict[str, Any] | None, executor: str) -> str:
    """What a starting service still lacks, in words: the engine's compilation (with its progress),
    the web service, the scheduler (which starts once Ray is up and the engine compiled)."""
    from finaldrive.engine import compile_progress, is_compiled

    parts = []
    if executor != "serial" and not is_compiled("fast"):
        progress = compile_progress("fast")
        how = (f"{progress[0]} of {progress[1]} kernels" if progress and progress[1] else "tracing its calls"
               if progress else "starting")
        parts.append(f"the engine's compilation (once on this machine; {how})")
    if health is None:
        parts.append("the web service")
    parts.append("the scheduler" + (" (Ray starting)" if executor == "ray" else ""))
    return ", ".join(parts)


def wait_ready(client: Any, proc: subprocess.Popen[bytes], executor: str,
               timeout: float = START_TIMEOUT_S) -> dict[str, Any]:
    """The service's /v1/health once it answers and a scheduler of it is alive (Ray up, the engine
    compiled); after NOTE_FIRST_S, then every NOTE_EVERY_S, says on stderr what it still waits for.
    RuntimeError when the service exits, or after ``timeout`` seconds."""
    from finaldrive.service.client import ClientError

    start = time.monotonic()
    noted = start + NOTE_FIRST_S - NOTE_EVERY_S   # the first note NOTE_FIRST_S in
    while True:
        if proc.poll() is not None:
            raise RuntimeError(f"the service exited with code {proc.returncode} (see {LOG})")
        health = None
        with contextlib.suppress(ClientError):
            health = dict(client.health())
        if health is not None and any(s["alive"] for s in health["schedulers"]):
            return health
        now = time.monotonic()
        if now - start > timeout:
            raise RuntimeError(f"the service was not ready within {timeout:g} s; still waiting for "
                               f"{waiting_for(health, executor)} (see {LOG}; --timeout waits longer)")
        if now - noted >= NOTE_EVERY_S:
            print(f"  {now - start:.0f} s: waiting for {waiting_for(health, executor)}", file=sys.stderr)
            noted = now
        time.sleep(0.25)


def demo_spec(args: argparse.Namespace) -> dict[str, Any]:
    return {"kind": "de", "roads": [args.road], "de": {"np": args.np, "iters": args.iters}, "seed": 1,
            "settings": {"method": "fast", "duration": 3.5}}


def run_demo(args: argparse.Namespace) -> int:
    from finaldrive.service.client import ServiceClient

    if args.timeout <= 0:
        raise UsageError(f"--timeout must be > 0, not {args.timeout:g}")
    if args.executor != "serial":
        from finaldrive.engine import compile_engine

        compile_engine()   # now, so it overlaps the service's start; the service's scheduler waits for it
    started = time.monotonic()
    port = args.port or free_port()
    url = f"http://127.0.0.1:{port}"
    print(f"starting the service at {url} ({args.executor} executor, {args.db}; log: {LOG})", file=sys.stderr)
    proc = start_server(port, args.db, args.executor, LOG)
    try:
        with ServiceClient(url) as client:
            try:
                health = wait_ready(client, proc, args.executor, args.timeout)
            except RuntimeError as exc:
                print(f"finaldrive: error: {exc}", file=sys.stderr)
                return EXIT_FAILED
            executors = ", ".join(f"{s['executor']} ({s['capacity']} tasks)"
                                  for s in health["schedulers"] if s["alive"])
            print(f"service up after {time.monotonic() - started:.0f} s: engine {health['engine_version']}, "
                  f"scheduler: {executors}", file=sys.stderr)
            return _run_job(args, client)
    finally:
        print("stopping the service", file=sys.stderr)
        stop_process(proc, 30.0)


@client_command
def _run_job(args: argparse.Namespace, client: Any) -> int:
    start = time.monotonic()
    job = client.submit(demo_spec(args))
    print(f"job {job['id']}: DE (NP {args.np}, {args.iters} generations) on {args.road}, "
          f"{job['total']} simulations", file=sys.stderr)
    job = follow(client, job["id"])
    if job["state"] != "succeeded":
        print(f"finaldrive: error: job {job['id']} {job['state']}: {job.get('error') or ''}", file=sys.stderr)
        return EXIT_FAILED
    best = job["roads"][0]["best"]
    near = client.best(job["id"])["sharpness"][0]   # how well the DE's few simulations decide each variable
    result = {"job": job["id"], "road": job["roads"][0]["spec"], "a2_deg": best["a2_deg"], "l2_m": best["l2_m"],
              "rws_m": best["rws_m"], "fitness_m": best["fitness_m"], "distance_m": best["distance_m"],
              "near_optimal": {k: near[k] for k in ("tolerance_pct", "tolerance_m", "count", "evaluated", "ranges",
                                                   "sentences")},
              "simulations": job["done"] + job["failed"], "wall_s": round(time.monotonic() - start, 1)}
    if args.json:
        print_json(result)
    else:
        print(f"best geometry on {result['road']} (job {result['job']}, {result['simulations']} simulations, "
              f"{result['wall_s']} s):")
        print(f"  a2 = {best['a2_deg']:.1f} deg   L2 = {best['l2_m']:.4f} m   R_WS = {best['rws_m']:.4f} m")
        print(f"  fitness = {best['fitness_m']:.3f} m   distance = {best['distance_m']:.3f} m")
        print("\n".join(near_lines(near)))
        print(dashboard_hint(args.db, result["job"]))
    return EXIT_OK


def dashboard_hint(db: str, job_id: int) -> str:
    """How to look at the job in the dashboard after the demo's service has stopped."""
    serve = "finaldrive serve" + ("" if db == DEFAULT_DB else f" --db {db}")
    return (f"look at it in the dashboard: run `{serve}`, then open http://127.0.0.1:8000/jobs/{job_id}\n"
            "  (the sweep map, the DE history, every evaluation, the best design riding the road in rerun's viewer)")


def register(sub: Any) -> None:
    p = sub.add_parser("demo", help=COMMANDS["demo"].help,
                       **parser_options())
    p.add_argument("--port", type=int, help="port of the service (default: a free one)")
    p.add_argument("--db", default=DEFAULT_DB, help="database URL")
    p.add_argument("--executor", choices=("serial", "process", "ray"), default="ray", help="where simulations run")
    p.add_argument("--np", type=int, default=12, help="DE population size")
    p.add_argument("--iters", type=int, default=6, help="DE generations after the initial population")
    p.add_argument("--road", default="sine:0.04:3", help="the road (its spec)")
    p.add_argument("--json", action="store_true", help="print the best design as JSON")
    p.add_argument("--timeout", type=float, default=START_TIMEOUT_S,
                   help="how long to wait for the service to start [s]; it says what it waits for meanwhile")
    p.set_defaults(run=run_demo)
