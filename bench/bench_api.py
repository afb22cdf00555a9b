"""Latency of GET /v1/jobs/{id} while a sweep runs: 50 concurrent clients on loopback.

Starts a real server (uvicorn, a temporary SQLite file), submits a Table 9 sweep, waits
until evaluations are being stored, then has ``--clients`` tasks issue GETs for
``--seconds`` seconds through one httpx.AsyncClient (one connection per client).
Prints the machine, the request rate and the latency percentiles; target p99 < 50 ms.

    python bench/bench_api.py [--clients 50] [--seconds 10] [--interval 0] [--executor process]

``--interval 0`` is a closed loop (every client re-sends at once: a throughput test);
``--interval 0.5`` is 50 dashboards polling twice a second.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from finaldrive.service.machine import describe, free_port

#: The Table 9 sweep on all 23 roads at full duration: it keeps both cores busy for minutes,
#: longer than any measurement window.
SWEEP = {"kind": "sweep", "roads": ["paper"], "grid": "table9"}


def start_server(db: Path, port: int, executor: str, log: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, "FINALDRIVE_DB_URL": f"sqlite:///{db}", "FINALDRIVE_EXECUTOR": executor,
           "FINALDRIVE_NUM_WORKERS": "1"}
    cmd = [sys.executable, "-m", "uvicorn", "--factory", "finaldrive.service.main:create_app",
           "--host", "127.0.0.1", "--port", str(port), "--log-level", "warning"]
    with log.open("wb") as out:
        return subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT)


async def wait_for(client: httpx.AsyncClient, path: str, ready: callable, timeout: float = 120) -> dict:  # type: ignore[valid-type]
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            r = await client.get(path)
            if r.status_code == 200 and ready(r.json()):
                return r.json()  # type: ignore[no-any-return]
        except httpx.TransportError:
            pass
        await asyncio.sleep(0.2)
    raise RuntimeError(f"timed out waiting for {path}")


async def poll(
    client: httpx.AsyncClient, path: str, until: float, interval: float, out: list[float], errors: list[int]
) -> None:
    """One client: GET, then wait ``interval`` (0: closed loop), until the deadline.

    Clients start at random offsets within the interval (dashboards are not synchronised)."""
    await asyncio.sleep(random.uniform(0, interval))
    while time.monotonic() < until:
        t0 = time.perf_counter()
        r = await client.get(path)
        out.append(time.perf_counter() - t0)
        if r.status_code != 200:
            errors.append(r.status_code)
        if interval:
            await asyncio.sleep(interval)


async def bench(url: str, clients: int, seconds: float, interval: float) -> None:
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(base_url=url, limits=limits, timeout=30) as client:
        await wait_for(client, "/v1/health", lambda _: True)
        job = (await client.post("/v1/jobs", json=SWEEP)).json()
        path = f"/v1/jobs/{job['id']}"
        await wait_for(client, path, lambda j: j["done"] + j["failed"] > 0)  # the engine is warm
        warm_up = time.monotonic() + 2  # open the connections, threads and DB connections first
        await asyncio.gather(*(poll(client, path, warm_up, interval, [], []) for _ in range(clients)))
        latencies: list[float] = []
        errors: list[int] = []
        until = time.monotonic() + seconds
        await asyncio.gather(*(poll(client, path, until, interval, latencies, errors) for _ in range(clients)))
        final = (await client.get(path)).json()
        await client.post(f"{path}/cancel")
    ms = sorted(x * 1000 for x in latencies)
    q = statistics.quantiles(ms, n=100)
    print(f"machine: {describe()}")
    pace = f"each waiting {interval:g} s between requests" if interval else "closed loop"
    print(f"{len(ms)} GET {path} in {seconds:g} s from {clients} clients ({pace}) = {len(ms) / seconds:.0f} req/s, "
          f"{len(errors)} errors; sweep progress during the run: {final['done'] + final['failed']}/{final['total']}")
    print(f"latency ms: p50 {q[49]:.1f}  p90 {q[89]:.1f}  p99 {q[98]:.1f}  max {ms[-1]:.1f}  "
          f"(target p99 < 50: {'met' if q[98] < 50 else 'NOT met'})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--interval", type=float, default=0.0, help="seconds each client waits between GETs")
    parser.add_argument("--executor", choices=("serial", "process", "ray"), default="process")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        server = start_server(Path(tmp) / "bench.db", port, args.executor, Path(tmp) / "server.log")
        try:
            asyncio.run(bench(f"http://127.0.0.1:{port}", args.clients, args.seconds, args.interval))
        finally:
            server.send_signal(signal.SIGINT)
            try:
                server.wait(15)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()


if __name__ == "__main__":
    main()
