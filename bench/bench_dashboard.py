"""What a dashboard costs the service: 300 open event streams, and map requests on a large job.

1. Streams: starts ``finaldrive serve`` (process executor, one worker, a temporary SQLite file),
   submits a Table 9 sweep on the paper's roads (it runs for the whole measurement, so its
   progress changes every tick), then measures ``GET /v1/health`` (``--requests`` sequential
   requests: p50, p99) without streams and with ``--streams`` open on ``/v1/jobs/{id}/events``
   (held, and read, by a child process, so the measuring client shares no CPU time with them).
   Each phase ``--runs`` times; the medians are printed. Target: p99 < 50 ms with 300 streams.
2. Memory: a store with one sweep job of ``--evaluations`` evaluations on one road, inserted
   directly (a 200 x N grid over a2 and L2; the values follow a smooth stand-in fitness, plausible
   in range but not simulated), served by ``finaldrive serve --no-scheduler``; the server's RSS
   before, and its peak (sampled every 10 ms) while ten sweep-map PNGs and ten ``/points``
   answers are requested at once, ``--runs`` times.

    python bench/bench_dashboard.py [--streams 300] [--requests 500] [--runs 3] [--evaluations 100000]
"""

from __future__ import annotations

import argparse
import asyncio
import math
import multiprocessing
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import psutil

from finaldrive.service.machine import describe, free_port

SWEEP = {"kind": "sweep", "roads": ["paper"], "grid": "table9"}
A2_STEPS = 200


def start_server(db: Path, port: int, log: Path, *extra: str) -> subprocess.Popen[bytes]:
    env = {**os.environ, "FINALDRIVE_NUM_WORKERS": "1", "FINALDRIVE_MAX_STREAMS_PER_CLIENT": "10000",
           "RAY_USAGE_STATS_ENABLED": "0"}
    env.pop("FINALDRIVE_API_TOKEN", None)
    cmd = [str(Path(sys.executable).with_name("finaldrive")), "serve", "--port", str(port), "--db",
           f"sqlite:///{db}", *extra]
    with log.open("wb") as out:
        server = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/v1/health", timeout=5).status_code in (200, 503):
                return server
        except httpx.TransportError:
            pass
        time.sleep(0.3)
    raise SystemExit(f"the service did not start: {log.read_text()[-2000:]}")


def stop(server: subprocess.Popen[bytes]) -> None:
    server.terminate()
    try:
        server.wait(30)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait()


def latencies_ms(base: str, n: int) -> list[float]:
    """``n`` sequential GET /v1/health on one keep-alive connection [ms]."""
    out = []
    with httpx.Client(base_url=base, timeout=60) as client:
        client.get("/v1/health")
        for _ in range(n):
            t0 = time.perf_counter()
            client.get("/v1/health").raise_for_status()
            out.append((time.perf_counter() - t0) * 1000)
    return out


def percentiles(ms: list[float]) -> tuple[float, float]:
    q = statistics.quantiles(ms, n=100)
    return q[49], q[98]


# --- streams -------------------------------------------------------------------------------------

def hold_streams(url: str, n: int, pipe: Connection) -> None:
    """Child process: open ``n`` streams, say "open" once each had its first event, read until told to stop;
    then send the number of events received."""

    async def one(client: httpx.AsyncClient, opened: list[int], events: list[int]) -> None:
        async with client.stream("GET", url) as r:
            r.raise_for_status()
            first = True
            async for line in r.aiter_lines():
                if line.startswith("event:"):
                    events[0] += 1
                    if first:
                        opened[0] += 1
                        first = False

    async def main() -> None:
        limits = httpx.Limits(max_connections=n + 10, max_keepalive_connections=n + 10)
        opened, events = [0], [0]
        async with httpx.AsyncClient(limits=limits, timeout=httpx.Timeout(60, read=None)) as client:
            tasks = [asyncio.create_task(one(client, opened, events)) for _ in range(n)]
            while opened[0] < n:
                await asyncio.sleep(0.05)
                if any(t.done() for t in tasks):
                    next(t for t in tasks if t.done()).result()
            pipe.send("open")
            await asyncio.get_running_loop().run_in_executor(None, pipe.recv)
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        pipe.send(events[0])

    asyncio.run(main())


def bench_streams(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = start_server(tmp / "streams.db", port, tmp / "streams.log", "--executor", "process")
    try:
        job = httpx.post(f"{base}/v1/jobs", json=SWEEP, timeout=30).json()
        while httpx.get(f"{base}/v1/jobs/{job['id']}", timeout=30).json()["done"] == 0:
            time.sleep(0.5)
        runs = []
        for _ in range(args.runs):
            alone = percentiles(latencies_ms(base, args.requests))
            ours, theirs = multiprocessing.Pipe()
            holder = multiprocessing.Process(target=hold_streams, args=(f"{base}/v1/jobs/{job['id']}/events",
                                                                        args.streams, theirs))
            t0 = time.perf_counter()
            holder.start()
            assert ours.poll(180), "the streams did not open"
            ours.recv()
            opened_s = time.perf_counter() - t0
            loaded = percentiles(latencies_ms(base, args.requests))
            ours.send("stop")
            events = ours.recv()
            holder.join(30)
            runs.append({"alone": alone, "streams": loaded, "open_s": opened_s, "events": events})
            time.sleep(1)
        progress = httpx.get(f"{base}/v1/jobs/{job['id']}", timeout=30).json()
    finally:
        stop(server)
    return {"runs": runs, "progress": f"{progress['done'] + progress['failed']}/{progress['total']}"}


# --- memory --------------------------------------------------------------------------------------

def make_store(db: Path, n: int) -> int:
    """A sweep job with ``n`` evaluations on one road, inserted directly; returns its id."""
    from sqlalchemy import insert

    from finaldrive.service.config import Settings
    from finaldrive.service.db.levels import add_entries
    from finaldrive.service.db.models import Evaluation
    from finaldrive.service.db.repository import create_job, utcnow
    from finaldrive.service.services import open_database

    l2_steps = math.ceil(n / A2_STEPS)
    a2 = np.repeat(np.linspace(0, 358.2, A2_STEPS), l2_steps)[:n]
    l2 = np.tile(np.linspace(0, 0.2, l2_steps), A2_STEPS)[:n]
    fitness = 20 + 0.6 * np.cos(np.radians(a2) - 3.4) * l2 / 0.2 - 4 * (l2 - 0.08) ** 2
    failed = (np.arange(n) % 97) == 0  # about 1 %, as rough roads give
    db_ = open_database(Settings(db_url=f"sqlite:///{db}"))
    try:
        with db_.write() as session:
            grid = f"a2_deg=0:358.2:{358.2 / (A2_STEPS - 1):.4f},l2_m=0:0.2:{0.2 / (l2_steps - 1)}"
            job = create_job(session, kind="sweep", spec={"kind": "sweep", "roads": ["sine:0.04:3"], "grid": grid},
                             request_hash="bench", idempotency_key=None, total=n,
                             roads=[("sine:0.04:3", "sine:0.04:3")])
            job.state, job.n_done, job.n_failed = "succeeded", int(n - failed.sum()), int(failed.sum())
            job_id = job.id
        now = utcnow()
        rows = [{"job_id": job_id, "road_index": 0, "step": 0, "candidate": i, "a2_deg": float(a2[i]),
                 "l2_m": float(l2[i]), "rws_m": 0.093, "distance_m": None if failed[i] else float(fitness[i]) + 0.4,
                 "squat_ratio": None if failed[i] else 0.8 + 0.3 * float(l2[i]), "slack_m": 0.001,
                 "fitness_m": None if failed[i] else float(fitness[i]), "chain_length_m": 1.2,
                 "status": "failed" if failed[i] else "ok", "reason": "diverged" if failed[i] else "",
                 "wall_s": 0.005, "cached": False, "cache_key": f"{i:064x}", "cache_hash": i, "transient": False,
                 "created_at": now} for i in range(n)]
        with db_.write() as session:
            session.execute(insert(Evaluation), rows)
            add_entries(session, job_id)  # as the writer does
    finally:
        db_.dispose()
    return job_id


def peak_rss_during(pid: int, work: Any) -> tuple[float, float]:
    """(RSS before, peak RSS while ``work()`` runs) of process ``pid`` [MB]."""
    proc = psutil.Process(pid)
    before = proc.memory_info().rss
    peak, done = before, threading.Event()

    def sample() -> None:
        nonlocal peak
        while not done.is_set():
            peak = max(peak, proc.memory_info().rss)
            time.sleep(0.01)

    sampler = threading.Thread(target=sample)
    sampler.start()
    try:
        work()
    finally:
        done.set()
        sampler.join()
    return before / 2**20, peak / 2**20


def bench_memory(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    db = tmp / "memory.db"
    job_id = make_store(db, args.evaluations)
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    server = start_server(db, port, tmp / "memory.log", "--no-scheduler")
    urls = [f"/v1/jobs/{job_id}/plots/sweep-map.png"] * 10 + [f"/v1/jobs/{job_id}/points"] * 10

    def burst() -> list[int]:
        with httpx.Client(base_url=base, timeout=600, limits=httpx.Limits(max_connections=len(urls))) as client, \
                ThreadPoolExecutor(len(urls)) as pool:
            return list(pool.map(lambda u: client.get(u).status_code, urls))

    runs = []
    try:
        for _ in range(args.runs):
            t0 = time.perf_counter()
            statuses: list[int] = []
            before, peak = peak_rss_during(server.pid, lambda out=statuses: out.extend(burst()))
            runs.append({"before_mb": before, "peak_mb": peak, "wall_s": time.perf_counter() - t0,
                         "statuses": dict(sorted(Counter(statuses).items()))})
        points = httpx.get(f"{base}/v1/jobs/{job_id}/points", timeout=600)
    finally:
        stop(server)
    return {"runs": runs, "points_bytes": len(points.content)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--streams", type=int, default=300)
    parser.add_argument("--requests", type=int, default=500, help="sequential /v1/health requests a phase")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--evaluations", type=int, default=100_000)
    parser.add_argument("--skip", choices=("streams", "memory"), help="leave one part out")
    args = parser.parse_args()
    print(f"machine: {describe()}")
    with tempfile.TemporaryDirectory(prefix="finaldrive-dashboard-") as name:
        tmp = Path(name)
        if args.skip != "streams":
            s = bench_streams(args, tmp)
            print(f"\n/v1/health, {args.requests} sequential requests a phase, a Table 9 sweep running "
                  f"(process executor, 1 worker; progress at the end {s['progress']}):")
            print(f"{'run':>4} {'alone p50':>10} {'alone p99':>10} {'streams p50':>12} {'streams p99':>12} "
                  f"{'open s':>7} {'events':>7}")
            for i, r in enumerate(s["runs"], 1):
                print(f"{i:>4} {r['alone'][0]:>10.1f} {r['alone'][1]:>10.1f} {r['streams'][0]:>12.1f} "
                      f"{r['streams'][1]:>12.1f} {r['open_s']:>7.1f} {r['events']:>7}")
            med = {f"{k}{j}": statistics.median(r[k][j] for r in s["runs"])
                   for k in ("alone", "streams") for j in (0, 1)}
            print(f"median: alone p50 {med['alone0']:.1f} ms p99 {med['alone1']:.1f} ms; with {args.streams} streams "
                  f"p50 {med['streams0']:.1f} ms p99 {med['streams1']:.1f} ms; p99 ratio "
                  f"{med['streams1'] / med['alone1']:.2f} (target p99 < 50 ms: "
                  f"{'met' if med['streams1'] < 50 else 'NOT met'})")
        if args.skip != "memory":
            m = bench_memory(args, tmp)
            print(f"\nserver RSS, ten sweep-map PNGs and ten /points at once on {args.evaluations:,} evaluations "
                  f"(/points answer {m['points_bytes'] / 2**20:.1f} MB):")
            print(f"{'run':>4} {'before MB':>10} {'peak MB':>9} {'wall s':>7}  statuses (count)")
            for i, r in enumerate(m["runs"], 1):
                print(f"{i:>4} {r['before_mb']:>10.0f} {r['peak_mb']:>9.0f} {r['wall_s']:>7.1f}  {r['statuses']}")
    print(f"\nload average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
