"""Throughput and latency of GET /v1/jobs/{id} while a 23-road sweep runs: wrk on a real ``finaldrive serve``.

Starts ``finaldrive serve`` (a temporary SQLite file, its scheduler with the chosen executor: local
Ray by default, whose workers run at a lower priority than the API), submits the Table 9 sweep on
all 23 roads, waits until evaluations are being stored, then runs ``wrk -t2 -c50 -d15s --latency``
on the job's status ``--runs`` times and prints each run and the median. Target (issue 26):
>= 1,000 requests/s and p99 <= 50 ms. wrk is written in C, so the client costs the API little; it
is Debian's ``wrk`` package (the benchmark says so and stops when it is missing).

    python bench/bench_api.py [--runs 3] [--seconds 15] [--connections 50] [--executor ray] [--idle]

``--idle``: the same with no job running (the status of a finished, cancelled sweep).

Results, 2026-12-04 (lscpu: AMD EPYC family 25 model 17, 2 CPUs under KVM; Python 3.11.7, uvicorn
0.55; load average 2-4 with the sweep; median of 3 runs; docs/performance-log.md has each run):
h11 + asyncio 3,784 req/s, p99 30.8 ms; httptools + uvloop 5,291 req/s, p99 34.8 ms (again:
5,045 req/s, p99 27.0 ms); idle 6,544 req/s, p99 17.7 ms. Before the snapshots: 1,208 req/s,
p99 250 ms.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from finaldrive.service.machine import describe, free_port

#: The Table 9 sweep on all 23 roads at full duration: it keeps both cores busy for many minutes,
#: longer than the measurement.
SWEEP = {"kind": "sweep", "roads": ["paper"], "grid": "table9"}
TARGET_RPS = 1000.0
TARGET_P99_MS = 50.0
_UNITS = {"us": 1e-3, "ms": 1.0, "s": 1e3, "m": 6e4}


@dataclass(frozen=True)
class WrkRun:
    rps: float
    p50_ms: float
    p99_ms: float
    max_ms: float
    requests: int
    non_2xx: int
    errors: int
    load: tuple[float, float, float]


def _ms(text: str) -> float:
    value, unit = re.fullmatch(r"([0-9.]+)([a-z]+)", text).groups()  # type: ignore[union-attr]
    return float(value) * _UNITS[unit]


def parse_wrk(out: str, load: tuple[float, float, float]) -> WrkRun:
    """The numbers of ``wrk --latency``'s report."""
    pct = dict(re.findall(r"^\s+(50|99)%\s+(\S+)$", out, re.M))
    errors = re.search(r"Socket errors: connect (\d+), read (\d+), write (\d+), timeout (\d+)", out)
    non_2xx = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    return WrkRun(
        rps=float(re.search(r"Requests/sec:\s+([0-9.]+)", out).group(1)),  # type: ignore[union-attr]
        p50_ms=_ms(pct["50"]), p99_ms=_ms(pct["99"]),
        max_ms=_ms(re.search(r"Latency\s+\S+\s+\S+\s+(\S+)", out).group(1)),  # type: ignore[union-attr]
        requests=int(re.search(r"(\d+) requests in", out).group(1)),  # type: ignore[union-attr]
        non_2xx=int(non_2xx.group(1)) if non_2xx else 0,
        errors=sum(map(int, errors.groups())) if errors else 0, load=load,
    )


def wrk(url: str, seconds: float, connections: int, threads: int) -> WrkRun:
    load = os.getloadavg()
    out = subprocess.run(["wrk", f"-t{threads}", f"-c{connections}", f"-d{seconds:g}s", "--latency", url],
                         capture_output=True, text=True, check=True).stdout
    return parse_wrk(out, load)


def stack() -> str:
    """The HTTP parser and event loop uvicorn picks in this environment (its default: the fastest installed)."""
    http = "httptools" if importlib.util.find_spec("httptools") else "h11"
    loop = "uvloop" if importlib.util.find_spec("uvloop") else "asyncio"
    return f"one uvicorn process, {http}, {loop}"


def start_server(tmp: Path, port: int, executor: str) -> subprocess.Popen[bytes]:
    """``finaldrive serve`` on 127.0.0.1 with a SQLite file in ``tmp`` (its log: ``tmp/server.log``)."""
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    cmd = [sys.executable, "-m", "finaldrive.service.cli", "serve", "--host", "127.0.0.1", "--port", str(port),
           "--db", f"sqlite:///{tmp / 'bench.db'}", "--executor", executor]
    with (tmp / "server.log").open("wb") as out:
        return subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)


def wait_for(client: httpx.Client, path: str, ready: Any, timeout: float = 300) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            r = client.get(path)
            if r.status_code == 200 and ready(r.json()):
                return r.json()  # type: ignore[no-any-return]
        except httpx.TransportError:
            pass
        time.sleep(0.5)
    raise RuntimeError(f"timed out waiting for {path}")


def stop(server: subprocess.Popen[bytes]) -> None:
    """SIGINT (serve stops its scheduler, which stops Ray), then SIGKILL of the group after 30 s."""
    server.send_signal(signal.SIGINT)
    try:
        server.wait(30)
    except subprocess.TimeoutExpired:
        os.killpg(server.pid, signal.SIGKILL)
        server.wait()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--connections", type=int, default=50)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--executor", choices=("serial", "process", "ray"), default="ray")
    parser.add_argument("--idle", action="store_true", help="measure with no job running")
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        print("wrk is not installed (Debian: apt-get install wrk): benchmark skipped")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        base = f"http://127.0.0.1:{port}"
        server = start_server(Path(tmp), port, args.executor)
        try:
            with httpx.Client(base_url=base, timeout=30) as client:
                wait_for(client, "/v1/health", lambda _: True)
                job = client.post("/v1/jobs", json=SWEEP).json()
                path = f"/v1/jobs/{job['id']}"
                if args.idle:
                    client.post(f"{path}/cancel")
                    wait_for(client, path, lambda j: j["state"] == "cancelled")
                else:
                    wait_for(client, path, lambda j: j["done"] + j["failed"] > 0)  # the engine is warm
                wrk(base + path, 2, args.connections, args.threads)  # warm-up: connections, caches
                runs = []
                for i in range(args.runs):
                    run = wrk(base + path, args.seconds, args.connections, args.threads)
                    state = client.get(path).json()
                    runs.append(run)
                    print(f"run {i + 1}: {run.rps:,.0f} req/s, p50 {run.p50_ms:.2f} ms, p99 {run.p99_ms:.2f} ms, "
                          f"max {run.max_ms:.1f} ms, {run.non_2xx} non-2xx, {run.errors} socket errors; "
                          f"load average before {run.load[0]:.2f}; job {state['state']} "
                          f"{state['done'] + state['failed']}/{state['total']}", flush=True)
                if not args.idle:
                    client.post(f"{path}/cancel")
        finally:
            stop(server)
    rps = statistics.median(r.rps for r in runs)
    p99 = statistics.median(r.p99_ms for r in runs)
    met = rps >= TARGET_RPS and p99 <= TARGET_P99_MS
    print(f"machine: {describe()}")
    print(f"server: {stack()}")
    print(f"median of {len(runs)} x wrk -t{args.threads} -c{args.connections} -d{args.seconds:g}s on GET {path}"
          f"{' (idle)' if args.idle else ' during the 23-road sweep'}: {rps:,.0f} req/s, "
          f"p50 {statistics.median(r.p50_ms for r in runs):.2f} ms, p99 {p99:.2f} ms "
          f"(target >= {TARGET_RPS:,.0f} req/s and p99 <= {TARGET_P99_MS:g} ms: {'met' if met else 'NOT met'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
