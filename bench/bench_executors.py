"""Simulations per second with the serial, process-pool and Ray executors.

    python -m bench.bench_executors [--n 400] [--duration 3.5] [--repeat 3] [--workers 2]

Real engine, road ``sine:0.04:3``, default ``SimSettings`` (the fast method; ``--duration``
overrides the simulated time), designs drawn uniformly from the paper's Table 8 search
space with a fixed seed. Each executor is started once and warmed up (compiled code loaded
in every worker) before the timed runs, whose start-up time is printed separately; the
timed runs are interleaved across executors so that changes in machine load affect each
alike. Ray runs locally on ``--workers`` CPUs (``RAY_ADDRESS`` is ignored). The machine
may be shared: the load average is printed with the results. Run it on a quiet machine
(docs/workers.md, "Results").
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # run as a script from anywhere

from finaldrive.engine import BatchResult, Request, Road, SimSettings
from finaldrive.service.machine import describe
from finaldrive.workers import Executor, make_executor
from finaldrive.workers.dispatch import Dispatcher, Work
from finaldrive.workers.evaluate import run_engine_on_roads, warm_up_engine

ROAD = "sine:0.04:3"
BOUNDS = np.array([[0.0, 2 * np.pi], [0.0, 0.2], [0.05, 0.15]])   # a2 [rad], L2 [m], R_WS [m]


def sample_designs(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return BOUNDS[:, 0] + rng.random((n, 3)) * (BOUNDS[:, 1] - BOUNDS[:, 0])


def evaluate(executor: Executor, designs: np.ndarray, road: Road, settings: SimSettings) -> tuple[BatchResult, int]:
    """The designs' results in order, and the tasks they took, by the service's path: the dispatcher
    (adaptive batches, finaldrive.workers.dispatch) and the workers' task."""
    parts: dict[int, BatchResult] = {}

    def failed(part: Request, reason: str) -> None:
        raise RuntimeError(f"{len(part)} designs failed: {reason}")

    work = Work(key="bench", shared=((road,), settings, None),
                on_result=lambda part, batch: parts.__setitem__(int(part.candidates[0]), batch), on_failure=failed)
    work.queue.append(Request(0, 0, 0, np.arange(len(designs)), designs))
    dispatcher = Dispatcher(executor, run_engine_on_roads, warmup=warm_up_engine)
    dispatcher.add(work)
    tasks = 0
    try:
        while work.queue or work.alone or dispatcher.in_flight():
            tasks += dispatcher.step(1.0)
    finally:
        dispatcher.close()
    return BatchResult.concat([parts[start] for start in sorted(parts)]), tasks


def timed_run(executor: Executor, designs: np.ndarray, road: Road, settings: SimSettings
              ) -> tuple[float, int, BatchResult]:
    """(seconds, batches, results) of one evaluation of ``designs``."""
    start = time.perf_counter()
    result, batches = evaluate(executor, designs, road, settings)
    return time.perf_counter() - start, batches, result


def start(kind: str, workers: int, designs: np.ndarray, road: Road, settings: SimSettings) -> Executor:
    """Start an executor and load the compiled engine in every worker; print the time taken."""
    begin = time.perf_counter()
    executor = make_executor(kind, num_workers=workers)  # type: ignore[arg-type]
    evaluate(executor, designs[: 2 * executor.num_workers], road, settings)
    print(f"{kind:8s} workers={executor.num_workers}  start + warm-up {time.perf_counter() - begin:5.1f} s",
          flush=True)
    return executor


def same(a: BatchResult, b: BatchResult) -> bool:
    return a.status == b.status and all(
        np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True)
        for name in ("distance_m", "squat_ratio", "slack_m", "fitness_m", "chain_length_m")
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=400, help="designs per run")
    parser.add_argument("--duration", type=float, default=None, help="simulated time [s] (default: SimSettings)")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per executor (median reported)")
    parser.add_argument("--workers", type=int, default=2, help="process-pool and Ray workers (default 2)")
    parser.add_argument("--executors", default="serial,process,ray", help="comma-separated kinds")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    os.environ.pop("RAY_ADDRESS", None)

    settings = SimSettings() if args.duration is None else SimSettings(duration=args.duration)
    road, designs = Road.parse(ROAD), sample_designs(args.n, args.seed)
    print(f"machine: {describe()}")
    print(f"python {platform.python_version()}, road {ROAD}, {args.n} designs, duration {settings.duration} s, "
          f"dt {settings.dt} s, method {settings.method}, repeat {args.repeat}", flush=True)

    kinds = args.executors.split(",")
    executors = {kind: start(kind, args.workers, designs, road, settings) for kind in kinds}
    rates: dict[str, list[float]] = {kind: [] for kind in kinds}
    results: dict[str, BatchResult] = {}
    try:
        for run in range(args.repeat):             # interleaved, so load changes hit every kind
            for kind, executor in executors.items():
                seconds, batches, results[kind] = timed_run(executor, designs, road, settings)
                rates[kind].append(len(designs) / seconds)
                print(f"  run {run + 1} {kind:8s} {seconds:7.2f} s  {rates[kind][-1]:7.2f} sims/s  "
                      f"({batches} batches)", flush=True)
    finally:
        for executor in executors.values():
            executor.close()

    medians = {kind: statistics.median(r) for kind, r in rates.items()}
    for kind, r in rates.items():
        print(f"{kind:8s} median {medians[kind]:7.2f} sims/s  (min {min(r):.2f}, max {max(r):.2f})")
    first = next(iter(results.values()))
    ok = sum(first.ok)
    print(f"ok simulations: {ok}/{len(first)}; results identical across executors: "
          f"{all(same(first, r) for r in results.values())}")
    if "ray" in medians and "process" in medians:
        print(f"Ray / process pool (medians, same run): {medians['ray'] / medians['process']:.3f}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
