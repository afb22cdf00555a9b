"""The command line's start-up: wall time of `finaldrive --help`, `--version` and a command's help, each
the median of --repeat runs after one untimed, beside the interpreter's own start (`python -c pass`)
as the floor. Prints a markdown table.

    python bench/bench_cli.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

CASES = (
    ("python -c pass (the floor)", [sys.executable, "-c", "pass"]),
    ("finaldrive --help", [sys.executable, "-m", "finaldrive.service.cli", "--help"]),
    ("finaldrive --version", [sys.executable, "-m", "finaldrive.service.cli", "--version"]),
    ("finaldrive simulate --help", [sys.executable, "-m", "finaldrive.service.cli", "simulate", "--help"]),
    ("finaldrive serve --help", [sys.executable, "-m", "finaldrive.service.cli", "serve", "--help"]),
)


def wall(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(f"| command | median of {args.repeat} [s] | runs [s] |")
    print("|---|---|---|")
    for label, command in CASES:
        wall(command)
        runs = [wall(command) for _ in range(args.repeat)]
        print(f"| {label} | {statistics.median(runs):.3f} | {', '.join(f'{r:.3f}' for r in runs)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
