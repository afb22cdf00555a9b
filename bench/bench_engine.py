"""Engine speed on one core: real-time ratio (simulated s per wall s) of one 3.5 s run,
median of N runs after a warm-up, per road and method; batch throughput; first-call latency
in fresh processes (cold: empty numba cache; cached); and 2-process throughput.

    python bench/bench_engine.py [--repeat 5] [--methods reference,fast] [--quick]

Prints the machine it ran on. The machine is shared and noisy: compare methods by the ratio
measured in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from finaldrive.engine import Design, Road, SimSettings, evaluate, simulate  # noqa: E402
from finaldrive.service.machine import describe  # noqa: E402

TABLE11 = Design.from_deg(195.3, 0.037, 0.088)
ROADS = ("flat", "sine:0.04:3", "sine:0.04:2", "bump:0.04:0.2")


def settings_for(method: str, **kw: object) -> SimSettings:
    return SimSettings(method=method, **kw)  # type: ignore[arg-type]


def realtime_ratio(method: str, road: str, repeat: int) -> tuple[float, float]:
    """(median ratio, median wall s) of `repeat` runs after one warm-up."""
    s = settings_for(method)
    r = Road.parse(road)
    simulate(TABLE11, r, s)
    walls = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = simulate(TABLE11, r, s)
        walls.append(time.perf_counter() - t0)
        assert res.ok, res.reason
    wall = statistics.median(walls)
    return s.duration / wall, wall


def random_designs(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 0.2, n), rng.uniform(0.05, 0.15, n)])


def batch_throughput(method: str, n: int, repeat: int) -> float:
    designs = random_designs(n)
    road = Road.parse("sine:0.04:3")
    s = settings_for(method)
    evaluate(designs[:2], road, s)
    rates = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        evaluate(designs, road, s)
        rates.append(n / (time.perf_counter() - t0))
    return statistics.median(rates)


def _chunk(args: tuple[np.ndarray, str]) -> int:
    designs, method = args
    evaluate(designs, Road.parse("sine:0.04:3"), settings_for(method))
    return len(designs)


def two_process_throughput(method: str, n: int) -> tuple[float, float]:
    """(1-process, 2-process) simulations per second, pools warmed up first."""
    designs = random_designs(n, seed=2)
    out = []
    for workers in (1, 2):
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            list(pool.map(_chunk, [(designs[:1], method)] * workers))
            chunks = np.array_split(designs, workers * 4)
            t0 = time.perf_counter()
            list(pool.map(_chunk, [(c, method) for c in chunks]))
            out.append(n / (time.perf_counter() - t0))
    return out[0], out[1]


_FIRST_CALL = """
import time, sys
t0 = time.perf_counter()
sys.path.insert(0, {repo!r})
from finaldrive.engine import Design, Road, SimSettings, simulate
r = simulate(Design.from_deg(195.3, 0.037, 0.088), Road.parse("flat"), SimSettings(method={method!r}, duration=0.1))
assert r.ok
print(time.perf_counter() - t0)
"""


def first_call_latency(method: str) -> tuple[float, float]:
    """(cold, cached) seconds from interpreter start to a first result, in fresh processes.

    Cold uses an empty numba cache directory (NUMBA_CACHE_DIR), so it includes compilation.
    """
    code = _FIRST_CALL.format(repo=str(REPO), method=method)
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True)
            times.append(time.perf_counter() - t0)
        shutil.rmtree(cache, ignore_errors=True)
    return times[0], times[1]


def cli_evaluate_cost(n_extra: int = 100, repeat: int = 3) -> tuple[float, float]:
    """(median wall s of `finaldrive evaluate` on 1 design, on 1 + n_extra designs)."""
    rng = np.random.default_rng(7)
    rows = ["a2_deg,l2,rws", "195.3,0.037,0.088"]
    rows += [
        f"{rng.uniform(0, 360):.3f},{rng.uniform(0, 0.2):.4f},{rng.uniform(0.05, 0.15):.4f}" for _ in range(n_extra)
    ]
    exe = shutil.which("finaldrive") or "finaldrive"
    with tempfile.TemporaryDirectory() as tmp:
        one, many = Path(tmp) / "one.csv", Path(tmp) / "many.csv"
        one.write_text("\n".join(rows[:2]) + "\n")
        many.write_text("\n".join(rows) + "\n")
        walls: dict[Path, list[float]] = {one: [], many: []}
        for _ in range(repeat):
            for path in (one, many):
                t0 = time.perf_counter()
                subprocess.run([exe, "evaluate", "--designs", str(path), "--road", "sine:0.04:3"],
                               check=True, capture_output=True)
                walls[path].append(time.perf_counter() - t0)
    return statistics.median(walls[one]), statistics.median(walls[many])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--methods", default="reference")
    ap.add_argument("--batch", type=int, default=200, help="designs in the batch throughput test")
    ap.add_argument("--quick", action="store_true", help="fewer designs, for a smoke run")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    n_batch = 20 if args.quick else args.batch
    report: dict[str, object] = {"machine": describe(), "methods": {}}
    print(f"machine: {report['machine']}")
    for method in args.methods.split(","):
        m: dict[str, object] = {}
        print(f"\n== method {method}")
        for road in ROADS:
            ratio, wall = realtime_ratio(method, road, args.repeat)
            m[f"ratio {road}"] = ratio
            print(
                f"real-time ratio, Table 11 design, {road:>14}: {ratio:8.1f}  "
                f"({wall * 1000:.1f} ms / 3.5 s run, median of {args.repeat})"
            )
        rate = batch_throughput(method, n_batch, max(1, args.repeat // 2))
        m["batch sims/s"] = rate
        print(f"batch throughput, {n_batch} random designs on sine:0.04:3, 1 core: {rate:.1f} sims/s")
        cold, cached = first_call_latency(method)
        m["first call cold s"], m["first call cached s"] = cold, cached
        print(f"first call in a fresh process: cold {cold:.2f} s, cached {cached:.2f} s")
        one, two = two_process_throughput(method, n_batch)
        m["1 process sims/s"], m["2 processes sims/s"] = one, two
        print(f"throughput: 1 process {one:.1f} sims/s, 2 processes {two:.1f} sims/s (x{two / one:.2f})")
        report["methods"][method] = m  # type: ignore[index]
    one, many = cli_evaluate_cost()
    report["cli evaluate 1 / 101 s"] = [one, many]
    print(f"\nfinaldrive evaluate (default method): 1 design {one:.2f} s, 101 designs {many:.2f} s "
          f"(+{(many - one) / 100 * 1000:.1f} ms a design; budget 7 ms)")
    if args.json:
        print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
