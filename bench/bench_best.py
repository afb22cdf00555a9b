"""Memory and time of GET /v1/jobs/{id}/best on a job of a million evaluations (issue 26).

Builds the job in a temporary SQLite file by bulk SQL (a recursive CTE: random designs, a2 over
a full turn, fitness spread over 10 m, so the near-optimal set at the default 0.1 % is about 0.2 %
of the rows), then asks the API (in this process, FastAPI's TestClient, no scheduler) for /best:
once, and ``--concurrent`` at once from one client address. Prints the wall time of each answer
and the growth of this process's resident memory (sampled every 2 ms, peak over the start).
Target: growth < 50 MB and an answer < 1 s; concurrent requests beyond the client's limit get 429.

    python bench/bench_best.py [--evaluations 1000000] [--roads 1] [--concurrent 10] [--tolerance-pct 0.1]
"""

from __future__ import annotations

import argparse
import sqlite3
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import psutil
from fastapi.testclient import TestClient

from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.levels import add_entries
from finaldrive.service.db.migrate import upgrade
from finaldrive.service.db.summaries import recount_explored
from finaldrive.service.main import create_app

TARGET_MB = 50.0
TARGET_S = 1.0


def build_job(path: Path, evaluations: int, roads: int) -> int:
    """A succeeded sweep job of ``evaluations`` random designs spread over ``roads`` roads (flat); its id."""
    upgrade(f"sqlite:///{path}")
    with sqlite3.connect(path) as db:
        spec = '{"kind": "sweep", "roads": ["flat"], "grid": "table9"}'
        job = db.execute(
            "INSERT INTO jobs (kind, state, spec, request_hash, total, n_done, n_failed, n_cached, "
            "completed_at_resume, created_at) "
            "VALUES ('sweep', 'succeeded', ?, 'bench', ?, ?, 0, 0, 0, '2026-01-01 00:00:00')",
            (spec, evaluations, evaluations)).lastrowid
        assert job is not None
        db.executemany("INSERT INTO job_roads (job_id, road_index, name, spec) VALUES (?, ?, ?, 'flat')",
                       [(job, r, f"road{r}") for r in range(roads)])
        db.execute(
            f"""WITH RECURSIVE k(i) AS (SELECT 0 UNION ALL SELECT i + 1 FROM k WHERE i < {evaluations - 1})
            INSERT INTO evaluations (job_id, road_index, step, candidate, a2_deg, l2_m, rws_m, distance_m, squat_ratio,
              slack_m, fitness_m, chain_length_m, status, reason, wall_s, cached, cache_key, cache_hash, transient,
              created_at)
            SELECT {job}, i % {roads}, 0, i / {roads}, (abs(random()) % 3600000) / 10000.0 - 180.0,
              (abs(random()) % 200000) / 1e6, 0.08 + (abs(random()) % 20000) / 1e6, 20.0, 1.0, 0.0,
              20.0 - (abs(random()) % 1000000) / 1e5, 1.2, 'ok', '', 0.1, 0, 'bench', 0, 0, '2026-01-01 00:00:00'
            FROM k""")
        db.execute("UPDATE job_roads SET best_evaluation_id = (SELECT id FROM evaluations e WHERE e.job_id = "
                   "job_roads.job_id AND e.road_index = job_roads.road_index ORDER BY fitness_m DESC LIMIT 1) "
                   "WHERE job_id = ?", (job,))
    store = Database(f"sqlite:///{path}")
    with store.write() as session:  # as the writer keeps them
        recount_explored(session, int(job))
        add_entries(session, int(job))
    store.dispose()
    return int(job)


@contextmanager
def peak_growth() -> Iterator[Callable[[], float]]:
    """Yields a function giving the peak growth [MB] of this process's resident memory so far."""
    process = psutil.Process()
    start = process.memory_info().rss
    peak = [start]
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(0.002):
            peak[0] = max(peak[0], process.memory_info().rss)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    try:
        yield lambda: (max(peak[0], process.memory_info().rss) - start) / 2**20
    finally:
        stop.set()
        thread.join()


def app_client(path: Path) -> TestClient:
    settings = Settings(db_url=f"sqlite:///{path}", executor="serial", allowed_hosts=["testserver"],
                        status_cache_seconds=0)
    return TestClient(create_app(settings))


def timed_get(client: TestClient, url: str, params: dict[str, str]) -> tuple[int, float]:
    started = time.perf_counter()
    status = client.get(url, params=params).status_code
    return status, time.perf_counter() - started


def concurrent(client: TestClient, url: str, params: dict[str, str], n: int) -> list[tuple[int, float]]:
    out: list[tuple[int, float]] = []
    lock = threading.Lock()

    def one() -> None:
        result = timed_get(client, url, params)
        with lock:
            out.append(result)

    threads = [threading.Thread(target=one) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--evaluations", type=int, default=1_000_000)
    parser.add_argument("--roads", type=int, default=1)
    parser.add_argument("--concurrent", type=int, default=10)
    parser.add_argument("--tolerance-pct", type=float, default=0.1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-best-") as tmp:
        path = Path(tmp) / "best.db"
        started = time.perf_counter()
        job = build_job(path, args.evaluations, args.roads)
        print(f"built job {job}: {args.evaluations:,} evaluations on {args.roads} road(s) in "
              f"{time.perf_counter() - started:.1f} s ({path.stat().st_size / 2**20:.0f} MB)")
        url, params = f"/v1/jobs/{job}/best", {"tolerance_pct": repr(args.tolerance_pct)}
        with app_client(path) as client:
            client.get("/v1/health")
            with peak_growth() as growth:
                status, seconds = timed_get(client, url, params)
                print(f"one request: {status} in {seconds:.3f} s, RSS +{growth():.1f} MB "
                      f"(targets: < {TARGET_S:g} s, < {TARGET_MB:g} MB)")
            with peak_growth() as growth:
                answers = concurrent(client, url, params, args.concurrent)
                codes = sorted(code for code, _ in answers)
                slowest = max(s for _, s in answers)
                print(f"{args.concurrent} concurrent: statuses {codes}, slowest {slowest:.3f} s, "
                      f"RSS +{growth():.1f} MB")


if __name__ == "__main__":
    main()
