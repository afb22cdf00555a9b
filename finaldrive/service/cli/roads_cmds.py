"""``finaldrive roads``: the paper's 23 road presets, with the paper's optimum on each."""

from __future__ import annotations

import argparse
import math
from typing import Any

from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import add_json_arg, parser_options, print_json


def run_roads(args: argparse.Namespace) -> int:
    from finaldrive.engine import PRESETS

    if args.json:
        print_json([{"name": p.name, "spec": p.road.spec, "description": p.description, "paper": p.paper}
                    for p in PRESETS.values()])
        return 0
    print(f"{'road':<16} {'a2_deg':>7} {'l2_m':>6} {'rws_m':>6} {'fitness_m':>9}  description")
    for p in PRESETS.values():
        ref = p.paper or {}
        print(f"{p.spec:<16} {ref.get('a2_deg', math.nan):7.1f} "
              f"{ref.get('l2_m', math.nan):6.3f} {ref.get('rws_m', math.nan):6.3f} "
              f"{ref.get('fitness_m', math.nan):9.3f}  {p.description}")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("roads", help=COMMANDS["roads"].help, **parser_options())
    add_json_arg(p, "print a JSON list")
    p.set_defaults(run=run_roads)
