"""How ``optimize`` and ``sweep`` print their results."""

from __future__ import annotations

from typing import Any

from finaldrive.service.cli.common import print_json
from finaldrive.service.cli.sharpness_view import sharpness_lines


def print_result(out: dict[str, Any], as_json: bool) -> None:
    """An optimize or sweep result: JSON, or a summary for people."""
    if as_json:
        print_json(out)
        return
    where = f"  ({out['objective']} over {len(out['roads'])} roads)" if out["objective"] else f"  on {out['roads'][0]}"
    print(f"best: {_design_text(out['best'])}{where}")
    if len(out["roads"]) > 1:
        for road in out["per_road"]:
            print(f"  {road['road']:<22} {_design_text(road.get('best') or road.get('best_design'))}")
    extra = f", {out['generations']} generations, stop: {out['stop_reason']}" if out["command"] == "optimize" else ""
    print(f"evaluations: {out['evaluations']} ({out['failed']} failed){extra}, "
          f"executor {out['executor']}, {out['wall_s']:.1f} s")
    if out.get("out"):
        print(f"results: {out['out']}")
    print("\n".join(sharpness_lines(out["sharpness"])))


def _design_text(d: dict[str, Any] | None) -> str:
    if d is None:
        return "none (every simulation failed)"
    fitness = "failed" if d["fitness_m"] is None else f"{d['fitness_m']:.4f} m"
    distance = "-" if d.get("distance_m") is None else f"{d['distance_m']:.3f} m"
    return (f"a2 = {d['a2_deg']:.2f} deg, L2 = {d['l2_m']:.4f} m, R_WS = {d['rws_m']:.4f} m, "
            f"fitness {fitness}, distance {distance}")
