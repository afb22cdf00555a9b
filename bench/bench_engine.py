"""Engine speed on one core: real-time ratio (simulated s per wall s) of one 3.5 s run,
median of N runs after a warm-up, per road and method, for the Table 11 design and as a
distribution over random designs (a2 uniform 0-360 deg, L2 0-0.2 m, R_WS 0.05-0.15 m: median,
p90 and max of the wall time, failures); batch throughput; the cold start (compiling the engine
once, loading it in a fresh process, `finaldrive geometry`); 2-process throughput.

    taskset -c 1 python bench/bench_engine.py [--repeat 5] [--methods fast,reference] [--designs 401]
        [--roads sine:0.04:3,sine:0.04:2] [--compare fast_tolerance=1e-4] [--quick]
    (--compare takes SimSettings fields and vehicle parameters, e.g. --compare front_wheel_spin=1)
    python bench/bench_engine.py --cold-start [--repeat 5] [--no-demo]   # the cold start alone, `finaldrive demo` too

Prints the machine it ran on and its load average. The machine is shared and noisy: compare
methods (or, with --compare, the default settings and changed ones) by the ratio measured in the
same run, the designs interleaved.
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

from finaldrive.engine import Design, Road, SimSettings, Vehicle, default_vehicle, evaluate, simulate  # noqa: E402
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


Variant = tuple[SimSettings, Vehicle]


def distributions(variants: list[Variant], road: str, n: int) -> list[dict[str, float]]:
    """Per (settings, vehicle): the wall time of each of n random designs' runs (simulate's own wall_s),
    the variants interleaved design by design so that the machine's noise hits them alike; median real-
    time ratio, median / p90 / max wall [ms], failures."""
    r = Road.parse(road)
    designs = [Design(*row) for row in random_designs(n)]
    for s, v in variants:
        simulate(designs[0], r, s, v)
    walls: list[list[float]] = [[] for _ in variants]
    failures = [0] * len(variants)
    for d in designs:
        for i, (s, v) in enumerate(variants):
            res = simulate(d, r, s, v)
            walls[i].append(res.wall_s)
            failures[i] += not res.ok
    out = []
    for (s, _), w, f in zip(variants, walls, failures, strict=True):
        a = np.array(w)
        out.append({"ratio median": s.duration / float(np.median(a)), "ms median": 1e3 * float(np.median(a)),
                    "ms p90": 1e3 * float(np.percentile(a, 90)), "ms max": 1e3 * float(a.max()), "failures": f})
    return out


def parse_variant(spec: str) -> Variant:
    """``key=value,key=value`` -> the fast method's settings and the paper's vehicle with those of the keys
    that are SimSettings fields and vehicle parameters changed (numbers)."""
    values = {k: float(v) for k, v in (item.split("=") for item in spec.split(",") if item)}
    defaults = SimSettings()
    fields = set(SimSettings.__dataclass_fields__)
    def typed(key: str, value: float) -> object:   # a bool or int field as its own type (fast_ros2=1: True)
        default = getattr(defaults, key)
        return type(default)(value) if isinstance(default, (bool, int)) else value

    settings = settings_for("fast", **{k: typed(k, v) for k, v in values.items() if k in fields})
    return settings, default_vehicle().replace(**{k: v for k, v in values.items() if k not in fields})


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


_COMPILE = """
import resource, time, sys
def cpu():
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime
sys.path.insert(0, {repo!r})
from finaldrive.engine import compile_engine
fast = compile_engine(now=("fast",), later=())()
fast_cpu = cpu()
reference = compile_engine(now=("reference",), later=())()
print(fast, fast_cpu, reference, cpu() - fast_cpu)
"""

_FIRST_CALL = """
import time, sys
t0 = time.perf_counter()
sys.path.insert(0, {repo!r})
from finaldrive.engine import Design, Road, SimSettings, simulate
r = simulate(Design.from_deg(195.3, 0.037, 0.088), Road.parse("flat"), SimSettings(method={method!r}, duration=0.1))
assert r.ok
print(time.perf_counter() - t0)
"""


def finaldrive_command() -> str:
    """The `finaldrive` script of this interpreter's environment (else the one on PATH)."""
    beside = Path(sys.executable).parent / "finaldrive"
    return str(beside) if beside.exists() else shutil.which("finaldrive") or "finaldrive"


def _median_wall(cmd: list[str], repeat: int, env: dict[str, str] | None = None) -> float:
    """Median wall s of `repeat` runs of cmd, after one run that writes the bytecode caches."""
    walls = []
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        subprocess.run(cmd, env=env, check=True, capture_output=True)
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls[1:])


def cold_start(repeat: int) -> dict[str, float]:
    """Seconds: compile_engine into an empty cache directory (once per method); a fresh process's first
    result with that cache, median of `repeat` per method; `finaldrive geometry`, median, and numpy's
    import alone (the floor under it). The processes read Python's bytecode caches, as an installed
    package's do (PYTHONDONTWRITEBYTECODE, if set, is dropped for them: else every process compiles
    finaldrive's sources, ~0.1-0.2 s)."""
    out: dict[str, float] = {}
    base = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    with tempfile.TemporaryDirectory() as cache:
        env = {**base, "NUMBA_CACHE_DIR": cache}
        done = subprocess.run([sys.executable, "-c", _COMPILE.format(repo=str(REPO))], env=env, check=True,
                              capture_output=True, text=True)
        fast, fast_cpu, reference, reference_cpu = (float(v) for v in done.stdout.split()[-4:])
        out["compile_engine, empty cache: fast method"] = fast
        out["compile_engine, empty cache: fast method, CPU s"] = fast_cpu
        out["compile_engine, empty cache: reference method"] = reference
        out["compile_engine, empty cache: reference method, CPU s"] = reference_cpu
        for method in ("fast", "reference"):
            code = _FIRST_CALL.format(repo=str(REPO), method=method)
            out[f"first {method} result, fresh process, cached"] = _median_wall([sys.executable, "-c", code], repeat,
                                                                                env)
    geometry = [finaldrive_command(), "geometry", "--a2-deg", "195.3", "--l2-m", "0.037", "--rws-m", "0.088"]
    out["finaldrive geometry"] = _median_wall(geometry, repeat, base)
    out["python -c 'import numpy' (the floor under finaldrive geometry)"] = _median_wall(
        [sys.executable, "-c", "import numpy"], repeat, base)
    return out


def demo_walls(repeat: int) -> dict[str, float]:
    """Seconds of `finaldrive demo` (Ray) in an empty directory: with an empty numba cache (once; the
    reference method's background compilation is waited for before the next run), then with the
    cache filled (median of `repeat`)."""
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as work:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        walls = []
        for i in range(repeat + 1):
            t0 = time.perf_counter()
            subprocess.run([finaldrive_command(), "demo"], cwd=work, env=env, check=True, capture_output=True)
            walls.append(time.perf_counter() - t0)
            while i == 0 and not (Path(cache) / "compiled-reference").exists():
                time.sleep(1.0)
        out["finaldrive demo, empty cache"] = walls[0]
        out["finaldrive demo, cache filled"] = statistics.median(walls[1:])
    return out


def cli_evaluate_cost(n_extra: int = 100, repeat: int = 3) -> tuple[float, float]:
    """(median wall s of `finaldrive evaluate` on 1 design, on 1 + n_extra designs)."""
    rng = np.random.default_rng(7)
    rows = ["a2_deg,l2_m,rws_m", "195.3,0.037,0.088"]
    rows += [
        f"{rng.uniform(0, 360):.3f},{rng.uniform(0, 0.2):.4f},{rng.uniform(0.05, 0.15):.4f}" for _ in range(n_extra)
    ]
    exe = finaldrive_command()
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
    ap.add_argument("--designs", type=int, default=401, help="random designs per road (fast method)")
    ap.add_argument("--reference-designs", type=int, default=21, help="random designs per road (reference)")
    ap.add_argument("--roads", default="sine:0.04:3,sine:0.04:2", help="roads of the random-design distributions")
    ap.add_argument("--compare", default="", help="fast settings or vehicle parameters to compare with the default, "
                    "e.g. fast_tolerance=1e-4 or front_wheel_spin=1")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--cold-start", action="store_true",
                    help="only the cold start, `finaldrive demo` with an empty and a filled cache included")
    ap.add_argument("--no-demo", action="store_true", help="--cold-start without `finaldrive demo` (Ray)")
    args = ap.parse_args()
    if args.cold_start:
        print(f"machine: {describe()}\nload average before: {os.getloadavg()[0]:.2f}")
        for key, value in {**cold_start(args.repeat), **({} if args.no_demo else demo_walls(args.repeat))}.items():
            print(f"cold start: {key}: {value:.2f} s")
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        return
    n_batch = 20 if args.quick else args.batch
    n_designs = 21 if args.quick else args.designs
    report: dict[str, object] = {"machine": describe(), "methods": {}}
    print(f"machine: {report['machine']}")
    print(f"\n== random designs ({n_designs} fast, {args.reference_designs} reference), wall time a run, 1 core")
    methods = args.methods.split(",")
    for road in args.roads.split(","):
        variants = [(settings_for(m), default_vehicle()) for m in methods]
        names = list(methods)
        if args.compare:
            variants.append(parse_variant(args.compare))
            names.append(f"fast {args.compare}")
        fast = [i for i, (s, _) in enumerate(variants) if s.method == "fast"]
        slow = [i for i, (s, _) in enumerate(variants) if s.method != "fast"]
        stats: dict[int, dict[str, float]] = {}
        for group, n in ((fast, n_designs), (slow, args.reference_designs)):
            if group:
                stats.update(zip(group, distributions([variants[i] for i in group], road, n), strict=True))
        for i, name in enumerate(names):
            d = stats[i]
            report[f"random {road} {name}"] = d
            print(f"{road:>12} {name:>28}: real-time ratio {d['ratio median']:7.1f} (median); wall ms median "
                  f"{d['ms median']:.2f}, p90 {d['ms p90']:.2f}, max {d['ms max']:.2f}; failures {d['failures']}")
        for i in range(1, len(names)):
            print(f"{road:>12} median ratio {names[i]} / {names[0]}: "
                  f"{stats[i]['ratio median'] / stats[0]['ratio median']:.3f}")
    print(f"load average now: {os.getloadavg()[0]:.2f}")
    for key, value in cold_start(3 if args.quick else args.repeat).items():
        report[key] = value
        print(f"cold start: {key}: {value:.2f} s")
    for method in methods:
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
        if len(os.sched_getaffinity(0)) < 2:
            print("throughput of 1 and 2 processes: skipped (pinned to one core)")
        else:
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
