"""How ``optimize`` and ``sweep`` print their results."""

from __future__ import annotations

from typing import Any

from finaldrive.service.cli.common import print_json
from finaldrive.service.cli.sharpness_view import band_lines, band_text, sharpness_lines


def print_result(out: dict[str, Any], as_json: bool) -> None:
    """An optimize or sweep result: JSON, or a summary for people."""
    if as_json:
        print_json(out)
        return
    where = f"  ({out['aggregate']} over {len(out['roads'])} roads)" if out["aggregate"] else f"  on {out['roads'][0]}"
    print(f"best: {_design_text(out['best'])}{where}")
    if len(out["roads"]) > 1:
        for road in out["per_road"]:
            print(f"  {road['road']:<22} {_design_text(road.get('best') or road.get('best_design'), band=True)}")
    for line in _band_lines(out):
        print(line)
    extra = f", {out['generations']} generations, stop: {out['stop_reason']}" if out["command"] == "optimize" else ""
    print(f"evaluations: {out['evaluations']} ({out['failed']} failed){extra}, "
          f"executor {out['executor']}, {out['wall_s']:.1f} s")
    if out.get("out"):
        print(f"results: {out['out']}")
    print("\n".join(sharpness_lines(out["sharpness"])))


def _band_lines(out: dict[str, Any]) -> list[str]:
    """The best's numerical band (and its ties), when ``optimize`` computed them."""
    band = (out.get("best") or {}).get("numerical_band")
    if band is None:
        return []
    what = "fitness" if len(out["roads"]) == 1 else f"{out['aggregate']} fitness"
    return band_lines(band, out["sharpness"].get("ties") or [], what=what, indent="")


def _design_text(d: dict[str, Any] | None, *, band: bool = False) -> str:
    if d is None:
        return "none (every simulation failed)"
    fitness = "failed" if d["fitness_m"] is None else f"{d['fitness_m']:.4f} m"
    distance = "-" if d.get("distance_m") is None else f"{d['distance_m']:.3f} m"
    within = f" (band {band_text(d['numerical_band'])})" if band and d.get("numerical_band") else ""
    return (f"a2 = {d['a2_deg']:.2f} deg, L2 = {d['l2_m']:.4f} m, R_WS = {d['rws_m']:.4f} m, "
            f"fitness {fitness}{within}, distance {distance}")
