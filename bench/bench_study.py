"""The paper's whole study through ``finaldrive serve``, and the API's latency while it runs.

Starts ``finaldrive serve`` (its API and one scheduler with the chosen executor) on a SQLite
file, submits the paper-study job (Table 9 sweep + Table 10 DE on the 23 roads, 104,190
simulations) and, while it runs, measures ``GET /v1/jobs/{id}`` with wrk (a load generator
written in C, so the client does not take the API's core) in windows of ``--window`` seconds.
Simulations run at the service's lower OS priority (``FINALDRIVE_NICENESS``, default 10).

Prints JSON: the job's wall time, the engine's own time (sum of the stored per-simulation wall
times / workers), their ratio, and per wrk window the request rate and latency percentiles.

    python bench/bench_study.py [--executor ray] [--workers 2] [--connections 2] [--window 20]
        [--keep DB]   # keep the database (e.g. for ``finaldrive report paper-study``)
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from finaldrive.service.machine import describe

_UNIT_S = {"us": 1e-6, "ms": 1e-3, "s": 1.0, "m": 60.0}


def _seconds(text: str) -> float:
    number, unit = re.fullmatch(r"([\d.]+)(us|ms|s|m)", text).groups()  # type: ignore[union-attr]
    return float(number) * _UNIT_S[unit]


def wrk(url: str, seconds: int, connections: int) -> dict[str, float]:
    """One wrk window (one thread): requests/s and the latency distribution [s]."""
    out = subprocess.run(["wrk", "-t1", f"-c{connections}", f"-d{seconds}s", "--latency", url],
                         capture_output=True, text=True, check=True).stdout
    pct = dict(re.findall(r"^\s+(50|75|90|99)%\s+(\S+)$", out, re.M))
    rate = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))  # type: ignore[union-attr]
    errors = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    return {"requests_per_s": rate, "p50_s": _seconds(pct["50"]), "p90_s": _seconds(pct["90"]),
            "p99_s": _seconds(pct["99"]), "non_2xx": int(errors.group(1)) if errors else 0}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--executor", default="ray", choices=("process", "ray"), help="the scheduler's executor")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes / CPUs")
    parser.add_argument("--connections", type=int, default=2, help="wrk's open connections (closed loop)")
    parser.add_argument("--window", type=int, default=20, help="seconds a wrk window lasts")
    parser.add_argument("--port", type=int, default=8765)
    parser.add_argument("--roads", default="paper", help="roads of the study (default: the paper's 23)")
    parser.add_argument("--keep", metavar="DB", help="copy the study's SQLite database here at the end")
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        parser.error("wrk not found (Debian: apt-get install wrk)")

    tmp = Path(tempfile.mkdtemp(prefix="finaldrive-study-"))
    db = tmp / "study.db"
    script = Path(sys.executable).with_name("finaldrive")
    server = subprocess.Popen(
        [str(script), "serve", "--db", f"sqlite:///{db}", "--port", str(args.port), "--executor", args.executor],
        env={**os.environ, "FINALDRIVE_NUM_WORKERS": str(args.workers)},
        stdout=(tmp / "serve.log").open("wb"), stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{args.port}"
    windows: list[dict[str, float]] = []
    try:
        with httpx.Client(base_url=base, timeout=30) as client:
            deadline = time.monotonic() + 120
            while True:
                try:
                    if client.get("/v1/health").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline:
                    raise SystemExit(f"the service did not start: {(tmp / 'serve.log').read_text()[-2000:]}")
                time.sleep(0.5)
            study = {"kind": "paper-study", "roads": args.roads.split(",")}
            job_id = client.post("/v1/jobs", json=study).json()["id"]
            url = f"{base}/v1/jobs/{job_id}"
            while (job := client.get(url).json())["state"] in ("queued", "running"):
                if job["state"] == "running" and job["done"] > 0:
                    windows.append({"at_progress": round(job["progress"], 3),
                                    **wrk(url, args.window, args.connections)})
                    time.sleep(args.window)  # the study alone between windows
                else:
                    time.sleep(1)
            job = client.get(url).json()
    finally:
        server.terminate()
        server.wait(60)
    with sqlite3.connect(db) as conn:
        engine_s, simulated = conn.execute(
            "SELECT SUM(wall_s), COUNT(*) FROM evaluations WHERE job_id = ? AND NOT cached", (job_id,)).fetchone()
    if args.keep:  # SQLite's backup API: the copy includes what is still in the write-ahead log
        with sqlite3.connect(db) as source, sqlite3.connect(args.keep) as target:
            source.backup(target)
    shutil.rmtree(tmp, ignore_errors=True)
    engine_share = engine_s / args.workers
    print(json.dumps({
        "state": job["state"], "evaluations": job["done"] + job["failed"], "failed": job["failed"],
        "simulated": simulated, "wall_s": job["elapsed_s"], "engine_s_per_worker": round(engine_share, 1),
        "wall_over_engine": round(job["elapsed_s"] / engine_share, 3), "executor": args.executor,
        "workers": args.workers, "wrk_connections": args.connections, "windows": windows,
        "machine": describe(),
    }, indent=1))
    return 0 if job["state"] == "succeeded" else 1


if __name__ == "__main__":
    sys.exit(main())
