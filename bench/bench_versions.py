"""The fast path of this checkout against another git revision, in one process, design by design.

    taskset -c 1 python bench/bench_versions.py main [--roads sine:0.04:3,sine:0.04:2] [--designs 401] [--repeat 3]

The machine is shared and its speed drifts within minutes, so two versions timed in separate runs
are not comparable: here both simulate the same random designs (bench_engine.random_designs)
alternately, the order flipped every design, and the table gives per road and version the median
real-time ratio of each repeat (simulate's own wall_s, setup included), the wall time's median / p90 /
max [ms] and failures, and the ratio of the two medians. The other revision is exported with
`git archive` into a cache directory (its package renamed to finaldrive_<rev>, so that both import
side by side; its numba cache lives there too: the first run compiles it). Results are compared as
well: "identical" when every distance, slack and ledger residual is bit-identical.
"""

from __future__ import annotations

import argparse
import importlib
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench_engine import random_designs  # noqa: E402

import finaldrive.engine as this  # noqa: E402
from finaldrive.service.machine import describe  # noqa: E402


def export(rev: str) -> ModuleType:
    """The engine of git revision rev, imported as finaldrive_<sha>.engine."""
    sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", rev], check=True, capture_output=True,
                         text=True).stdout.strip()
    name = f"finaldrive_{sha}"
    root = Path(tempfile.gettempdir()) / "finaldrive-bench-versions"
    package = root / name
    if not package.exists():
        package.mkdir(parents=True)
        archive = subprocess.run(["git", "-C", str(REPO), "archive", sha], check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(package)], input=archive, check=True)
        for path in package.rglob("*.py"):
            text = path.read_text()
            text = re.sub(r"\bfinaldrive\.(engine|service|workers|migrations)\b", rf"{name}.\1", text)
            path.write_text(text.replace("from finaldrive import", f"from {name} import"))
    sys.path.insert(0, str(root))
    return importlib.import_module(f"{name}.engine")


def compare(engines: dict[str, ModuleType], road: str, n: int, repeat: int) -> None:
    rows = random_designs(n)
    runs = {}
    for label, engine in engines.items():
        case = (engine, engine.Road.parse(road), engine.SimSettings(method="fast").with_(series=False),
                [engine.Design(*row) for row in rows])
        engine.simulate(case[3][0], case[1], case[2])   # compile or load
        runs[label] = case
    ratios: dict[str, list[float]] = {label: [] for label in engines}
    walls: dict[str, list[float]] = {}
    values: dict[str, list[float]] = {}
    failures = dict.fromkeys(engines, 0)
    for r in range(repeat):
        walls = {label: [] for label in engines}
        values = {label: [] for label in engines}
        for i in range(n):
            order = list(engines) if (i + r) % 2 == 0 else list(reversed(engines))
            for label in order:
                engine, parsed, settings, designs = runs[label]
                res = engine.simulate(designs[i], parsed, settings)
                walls[label].append(res.wall_s)
                values[label] += [res.distance_m, res.slack_m, res.ledger_residual_j]
                failures[label] += r == 0 and not res.ok
        for label in engines:
            ratios[label].append(runs[label][2].duration / statistics.median(walls[label]))
    first, second = engines
    for label in engines:
        w = 1e3 * np.array(walls[label])
        print(f"{road:>12} {label:>12}: RT {statistics.median(ratios[label]):6.0f} (repeats "
              f"{', '.join(f'{x:.0f}' for x in ratios[label])}); wall ms median {np.median(w):.2f}, p90 "
              f"{np.percentile(w, 90):.2f}, max {w.max():.2f}; failures {failures[label]}")
    same = np.array_equal(np.array(values[first]), np.array(values[second]), equal_nan=True)
    gain = statistics.median(ratios[second]) / statistics.median(ratios[first])
    print(f"{road:>12} RT {second} / {first}: {gain:.3f}"
          f" (per repeat {', '.join(f'{b / a:.3f}' for a, b in zip(ratios[first], ratios[second], strict=True))});"
          f" results {'identical' if same else 'differ'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", help="the other git revision (e.g. main)")
    ap.add_argument("--roads", default="sine:0.04:3,sine:0.04:2")
    ap.add_argument("--designs", type=int, default=401)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"machine: {describe()}")
    engines = {args.rev: export(args.rev), "this": this}
    for road in args.roads.split(","):
        compare(engines, road, args.designs, args.repeat)


if __name__ == "__main__":
    main()
