"""What the client commands share: the HTTP client, exit codes, error lines, following a job.

The client commands speak only HTTP to the service (``--server``, default ``$FINALDRIVE_SERVER``
or http://127.0.0.1:8000; bearer token from ``$FINALDRIVE_API_TOKEN``).
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from collections.abc import Callable
from typing import Any, TextIO

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
#: Where the client finds the bearer token (the server reads the same variable).
TOKEN_VARIABLE = "FINALDRIVE_API_TOKEN"
TERMINAL = ("succeeded", "failed", "cancelled")

Runner = Callable[..., int]


def connect(args: argparse.Namespace) -> Any:
    from finaldrive.service.client import ServiceClient

    return ServiceClient(getattr(args, "server", None))


def client_command(fn: Runner) -> Runner:
    """Map the client's errors to one line on stderr and an exit code."""

    @functools.wraps(fn)
    def run(*args: Any) -> int:
        from finaldrive.service.client import ApiError, Unreachable

        try:
            return fn(*args)
        except ApiError as exc:
            hint = ""
            if exc.status == 401:
                given = "is set, but to another value" if os.environ.get(TOKEN_VARIABLE) else "is not set"
                hint = f"; the client sends ${TOKEN_VARIABLE}, which here {given}"
            print(f"finaldrive: error: {exc}{hint}", file=sys.stderr)
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
    seconds = round(seconds)
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


def finished(job: dict[str, Any]) -> int:
    if job["state"] != "succeeded":
        print(f"finaldrive: job {job['id']} {job['state']}" + (f": {job['error']}" if job.get("error") else ""),
              file=sys.stderr)
        return EXIT_JOB_NOT_SUCCEEDED
    return EXIT_OK




def add_server_args(p: argparse.ArgumentParser, *, server_default: bool = True) -> None:
    help_ = "service URL (default: $FINALDRIVE_SERVER, else http://127.0.0.1:8000)"
    if not server_default:
        help_ = "record or plot through this service instead of locally"
    p.add_argument("--server", metavar="URL", help=help_)
    p.add_argument("--json", action="store_true", help="print JSON (for scripts)")


def exit_codes_epilog() -> str:
    return "exit codes: " + "; ".join(f"{k} {v}" for k, v in EXIT_CODES.items())
